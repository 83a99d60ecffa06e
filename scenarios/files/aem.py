"""CCSDS Attitude Ephemeris and Parameter Messages (AEM, APM; CCSDS 504.0-B-2, KVN).

**Quaternions** are dynprop's (docs/conventions.md): scalar-last [q1 q2 q3 qc], the frame
rotation A(q) = C_{B←A} of Markley & Crassidis Eq. 2.125, v_B = A(q) v_A.  That is ADM
v2's own fixed convention (REF_FRAME_A → REF_FRAME_B, QC last), so a 2.0 file carries
no ATTITUDE_DIR or QUATERNION_TYPE (504.0-B-2 dropped both; Orekit's writer omits them).
``AemMeta(version="1.0")`` writes the 504.0-B-1 form, where ``ATTITUDE_DIR = A2B`` and
``QUATERNION_TYPE = LAST`` are mandatory.  The header's COMMENT lines state all this.

**Printed precision**: components with 12 decimals (|error| ≤ 5e-13), epochs UTC to the
microsecond.  Signs are made continuous row to row (q and −q are one attitude), so rows
interpolate component-wise.  A row with a NaN is left out, like a dropout, and a step
over 1.5 × the cadence starts a new segment (nothing interpolates across it).

**Frames.**  dynprop's N is not EME2000: the satellite's right ascension is GMST (IAU
1982, from the *mean equinox of date*) + longitude + ω0 t, ω0 being the GMST rate to
1.3e-8, so N is the mean equator and equinox of date (MOD).  The inertial export
composes C_{B←EME2000} = C_BR(ψ, φ, θ) C_RN(t) P(t) (``sim.inertial``) with the IAU
1976 precession P (``sim.ephemeris.precession_matrix``, ~0.37° in 2026).  Nutation,
UT1 − UTC and TT − UTC are left out there, and said so.  The orbit-frame variant is
LVLH_ROTATING: CCSDS's LVLH (z to nadir, y along −(r × v)) is exactly R.
"""

from __future__ import annotations

import re
import shutil
import tempfile
from dataclasses import dataclass, field, replace
from datetime import UTC, datetime
from pathlib import Path

import numpy as np

from .columns import epoch_ns

# ICRF/GCRF: EME2000 to the frame bias, 1.12e-7 rad; J2000 is EME2000.
INERTIAL_FRAMES = ("EME2000", "J2000", "ICRF", "GCRF")
ORBIT_FRAMES = ("LVLH_ROTATING", "LVLH_INERTIAL", "LVLH")
GAP_FACTOR = 1.5
NORM_TOLERANCE = 1e-5
SPOOL_BYTES = 1 << 22  # a segment's rows beyond this wait on disk for its STOP_TIME
_BODY = re.compile(r"SC_BODY(_\d+)?$")
_QUAT_COLUMNS = {"QUATERNION": 4, "QUATERNION/DERIVATIVE": 8, "QUATERNION/ANGVEL": 7,
                 "QUATERNION/RATE": 7}  # the quaternion comes first; the rest is not read
_META_KEYS = {"OBJECT_NAME", "OBJECT_ID", "CENTER_NAME", "REF_FRAME_A", "REF_FRAME_B",
              "ATTITUDE_DIR", "TIME_SYSTEM", "START_TIME", "USEABLE_START_TIME", "STOP_TIME",
              "USEABLE_STOP_TIME", "ATTITUDE_TYPE", "QUATERNION_TYPE", "EULER_ROT_SEQ",
              "RATE_FRAME", "ANGVEL_FRAME", "INTERPOLATION_METHOD", "INTERPOLATION_DEGREE"}
_EPOCH = re.compile(r"\d{4}-(\d{2}-\d{2}|\d{3})T\d{2}:\d{2}:\d{2}(\.\d*)?Z?$")
_ROW = "%s % .12f % .12f % .12f % .12f\n"


class AemError(ValueError):
    """A bad AEM/APM, in one line naming the file, the line and the problem."""


