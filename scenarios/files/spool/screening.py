"""``files.screen.screen`` a block at a time, with the whole file's verdicts.

The row-local rules (non-finite, range, field of view, a yaw with its σ) are the
whole screen's on each block's rows.  The jump rule judges each present reading
against the median of 5 present readings around it (the first and last full window
at the file's ends), so a reading is judged only once two more present readings of
its column follow it (``JumpCarry``): each column carries its last 5 present readings
into the next block, and a verdict on a reading of an earlier block is handed back
as a patch of the scratch column.  A wheel's screened first or last reading is held
from the nearest good one when the file ends (``_hold_wheel_ends``).  The report is
the whole screen's: its entries in the order the whole screen finds them.
"""

from __future__ import annotations

import numpy as np

from ...config.screen import HALF_WINDOW
from ..screen import HEAD_NAMES, Screened, ScreenReport, _screen_heads, bad_flags, limits

WIDTH = 2 * HALF_WINDOW + 1     # the running median's present readings
CARRY = WIDTH                   # the last window of the file, for its last readings


def median_of_five(a, b, c, d, e) -> np.ndarray:
    """The middle of five values elementwise, by minima and maxima: the very value
    ``np.median`` picks (a median of an odd count is one of the values), or the
    other zero of ±0, which the rule's |x − median| cannot tell apart."""
    assert WIDTH == 5
    lo1, hi1 = np.minimum(a, b), np.maximum(a, b)
    lo2, hi2 = np.minimum(c, d), np.maximum(c, d)
    # The smaller of the two pairs' minima and the larger of their maxima cannot be
    # the median; the median of the other three and e is then...
    lo = np.maximum(lo1, lo2)
    hi = np.minimum(hi1, hi2)
    # ...the median of (lo, hi, e).
    return np.maximum(np.minimum(lo, hi), np.minimum(np.maximum(lo, hi), e))


class JumpCarry:
    """The jump rule (``screen.jumps``) over one column's present readings as they
    arrive: ``feed`` the block's, get back the global rows judged so far and which
    were jumps; ``finish`` judges the last with the file's last full window."""

    def __init__(self, rate: float, allowance: float):
        self.rate, self.allowance = rate, allowance
        self.x = np.zeros(0)
        self.t = np.zeros(0)
        self.rows = np.zeros(0, dtype=np.int64)
        self.g0 = 0             # global index (among present readings) of x[0]
        self.decided = 0        # readings judged so far

    def feed(self, x, t, rows, final: bool = False):
        """(rows, values, is_jump) of the readings judged with these."""
        x = np.concatenate([self.x, x])
        t = np.concatenate([self.t, t])
        rows = np.concatenate([self.rows, rows])
        m = self.g0 + len(x)                      # readings seen
        last = m - 1
        if final:
            i = np.arange(self.decided, m)
            start = np.clip(i - HALF_WINDOW, 0, m - WIDTH) if m >= WIDTH else None
        else:
            stop = last - HALF_WINDOW + 1 if last >= WIDTH - 1 else self.decided
            i = np.arange(self.decided, max(stop, self.decided))
            start = np.maximum(i - HALF_WINDOW, 0)
        j = i - self.g0
        jump = np.zeros(len(i), dtype=bool)
        if start is not None and len(i):
            s = start - self.g0
            med = median_of_five(*(x[s + q] for q in range(WIDTH)))
            span = np.maximum(np.abs(t[j] - t[s]), np.abs(t[s + WIDTH - 1] - t[j]))
            jump = np.abs(x[j] - med) > self.rate * span + self.allowance
        out = rows[j], x[j], jump
        self.decided += len(i)
        keep = min(CARRY, len(x))
        self.g0 = m - keep
        # Copies: a view would keep the whole block's readings alive.
        self.x, self.t, self.rows = (x[len(x) - keep:].copy(), t[len(x) - keep:].copy(),
                                     rows[len(x) - keep:].copy())
        return out


def slot_keys(columns) -> list[tuple]:
    """Every (rule, column) the whole screen drops in, in its order of calls; an
    entry of its report is a key that dropped something."""
    measured = [c for c in columns if c not in ("t_s", "sun_head")]
    wheels = [c for c in columns if c.startswith("wheel") and c.endswith("_rpm")]
    keys = [("non-finite", c) for c in measured]
    keys += [("range", c) for c in ("roll_deg", "pitch_deg", "yaw_deg", "yaw_sigma_deg")
             if c in columns]
    keys += [("range", c) for c in wheels]
    keys += [("flag", "maneuver")] if "maneuver" in columns else []
    for head in HEAD_NAMES:
        keys += [("field of view", f"{head}_alpha_deg"), ("field of view", f"{head}_beta_deg"),
                 ("field of view", "yaw_deg", head)]
    keys += [("non-finite", "yaw_deg", "sigma"), ("range", "yaw_deg", "sigma")]
    keys += [("jump", c) for c in ("roll_deg", "pitch_deg") if c in columns]
    return keys + [("jump", c) for c in wheels]


