"""comparison.npz at the output cadence, written window by window.

Row i is the sample i·stride (``output.interval_s``), every value the one at that
sample, exactly what ``comparison.comparison_arrays`` gives for it.  When rows are
decimated (stride > 1), the series whose peaks matter also get a min/max envelope
per output interval (``<key>_min``, ``<key>_max``: over the samples of row i up
to row i+1, NaN where none is finite), so a gap-end error or a NEES spike between
two rows still shows in the figures; NEES is computed every ``NEES_STRIDE``
samples and its envelope covers those.

Each key is a ``.npy`` file in a scratch folder of the run, mapped only while a
window is written into it, so memory does not grow with the run; ``finish``
stores them into comparison.npz (a zip of .npy files, as ``np.savez`` makes, with
fixed timestamps so the bytes repeat).
"""

from __future__ import annotations

import shutil
import zipfile
from pathlib import Path

import numpy as np

from ..records import FilterHistory, Window
from ..samples import output_rows
from .columns import PITCH_FACTORS, display_factors
from .comparison import DIFF_STATES, ComparisonInputs, PitchRows, comparison_arrays

DIFF_COLS = list(DIFF_STATES)


def _at(h: FilterHistory, k) -> FilterHistory:
    return FilterHistory(h.x[k], None if h.sigma is None else h.sigma[k], h.innovations[k],
                         h.innovation_var[k], h.backend)


def _pitch_at(w: Window, k, pick) -> PitchRows | None:
    p = w.pitch
    if p is None:
        return None
    # A sparse truth's pitch (NaN between its rows) has its errors here, its NEES in
    # the summary only (``run.pitch.history_at``).
    truth = w.pitch_truth is not None and (p.nees is not None or w.truth_rows is not None)
    return PitchRows(p.x[k], p.sigma[k], p.innovations[k], p.innovation_var[k],
                     w.pitch_truth[k] if truth else None,
                     None if p.nees is None else p.nees[pick])


FILL_ROWS = 1 << 16


def _filled(path: Path, dtype, shape: tuple, fill) -> None:
    """A .npy file of ``shape`` holding ``fill``, written a block at a time: filling
    a mapping of it would hold every page of the file at once (a month at every
    sample is hundreds of MB per key)."""
    m = np.lib.format.open_memmap(path, mode="w+", dtype=dtype, shape=shape)
    offset = m.offset
    del m
    row = np.full((min(FILL_ROWS, shape[0]), *shape[1:]), fill, dtype=dtype)
    with open(path, "r+b") as f:
        f.seek(offset)
        for a in range(0, shape[0], FILL_ROWS):
            f.write(row[:min(FILL_ROWS, shape[0] - a)].tobytes())