@dataclass(frozen=True)
class AemMeta:
    """What a written message says about itself."""

    object_name: str
    object_id: str
    ref_frame_a: str = "EME2000"          # or "LVLH_ROTATING" for the orbit-frame variant
    ref_frame_b: str = "SC_BODY_1"
    center_name: str = "EARTH"
    originator: str = "DYNPROP"
    interpolation_method: str = "LAGRANGE"
    interpolation_degree: int = 7
    version: str = "2.0"
    comments: tuple[str, ...] = ()


@dataclass(frozen=True)
class AemSegment:
    """One META/DATA pair (or an APM): ``quaternions`` (N, 4) scalar-last C_{body←frame},
    whatever the file's order and direction, at ``epochs`` (datetime64[ns], UTC)."""

    meta: dict[str, str]
    epochs: np.ndarray
    quaternions: np.ndarray
    frame: str
    body: str
    line: int
    header: dict[str, str] = field(default_factory=dict)

    def seconds_since(self, epoch) -> np.ndarray:
        return (self.epochs - _datetime64(epoch)) / np.timedelta64(1, "s")

    def interpolate(self, epochs) -> np.ndarray:
        """Lagrange of INTERPOLATION_DEGREE on the components over the degree + 1
        nearest rows (Orekit's window), normalised; inside the segment only."""
        t, rows = stamps_of(epochs).astype(np.int64), self.epochs.astype(np.int64)
        if t.size and (t.min() < rows[0] or t.max() > rows[-1]):
            raise ValueError("interpolation epochs outside the segment")
        n = min(int(self.meta.get("INTERPOLATION_DEGREE", "1")), len(rows) - 1) + 1
        first = np.clip(np.searchsorted(rows, t, "right") - 1 - (n - 1) // 2, 0,
                        len(rows) - n)
        # Every epoch's window at once: (M, n) rows, times in s from the window's first.
        idx = first[:, None] + np.arange(n)
        x = (rows[idx] - rows[first][:, None]) / 1e9
        dx = ((t - rows[first]) / 1e9)[:, None] - x
        w = np.ones((t.size, n))
        for i in range(n):
            for j in range(n):
                if j != i:
                    w[:, i] *= dx[:, j] / (x[:, i] - x[:, j])
        q = self.quaternions[idx]
        # q and −q are one attitude: each window's rows on the side of its first.
        q = q * np.sign(np.einsum("mnk,mk->mn", q, q[:, 0]))[..., None]
        out = np.einsum("mn,mnk->mk", w, q)
        return out / np.linalg.norm(out, axis=1, keepdims=True)


def write_aem(out, times, quaternions, meta: AemMeta, **kw) -> list[tuple]:
    """Write ``quaternions`` (N, 4, scalar-last C_{B←A}) at ``times`` (datetimes, ISO
    strings, datetime64, or seconds after ``epoch=``); see ``write_aem_blocks``."""
    return write_aem_blocks(out, [(times, quaternions)], meta, **kw)


def write_aem_blocks(out, blocks, meta: AemMeta, *, epoch=None, cadence_s=None,
                     creation_date=None) -> list[tuple]:
    """Stream ``blocks`` of (times, quaternions) into one AEM at ``out`` (a path or a text
    stream) at bounded memory: a segment's rows wait in a spooled temporary file until
    its STOP_TIME is known.  ``cadence_s`` defaults to the first block's median step.
    Returns (START_TIME, STOP_TIME, rows) per segment."""
    header = _header("AEM", meta, creation_date, cadence_s)
    stream = open(out, "w", encoding="ascii", newline="\n") if isinstance(out, str | Path) \
        else out
    state: dict = {"seg": None}
    try:
        stream.write(header)
        state = {"last": None, "q": None, "seg": None, "done": [], "cadence": cadence_s}
        for times, q in blocks:
            _add_block(stream, state, meta, stamps_of(times, epoch), np.asarray(q, float))
        _close_segment(stream, state, meta)
        if not state["done"]:
            raise AemError("no finite rows to write: an AEM needs a segment")
        return state["done"]
    finally:
        # A block that raised mid-segment leaves that segment's spool open.
        if state.get("seg") is not None:
            state["seg"]["spool"].close()
        if stream is not out:
            stream.close()


