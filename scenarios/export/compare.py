"""`dynprop export --truth X.aem`: the exported attitude against another tool's, at
the exported epochs inside X's segments (never across a dropout between two), as the
export streams.

Both attitudes are taken to dynprop's orbit frame R (``files.truth_aem``: X's frame
converted with the run's orbit and epoch when it is inertial), so X may be in EME2000
(J2000, ICRF, GCRF) or LVLH_ROTATING whatever the export's frame is.  Reported: the
rotation angle between the two (the angle of C_exported · C_Xᵀ, frame-free), its RMS
and largest value with its time, and per axis the 3-1-2 angle differences exported − X
(roll, pitch, yaw: RMS, mean, largest magnitude), which for an export of the estimate
against the truth are dynprop's own errors (estimate − truth).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from dynprop.sim.frames import dcm_from_euler312, dcm_from_quat, euler312_from_quat, quat_from_dcm

from ..config import build
from ..config.schema import Scenario
from ..files.aem import read_aem
from ..files.truth_aem import orbit_frame_attitude, segment_spans
from ..units import RAD2DEG
from .source import Block, ExportError

AXES = ("roll", "pitch", "yaw")


def _wrapped(a: np.ndarray) -> np.ndarray:
    return (a + np.pi) % (2 * np.pi) - np.pi


def rotation_angle(c: np.ndarray) -> np.ndarray:
    """The angle (rad) of each rotation matrix, accurate near zero: 2 atan2(|v|, |w|)
    of its quaternion, not acos of the trace."""
    q = quat_from_dcm(c)
    return 2 * np.arctan2(np.linalg.norm(q[..., :3], axis=-1), np.abs(q[..., 3]))


class Comparison:
    """Sums over the blocks of an export: ``add`` each block, ``result`` at the end."""

    def __init__(self, path: Path | str, s: Scenario):
        self.path = Path(path)
        self.segments = read_aem(self.path)
        self.scenario = s
        self.exported = self.compared = 0
        self.angle_sq = 0.0
        self.angle_max = (-1.0, float("nan"))
        self.sums = {a: np.zeros(3) for a in AXES}   # Σd, Σd², max |d|

    def add(self, b: Block) -> None:
        finite = np.isfinite(b.yaw) & np.isfinite(b.roll) & np.isfinite(b.pitch)
        t = b.t_s[finite]
        self.exported += t.size
        keep, q_br, _ = orbit_frame_attitude(self.segments, t, self.scenario)
        if not keep.size:
            return
        mine = [x[finite][keep] for x in (b.yaw, b.roll, b.pitch)]
        angle = rotation_angle(dcm_from_euler312(*mine)
                               @ np.swapaxes(dcm_from_quat(q_br), -1, -2))
        self.compared += keep.size
        self.angle_sq += float(np.sum(angle**2))
        k = int(np.argmax(angle))
        if angle[k] > self.angle_max[0]:
            self.angle_max = (float(angle[k]), float(t[keep][k]))
        yaw, roll, pitch = euler312_from_quat(q_br)
        for axis, ours, theirs in zip(AXES, (mine[1], mine[2], mine[0]), (roll, pitch, yaw),
                                      strict=True):
            d = _wrapped(ours - theirs)
            s = self.sums[axis]
            s += [d.sum(), (d**2).sum(), 0.0]
            s[2] = max(s[2], float(np.abs(d).max()))

    def result(self) -> dict:
        """The figures (degrees), or ``ExportError`` when no exported epoch was inside
        a segment of the file."""
        if not self.compared:
            spans = segment_spans(self.segments, build.epoch(self.scenario))
            raise ExportError(f"{self.path}: no segment ({spans} after "
                              f"{self.scenario.epoch_utc}) covers an exported epoch: nothing "
                              "to compare")
        n = self.compared
        out = {"file": str(self.path),
               "frame": ", ".join(sorted({seg.frame for seg in self.segments})),
               "segments": len(self.segments), "exported": self.exported, "compared": n,
               "angle_rms_deg": float(np.sqrt(self.angle_sq / n)) * RAD2DEG,
               "angle_max_deg": self.angle_max[0] * RAD2DEG,
               "angle_max_t_s": self.angle_max[1]}
        for axis in AXES:
            total, squares, largest = self.sums[axis]
            out[f"{axis}_deg"] = {"rms": float(np.sqrt(squares / n)) * RAD2DEG,
                                  "mean": float(total / n) * RAD2DEG,
                                  "max_abs": float(largest) * RAD2DEG}
        return out


def lines(c: dict) -> list[str]:
    """What `dynprop export --truth` prints of a comparison."""
    name = Path(c["file"]).name
    out = [f"compared with {c['file']} ({c['frame']}; {c['compared']} of {c['exported']} "
           f"exported epochs inside its {c['segments']} segment"
           f"{'s' * (c['segments'] != 1)}), exported - {name}:",
           f"  rotation angle: RMS {c['angle_rms_deg']:.4g} deg, max "
           f"{c['angle_max_deg']:.4g} deg (t = {c['angle_max_t_s']:g} s)"]
    for axis in AXES:
        d = c[f"{axis}_deg"]
        out.append(f"  {axis + ':':<6} RMS {d['rms']:.4g} deg, mean {d['mean']:.4g} deg, "
                   f"max |.| {d['max_abs']:.4g} deg")
    return out