class BlockScreen:
    """The screen of a file read in blocks (``screen.screen``, whole)."""

    def __init__(self, s, names: dict[str, str]):
        self.lim = limits(s)
        self.names = names
        self.keys: list[tuple] | None = None
        self.found: dict[tuple, list] = {}
        self.carries: dict[str, JumpCarry] = {}
        self.good: dict[str, list] = {}       # wheel -> [first (row, v), last (row, v)]

    @property
    def enabled(self) -> bool:
        return self.lim is not None

    def _setup(self, out: dict) -> None:
        self.keys = slot_keys(list(out))
        self.found = {k: [] for k in self.keys}
        lim = self.lim
        for name in ("roll_deg", "pitch_deg"):
            if name in out:
                self.carries[name] = JumpCarry(lim.attitude_rate_degps, lim.earth_allowance_deg)
        self.wheels = [c for c in out if c.startswith("wheel") and c.endswith("_rpm")]
        for k, name in enumerate(self.wheels):
            rate = lim.wheel_rate_rpmps[min(k, len(lim.wheel_rate_rpmps) - 1)]
            self.carries[name] = JumpCarry(rate, lim.wheel_allowance_rpm)
            self.good[name] = [None, None]

    def block(self, cols: dict, written: dict, row0: int) -> tuple[dict, list]:
        """The block's columns screened as far as its rows can be judged, and the
        patches (column, row, value) for rows of earlier blocks."""
        if self.lim is None:
            return cols, []
        out = dict(cols)
        if self.keys is None:
            self._setup(out)
        lim = self.lim

        def drop(key, name, mask):
            if mask.any():
                rows = np.flatnonzero(mask)
                self.found[key].append((rows + row0, out[name][rows].copy()))
                out[name] = np.where(mask, np.nan, out[name])

        for key in self.keys:
            if key[0] == "non-finite" and len(key) == 2:
                name = key[1]
                bad = np.isinf(out[name])
                if name in written:
                    bad = bad | written[name]
                drop(key, name, bad)
        for name in ("roll_deg", "pitch_deg"):
            if name in out:
                drop(("range", name), name, np.abs(out[name]) > lim.earth_range_deg)
        if "yaw_deg" in out:
            drop(("range", "yaw_deg"), "yaw_deg", np.abs(out["yaw_deg"]) > 180.0)
        if "yaw_sigma_deg" in out:
            drop(("range", "yaw_sigma_deg"), "yaw_sigma_deg", out["yaw_sigma_deg"] <= 0)
        for name in self.wheels:
            drop(("range", name), name, np.abs(out[name]) > lim.wheel_speed_max_rpm)
        if "maneuver" in out:
            drop(("flag", "maneuver"), "maneuver", bad_flags(out["maneuver"]))
        head = [None]

        def heads_drop(name, mask, reason):
            if name == "yaw_deg":
                drop(("field of view", "yaw_deg", head[0]), name, mask)
            else:
                head[0] = name.split("_")[0]
                drop(("field of view", name), name, mask)
        _screen_heads(out, lim, heads_drop)
        for reason in ("non-finite", "range"):
            sigma = self.found.get((reason, "yaw_sigma_deg"))
            if sigma and sigma[-1][0][0] >= row0 and "yaw_deg" in out:
                mask = np.zeros(len(out["t_s"]), dtype=bool)
                mask[sigma[-1][0] - row0] = True
                drop((reason, "yaw_deg", "sigma"), "yaw_deg", mask & np.isfinite(out["yaw_deg"]))
        patches, mask = [], None
        t = out["t_s"]
        for name, carry in self.carries.items():
            ok = np.flatnonzero(np.isfinite(out[name]))
            judged = carry.feed(out[name][ok], t[ok], ok + row0)
            for r in self._verdicts(name, judged):
                if r >= row0:
                    mask = np.zeros(len(t), dtype=bool) if mask is None else mask
                    mask[r - row0] = True
                else:
                    patches.append((name, r, np.nan))
            if mask is not None:
                out[name] = np.where(mask, np.nan, out[name])
                mask = None
        return out, patches

    def _verdicts(self, name, judged) -> list[int]:
        """The rows judged jumps (recorded), after noting each wheel's first and last
        good reading."""
        rows, values, jump = judged
        if name in self.good and (~jump).any():
            good = np.flatnonzero(~jump)
            if self.good[name][0] is None:
                self.good[name][0] = (int(rows[good[0]]), float(values[good[0]]))
            self.good[name][1] = (int(rows[good[-1]]), float(values[good[-1]]))
        if not jump.any():
            return []
        self.found[("jump", name)].append((rows[jump], values[jump]))
        return [int(r) for r in rows[jump]]

    def finish(self, n_rows: int, t_s) -> tuple[ScreenReport, list]:
        """The whole screen's report (``t_s``: every row's time, or a stand-in that
        gives them) and the last patches: the last readings' verdicts and the
        wheels' ends held."""
        if self.lim is None:
            return ScreenReport(False, None, (), t_s, self.names), []
        patches = []
        for name, carry in self.carries.items():
            judged = carry.feed(np.zeros(0), np.zeros(0), np.zeros(0, dtype=np.int64), final=True)
            patches += [(name, r, np.nan) for r in self._verdicts(name, judged)]
        found = []
        for key in self.keys or ():
            parts = self.found[key]
            if parts:
                rows = np.concatenate([p[0] for p in parts])
                values = np.concatenate([p[1] for p in parts])
                found.append(Screened(key[1], key[0], rows, values))
        if not found:
            return ScreenReport(True, self.lim, (), t_s, self.names), patches
        held = []
        for name in self.wheels:
            rows = [x.rows for x in found if x.column == name]
            first, last = self.good[name]
            if not rows or first is None:
                continue
            rows = np.concatenate(rows)
            for end, near in ((0, first), (n_rows - 1, last)):
                if end in rows:
                    patches.append((name, end, near[1]))
                    held.append((name, int(end), near[0]))
        return ScreenReport(True, self.lim, tuple(found), t_s, self.names, tuple(held)), patches