def _add_block(stream, state, meta, stamps, q) -> None:
    if q.shape != (len(stamps), 4):
        raise AemError(f"quaternions must be ({len(stamps)}, 4), got {q.shape}")
    keep = np.isfinite(q).all(axis=1)
    stamps, q = stamps[keep], q[keep]
    if not len(q):
        return
    if np.any(np.abs(np.linalg.norm(q, axis=1) - 1) > NORM_TOLERANCE):
        raise AemError("quaternions must be unit quaternions")
    ns, last = stamps.astype(np.int64), state["last"]
    steps = np.diff(ns, prepend=ns[0] - 1 if last is None else last)
    if np.any(steps <= 0):
        raise AemError("epochs must increase strictly")
    if state["cadence"] is None and len(ns) > 1:
        state["cadence"] = float(np.median(np.diff(ns))) / 1e9
    new = steps > GAP_FACTOR * (state["cadence"] or np.inf) * 1e9
    new[0] |= state["seg"] is None
    ref = q[0] if state["q"] is None else state["q"]      # each row in the hemisphere
    flips = np.sign(np.einsum("ij,ij->i", q, np.vstack([ref, q[:-1]])))  # of the last
    q = q * np.cumprod(np.where(flips == 0, 1, flips))[:, None]
    text = np.datetime_as_string(((ns + 500) // 1000).astype("datetime64[us]"), unit="us")
    cuts = np.flatnonzero(new)
    for a, b in zip(np.r_[0, cuts], np.r_[cuts, len(q)], strict=True):
        if a == b:
            continue
        if new[a]:
            _close_segment(stream, state, meta)
            state["seg"] = {"spool": tempfile.SpooledTemporaryFile(SPOOL_BYTES, "w+",
                                                                   encoding="ascii"),
                            "start": str(text[a]), "rows": 0,
                            "gap": None if last is None and a == 0 else steps[a] / 1e9}
        seg, rows = state["seg"], np.empty((b - a, 5), dtype=object)
        rows[:, 0], rows[:, 1:] = text[a:b], q[a:b]
        seg["spool"].write((_ROW * (b - a)) % tuple(rows.ravel()))
        seg["rows"], seg["stop"] = seg["rows"] + b - a, str(text[b - 1])
    state["last"], state["q"] = ns[-1], q[-1]


def _close_segment(stream, state, meta) -> None:
    seg, v1 = state["seg"], meta.version == "1.0"
    if seg is None:
        return
    lines = ["", "META_START"] + ([] if seg["gap"] is None else [
        f"COMMENT after a dropout of {seg['gap']:g} s: do not interpolate across it"])
    lines += [f"OBJECT_NAME = {meta.object_name}", f"OBJECT_ID = {meta.object_id}",
              f"CENTER_NAME = {meta.center_name}", f"REF_FRAME_A = {meta.ref_frame_a}",
              f"REF_FRAME_B = {meta.ref_frame_b}", *(["ATTITUDE_DIR = A2B"] if v1 else []),
              "TIME_SYSTEM = UTC", f"START_TIME = {seg['start']}",
              f"USEABLE_START_TIME = {seg['start']}", f"USEABLE_STOP_TIME = {seg['stop']}",
              f"STOP_TIME = {seg['stop']}", "ATTITUDE_TYPE = QUATERNION",
              *(["QUATERNION_TYPE = LAST"] if v1 else []),
              f"INTERPOLATION_METHOD = {meta.interpolation_method}",
              f"INTERPOLATION_DEGREE = {min(meta.interpolation_degree, seg['rows'] - 1)}",
              "META_STOP", "", "DATA_START", ""]
    stream.write("\n".join(lines))
    seg["spool"].seek(0)
    shutil.copyfileobj(seg["spool"], stream)
    seg["spool"].close()
    stream.write("DATA_STOP\n")
    state["done"].append((seg["start"], seg["stop"], int(seg["rows"])))
    state["seg"] = None


def _header(kind, meta, creation_date, cadence_s) -> str:
    a, b = meta.ref_frame_a, meta.ref_frame_b
    if a not in ("EME2000", *ORBIT_FRAMES) or not _BODY.match(b):
        raise AemError(f"dynprop writes REF_FRAME_A = EME2000 or {', '.join(ORBIT_FRAMES)} "
                       f"and REF_FRAME_B = SC_BODY_n, not {a} and {b}")
    if meta.version not in ("1.0", "2.0"):
        raise AemError(f"version must be 1.0 or 2.0, not {meta.version!r}")
    notes = [*meta.comments,
             f"Quaternion q = [Q1 Q2 Q3 QC], scalar last, rotates frames {a} -> {b}:",
             f"v_{b} = A(q) v_{a}, A(q) = (QC^2 - |qv|^2) I + 2 qv qv' - 2 QC [qv x]",
             "(Markley & Crassidis 2014, Eq. 2.125); q = [e sin(angle/2), cos(angle/2)].",
             "Components to 12 decimals (error <= 5e-13); epochs UTC to the microsecond."]
    notes += [f"{a} = dynprop's orbit frame R: z to nadir, y = -(r x v)/|r x v|."] \
        if a in ORBIT_FRAMES else [
        "EME2000 = dynprop's mean-of-date frame N (IAU 1982 GMST) precessed to J2000",
        "(IAU 1976); nutation and UT1-UTC ignored (<= 1.5e-4 rad)."]
    if cadence_s:
        notes.append(f"CADENCE_S = {cadence_s:g}; a longer dropout starts a new segment.")
    created = creation_date or datetime.now(UTC).strftime("%Y-%m-%dT%H:%M:%S")
    return "\n".join([f"CCSDS_{kind}_VERS = {meta.version}", *(f"COMMENT {c}" for c in notes),
                      f"CREATION_DATE = {created}", f"ORIGINATOR = {meta.originator}", ""])


def write_apm(out, epoch, quaternion, meta: AemMeta, *, creation_date=None) -> None:
    """A 2.0 APM (KVN) with one quaternion block, C_{B←A} at ``epoch``."""
    q = np.asarray(quaternion, dtype=float)
    if q.shape != (4,) or abs(np.linalg.norm(q) - 1) > NORM_TOLERANCE:
        raise AemError("the APM quaternion must be one unit quaternion")
    lines = [_header("APM", replace(meta, version="2.0"), creation_date, None),
             f"OBJECT_NAME = {meta.object_name}", f"OBJECT_ID = {meta.object_id}",
             f"CENTER_NAME = {meta.center_name}", "TIME_SYSTEM = UTC", "",
             f"EPOCH = {np.datetime_as_string(stamps_of(epoch)[0], unit='us')}", "QUAT_START",
             f"REF_FRAME_A = {meta.ref_frame_a}", f"REF_FRAME_B = {meta.ref_frame_b}",
             *(f"{k} = {v:.12f}" for k, v in zip(("Q1", "Q2", "Q3", "QC"), q, strict=True)),
             "QUAT_STOP", ""]
    if isinstance(out, str | Path):
        Path(out).write_text("\n".join(lines), encoding="ascii")
    else:
        out.write("\n".join(lines))


def read_apm(path) -> AemSegment:
    """An APM's quaternion (1.0 or 2.0 KVN) as a one-row segment, C_{body←frame}."""
    name, header, meta, block, q, epoch = str(path), {}, {}, None, {}, None
    for n, line in _lines(path):
        if line.startswith("COMMENT"):
            continue
        if line.endswith(("_START", "_STOP")):
            block = line[:-6] if line.endswith("_START") else None
            continue
        key, value = _kv(name, n, line)
        if key.startswith("CCSDS_") or key in ("CREATION_DATE", "ORIGINATOR", "MESSAGE_ID"):
            header[key] = value
        elif key == "EPOCH":
            epoch = _parse_epochs(name, [value], [n])[0]
        elif block in (None, "QUAT") and key in ("Q1", "Q2", "Q3", "QC"):
            q[key] = _number(name, n, value)
        elif block in (None, "QUAT"):
            meta[key.replace("Q_FRAME", "REF_FRAME").replace("Q_DIR", "ATTITUDE_DIR")] = (value, n)
    if "CCSDS_APM_VERS" not in header or epoch is None or len(q) != 4:
        raise AemError(f"{name}: an APM needs CCSDS_APM_VERS, EPOCH and Q1, Q2, Q3, QC")
    frame, body, flip, _, _ = _convention(name, meta, header["CCSDS_APM_VERS"], apm=True)
    quat = np.array([[q["Q1"], q["Q2"], q["Q3"], q["QC"]]])
    _check_norms(name, quat, [0])
    return AemSegment({k: v for k, (v, _) in meta.items()}, np.array([epoch]),
                      _oriented(quat, flip), frame, body, 0, header)


def read_aem(path) -> list[AemSegment]:
    """Every segment of an AEM (1.0 or 2.0 KVN), quaternions made scalar-last
    C_{body←frame} (FIRST reordered, B2A conjugated: 1.0 only; 2.0 fixes both).  A step
    over ``GAP_FACTOR`` × the cadence (the header's ``CADENCE_S`` comment, else the
    segment's median step) inside a segment is an error, as is every other breach."""
    name, header, segments, state, meta, rows, note, start = str(path), {}, [], "header", {}, \
        [], "", 0
    order = {"META_START": ("header", "stop"), "META_STOP": ("meta",),
             "DATA_START": ("meta_done",), "DATA_STOP": ("data",)}
    for n, line in _lines(path):
        if state == "data" and line != "DATA_STOP":
            if not line.startswith("COMMENT"):
                rows.append((n, line))
        elif line.startswith("COMMENT"):
            note += " " + line
        elif line in order:
            if state not in order[line]:
                raise AemError(f"{name}:{n}: {line} out of place (in the {state} section)")
            if line == "DATA_STOP":
                segments.append(_segment(name, header, meta, rows, start, note))
            meta, start = ({}, n) if line == "META_START" else (meta, start)
            state, rows = {"META_START": "meta", "META_STOP": "meta_done",
                           "DATA_START": "data", "DATA_STOP": "stop"}[line], []
        else:
            key, value = _kv(name, n, line)
            if state == "header" and (header or key == "CCSDS_AEM_VERS"):
                header[key] = value
            elif state == "meta" and key in _META_KEYS:
                meta[key] = (value, n)
            else:
                raise AemError(f"{name}:{n}: unexpected keyword {key} in the {state} section")
    if state != "stop":
        raise AemError(f"{name}: ends inside the {state} section, or has no segment")
    for key in ("CREATION_DATE", "ORIGINATOR"):
        if key not in header:
            raise AemError(f"{name}: the header has no {key} (mandatory)")
    return segments


def _segment(name, header, meta, rows, line, note) -> AemSegment:
    frame, body, flip, first, ncol = _convention(name, meta, header.get("CCSDS_AEM_VERS", ""))
    if not rows:
        raise AemError(f"{name}:{line}: the segment has no data rows")
    values, texts, lines = np.empty((len(rows), 4)), [], [n for n, _ in rows]
    for k, (n, text) in enumerate(rows):
        fields = text.split()
        if len(fields) != 1 + ncol or not _EPOCH.match(fields[0]):
            raise AemError(f"{name}:{n}: expected an epoch and {ncol} numbers, got {text!r}")
        values[k] = [_number(name, n, f) for f in fields[1:5]]
        texts.append(fields[0])
    epochs = _parse_epochs(name, texts, lines)
    steps = np.diff(epochs.astype(np.int64)) / 1e9
    if np.any(steps <= 0):
        k = int(np.argmax(steps <= 0)) + 1
        raise AemError(f"{name}:{lines[k]}: epoch {texts[k]} is not after {texts[k - 1]}")
    lo, hi = (_parse_epochs(name, [meta[k][0]], [meta[k][1]])[0]
              for k in ("START_TIME", "STOP_TIME"))
    if epochs[0] < lo or epochs[-1] > hi:
        k = 0 if epochs[0] < lo else len(rows) - 1
        raise AemError(f"{name}:{lines[k]}: epoch {texts[k]} outside START_TIME..STOP_TIME")
    declared = re.search(r"CADENCE_S\s*=\s*([0-9.eE+]+)", note)
    cadence = float(declared.group(1)) if declared else (np.median(steps) if steps.size else 0)
    if steps.size and steps.max() > GAP_FACTOR * cadence:
        k = int(np.argmax(steps)) + 1
        raise AemError(f"{name}:{lines[k]}: a gap of {steps[k - 1]:g} s ({texts[k - 1]} to "
                       f"{texts[k]}) inside the segment of line {line}, over {GAP_FACTOR:g} × "
                       f"its {cadence:g} s cadence: a dropout must start a new segment")
    q = values[:, [1, 2, 3, 0]] if first else values
    _check_norms(name, q, lines)
    return AemSegment({k: v for k, (v, _) in meta.items()}, epochs, _oriented(q, flip), frame,
                      body, line, dict(header))


def _convention(name, meta, version, apm=False):
    """(external frame, body frame, conjugate?, scalar first?, columns) from the metadata."""
    where, v1 = f"{name}:{min((n for _, n in meta.values()), default=0)}", version[:2] == "1."
    if not re.fullmatch(r"[12]\.\d+", version):
        raise AemError(f"{name}: format version {version!r} missing or unsupported (1.x, 2.x)")
    need = ["OBJECT_NAME", "OBJECT_ID", "REF_FRAME_A", "REF_FRAME_B", "TIME_SYSTEM"] + (
        [] if apm else ["START_TIME", "STOP_TIME", "ATTITUDE_TYPE"]) + (
        [] if not v1 else ["ATTITUDE_DIR"] if apm else ["ATTITUDE_DIR", "QUATERNION_TYPE"])
    for key in need:
        if key not in meta:
            raise AemError(f"{where}: the metadata have no {key} (mandatory in a {version} "
                           f"{'APM' if apm else 'AEM'})")
    value = {k: v.upper() for k, (v, _) in meta.items()}
    line = {k: n for k, (_, n) in meta.items()}
    a, b, kind = value["REF_FRAME_A"], value["REF_FRAME_B"], value.get("ATTITUDE_TYPE")
    _check_frames(a, b, f"{name}:{line['REF_FRAME_A']}")
    if value["TIME_SYSTEM"] != "UTC":
        raise AemError(f"{name}:{line['TIME_SYSTEM']}: TIME_SYSTEM = {value['TIME_SYSTEM']}: "
                       "dynprop reads UTC only")
    if not apm and kind not in _QUAT_COLUMNS:
        raise AemError(f"{name}:{line['ATTITUDE_TYPE']}: ATTITUDE_TYPE = {kind}: dynprop reads "
                       f"quaternions only ({', '.join(_QUAT_COLUMNS)})")
    for key, standard, reverse in (("ATTITUDE_DIR", "A2B", "B2A"),
                                   ("QUATERNION_TYPE", "LAST", "FIRST")):
        got = value.get(key, standard)
        if got not in (standard, reverse):
            raise AemError(f"{name}:{line[key]}: {key} = {got} is neither {standard} nor {reverse}")
        if got == reverse and not v1:
            raise AemError(f"{name}:{line[key]}: {key} = {got} in a {version} message: 504.0-B-2 "
                           f"fixes {standard} (a reversed convention flag; a 1.0 file may say it)")
    body_a = bool(_BODY.match(a))
    flip = (value.get("ATTITUDE_DIR") == "B2A") != body_a
    return ((b, a) if body_a else (a, b)) + (flip, value.get("QUATERNION_TYPE") == "FIRST",
                                              _QUAT_COLUMNS.get(kind, 4))


def _check_frames(a, b, where) -> None:
    known = INERTIAL_FRAMES + ORBIT_FRAMES
    for key, frame in (("REF_FRAME_A", a), ("REF_FRAME_B", b)):
        if frame not in known and not _BODY.match(frame):
            raise AemError(f"{where}: {key} = {frame} is not a frame dynprop reads "
                           f"({', '.join(known)}, SC_BODY_n)")
    if bool(_BODY.match(a)) == bool(_BODY.match(b)):
        raise AemError(f"{where}: exactly one of REF_FRAME_A = {a}, REF_FRAME_B = {b} must be "
                       "the spacecraft body SC_BODY_n")


def _check_norms(name, q, lines) -> None:
    err = np.abs(np.linalg.norm(q, axis=1) - 1)
    if np.any(err > NORM_TOLERANCE):
        k = int(np.argmax(err))
        raise AemError(f"{name}:{lines[k]}: quaternion norm {np.linalg.norm(q[k]):.6g} is not 1 "
                       f"(tolerance {NORM_TOLERANCE:g}): not a unit quaternion")


def _oriented(q, flip) -> np.ndarray:
    q = q / np.linalg.norm(q, axis=1, keepdims=True)
    return q * np.array([-1, -1, -1, 1]) if flip else q


def _lines(path):
    with open(path, encoding="utf-8", errors="replace") as f:
        for n, raw in enumerate(f, 1):
            if raw.strip():
                yield n, raw.strip()


def _kv(name, n, line) -> tuple[str, str]:
    key, eq, value = line.partition("=")
    if not eq or not key.strip():
        raise AemError(f"{name}:{n}: expected KEY = value, got {line!r}")
    return key.strip().upper(), value.strip()


def _number(name, n, text) -> float:
    try:
        return float(text)
    except ValueError:
        raise AemError(f"{name}:{n}: {text!r} is not a number") from None


def _parse_epochs(name, texts, lines) -> np.ndarray:
    try:
        return np.array([t.rstrip("Z") for t in texts], dtype="datetime64[ns]")
    except ValueError:
        out = []
        for t, n in zip(texts, lines, strict=True):
            m = re.fullmatch(r"(\d{4})-(\d{3})(T.*)", t.rstrip("Z"))  # day-of-year form
            try:
                out.append(np.datetime64(t.rstrip("Z"), "ns") if not m else np.datetime64(
                    str(np.datetime64(f"{m[1]}-01-01") + int(m[2]) - 1) + m[3], "ns"))
            except ValueError:
                raise AemError(f"{name}:{n}: {t!r} is not a CCSDS UTC epoch") from None
        return np.array(out, dtype="datetime64[ns]")


def _datetime64(x) -> np.datetime64:
    if isinstance(x, datetime):
        if x.tzinfo is None:
            raise ValueError(f"{x} has no time zone: give UTC epochs as aware datetimes")
        return np.datetime64(x.astimezone(UTC).replace(tzinfo=None), "ns")
    if isinstance(x, str) and re.search(r"[+-]\d{2}:?\d{2}$", x.strip()):
        return epoch_ns(x)
    return np.datetime64(x.strip().rstrip("Z") if isinstance(x, str) else x, "ns")


def stamps_of(times, epoch=None) -> np.ndarray:
    """datetime64[ns] (UTC) of ``times``: datetime64, aware datetimes, ISO text (a zone
    converted, none read as UTC), or seconds after ``epoch`` (rounded to the ns), as
    ``write_aem_blocks`` dates its rows."""
    a = np.atleast_1d(np.asarray(times))
    if a.dtype.kind in "iuf":
        if epoch is None:
            raise ValueError("times in seconds need epoch=")
        return _datetime64(epoch) + np.round(a.astype(float) * 1e9).astype("timedelta64[ns]")
    if a.dtype.kind == "M":
        return a.astype("datetime64[ns]")
    return np.array([_datetime64(x) for x in a.ravel()], dtype="datetime64[ns]")