class ComparisonRows:
    def __init__(self, folder: Path, n_samples: int, stride: int):
        self.folder = Path(folder)
        self.folder.mkdir()
        self.stride = stride
        self.n_rows = -(-n_samples // stride)
        self.maps: dict[str, np.ndarray] = {}

    def _map(self, key: str, shape, dtype, fill=np.nan) -> np.ndarray:
        """The key's file mapped for this window; ``_release`` unmaps it after, so the
        pages written leave this process's memory (a mapping kept open would hold
        every page the run ever wrote)."""
        path = self.folder / f"{key}.npy"
        if key not in self.maps:
            _filled(path, dtype, (self.n_rows, *shape), fill)
            self.maps[key] = True
        if not isinstance(self.maps[key], np.memmap):
            m = np.load(path, mmap_mode="r+")
        else:
            return self.maps[key]
        self.maps[key] = m
        return m

    def _release(self) -> None:
        for key, m in self.maps.items():
            if isinstance(m, np.memmap):
                m.flush()
                self.maps[key] = True

    def add(self, w: Window, nees_idx, err=None, err_lin=None) -> None:
        """One window's rows; ``err`` and ``err_lin`` (x̂ − truth of the real filter and
        of the twin's) when the caller has them already."""
        a = w.start
        n = len(w.t_s)
        rows = output_rows(a, a + n, self.stride)
        k = rows - a
        at_nees = np.isin(rows, nees_idx)
        pick = np.searchsorted(nees_idx, rows[at_nees])
        truth, twin = w.truth_model is not None, w.linear is not None
        c = ComparisonInputs(
            w.params.omega_n_radps, _at(w.real, k),
            truth_model=w.truth_model[k] if truth else None,
            smoothed_x=None if w.smoothed_x is None else w.smoothed_x[k],
            linear_x=w.linear.x[k] if twin else None,
            twin_model=w.twin_model[k] if twin else None, true_euler_rad=w.euler_rows,
            filters={name: _at(h, k) for name, h in w.filters.items()},
            pitch=_pitch_at(w, k, pick))
        present = np.isfinite(w.measured.yaw_rad[k])
        nees_data = (np.flatnonzero(at_nees),
                     None if w.nees_real is None else w.nees_real[pick],
                     None if w.nees_linear is None else w.nees_linear[pick])
        arrays = comparison_arrays(c, w.t_s[k], present, nees_data, w.tel_rows)
        lo = rows[0] // self.stride if len(rows) else None
        for key, v in arrays.items():
            if lo is not None:
                self._map(key, v.shape[1:], v.dtype)[lo:lo + len(rows)] = v
        if self.stride > 1:
            self._envelopes(w, a, n, nees_idx, err, err_lin)
        self._release()

    def _envelopes(self, w: Window, a, n, nees_idx, err=None, err_lin=None) -> None:
        # Rounding keeps order, so the least of f·v over an interval is f times the
        # least of v when f > 0 (its greatest when f < 0: the rates' factor has
        # ω_n's sign), the same double.  So each series is scaled after its
        # reduction, on the rows kept, not before.
        f = display_factors(w.params.omega_n_radps)
        samples = np.arange(a, a + n)
        truth, twin = w.truth_model is not None, w.linear is not None
        if err is None and truth:
            err = w.real.x - w.truth_model
        if err_lin is None and twin:
            err_lin = w.linear.x - w.twin_model
        series = {}
        if truth:
            series["err_real"] = (samples, err, f)
        if twin:
            series["err_linear"] = (samples, err_lin, f)
            if truth:
                series["err_real_minus_linear"] = (samples, (err - err_lin)[:, DIFF_COLS],
                                                   f[DIFF_COLS])
            series["nees_linear"] = (nees_idx, w.nees_linear, None)
        if w.smoothed_x is not None and truth:
            series["err_smoothed"] = (samples, w.smoothed_x - w.truth_model, f)
        if truth:
            series["nees_real"] = (nees_idx, w.nees_real, None)
        p = w.pitch
        if p is not None and truth and (p.nees is not None or w.truth_rows is not None):
            series["err_pitch"] = (samples, p.x - w.pitch_truth, PITCH_FACTORS)
        if p is not None and p.nees is not None:
            series["nees_pitch"] = (nees_idx, p.nees, None)
        for key, (idx, v, scale) in series.items():
            if len(idx) == 0:
                continue
            ids = idx // self.stride
            starts = np.r_[0, np.flatnonzero(np.diff(ids)) + 1]
            rows = ids[starts]
            least, most = (op.reduceat(v, starts, axis=0) for op in (np.fmin, np.fmax))
            if scale is not None:
                least, most = (np.where(scale > 0, least, most) * scale,
                               np.where(scale > 0, most, least) * scale)
            for suffix, op, red in (("_min", np.fmin, least), ("_max", np.fmax, most)):
                m = self._map(key + suffix, v.shape[1:], np.float32)
                red = red.astype(np.float32)
                # A row whose interval began in the previous window keeps its part.
                red[0] = op(red[0], m[rows[0]])
                m[rows] = red

    def finish(self, path: Path, interval_s: float) -> None:
        """Write comparison.npz and remove the scratch folder."""
        self._release()
        if self.stride > 1:
            np.save(self.folder / "output_interval_s.npy", np.asarray(interval_s, dtype=float))
            self.maps["output_interval_s"] = True
        tmp = path.with_name(f".{path.name}.tmp")
        with zipfile.ZipFile(tmp, "w", zipfile.ZIP_STORED, allowZip64=True) as zf:
            for key in self.maps:
                info = zipfile.ZipInfo(f"{key}.npy", date_time=(1980, 1, 1, 0, 0, 0))
                with open(self.folder / f"{key}.npy", "rb") as src, \
                        zf.open(info, "w", force_zip64=True) as dst:
                    shutil.copyfileobj(src, dst, 1 << 20)
        self.maps.clear()
        shutil.rmtree(self.folder)
        tmp.replace(path)

