"""The page of a `dynprop simulate` directory: the truth's attitude, wheels and
momentum against the telemetry over time (docs/outputs.md, "truth.csv",
"telemetry.csv").  A simulation judges nothing, so the page has no verdict; its
table gives what the scenario asked for and what the files hold (worked out
here: the rows, the share of samples with a Sun-sensor yaw, the Sun gaps and the
eclipses).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ...files.csvio import comments
from .. import streamed
from .. import traces as tr
from ..cells import Table, cell, text
from ..page_parts import page, run_scale
from ..render import Page, Section
from ..run_figures import Plot
from ..source import ReportInputError, Source

SCENARIO = "scenario.yaml"
TRUTH_COLUMNS = ("t_s", "yaw_deg", "roll_deg", "pitch_deg", "h_Nms", "eclipse")
TEL_COLUMNS = ("t_s", "yaw_deg", "roll_deg", "pitch_deg", "sun_head")
ANGLES = ("yaw_deg", "roll_deg", "pitch_deg")
HEADS = {0: "dss", 1: "cass1", 2: "cass2"}


def _read(path, wanted: tuple[str, ...], **folds) -> streamed.Columns:
    """What the page draws and counts of a CSV's columns ``wanted`` (the angles it
    must have, the others where it has them, the wheels' whatever their number),
    read in blocks (``streamed``); a file that is not one is bad input."""
    names = [c for c in streamed.header(path) if c in wanted
             or (c.startswith("wheel") and c.endswith("_rpm"))]
    try:
        return streamed.read_columns(path, [*dict.fromkeys(["t_s", *ANGLES, *names])],
                                     **folds)
    except ValueError as exc:
        raise ReportInputError(str(exc)) from None


def _tel(path) -> streamed.Columns:
    """telemetry.csv's: the magnitudes' 99th percentiles, the runs without a yaw, the
    samples with one and the yaws from each Sun-sensor head."""
    have = streamed.header(path)
    sums = {"yaw": lambda c: int(np.isfinite(c["yaw_deg"]).sum())}
    if "sun_head" in have:
        for code in HEADS:
            sums[code] = lambda c, code=code: int(np.sum(
                c["sun_head"][np.isfinite(c["sun_head"])].astype(int) == code))
    return _read(path, TEL_COLUMNS, p99=ANGLES, sums=sums,
                 runs={"no_yaw": lambda c: ~np.isfinite(c["yaw_deg"])})


def gaps_of(spans, min_len: float) -> list[tuple[float, float]]:
    """The runs without a yaw at least ``min_len`` long (axis units): the Sun gaps."""
    return [s for s in spans if s[1] - s[0] >= min_len]


def _range(truth: streamed.Columns, tel: streamed.Columns, name: str, pad: float = 1.15):
    """A symmetric y range holding the truth and 99% of the readings: the coarse Sun
    sensors' yaw near noon reaches tens of degrees and would flatten the rest (the
    autoscale button shows it all)."""
    p99 = tel.p99[name]
    top = max(truth.abs_max[name] if truth.rows else 0.0, p99 if p99 is not None else 0.0)
    return (-pad * top, pad * top) if top > 0 and np.isfinite(top) else None


@dataclass(frozen=True)
class Axis:
    """The page's time axis: seconds per unit, its title, the shading, the span."""
    scale: float
    title: str
    shapes: list
    legend: list
    range: tuple[float, float]


def attitude(truth: streamed.Columns, tel: streamed.Columns, ax: Axis) -> Plot:
    """Yaw, roll and pitch: the truth beside what the sensors gave (the ground's yaw
    absent in the Sun gaps), then which Sun-sensor head gave the yaw."""
    data, panels = list(ax.legend), []
    for i, n in enumerate(("yaw", "roll", "pitch")):
        y, k = tr.axis(i), f"{n}_deg"
        panels.append({"title": f"{n} (deg)", "range": _range(truth, tel, k)})
        data += tr.draw(tel.in_unit(k, ax.scale), "telemetry" if i else "telemetry (ground yaw)",
                        tr.COLORS["real"], y, group="tel", show=i == 0, mode="markers")
        data += tr.draw(truth.in_unit(k, ax.scale), "truth", tr.COLORS["truth"], y,
                        group="truth", show=i == 0)
    if "sun_head" in tel.series:
        y = tr.axis(len(panels))
        panels.append({"title": "Sun head (0 dss, 1/2 cass)"})
        data += tr.draw(tel.in_unit("sun_head", ax.scale), "Sun-sensor head",
                        tr.COLORS["linear"], y, mode="markers")
    caption = ("The truth (3-1-2 Euler angles of the body against the orbit frame) and the "
               "telemetry: Earth-sensor roll and pitch, the ground's yaw from the Sun sensors "
               "(absent in the Sun gaps, shaded) and the head that gave it; the initial "
               "scales hold the truth and 99% of the readings. Beyond "
               f"{tr.MAX_POINTS} rows each series is the band of its extremes per bin.")
    layout = tr.stacked_layout(panels, ax.title, 190, ax.shapes, ax.range)
    return Plot("sim-attitude", "Attitude: truth and telemetry", caption,
                {"data": data, "layout": layout})


def wheels(truth: streamed.Columns, tel: streamed.Columns, ax: Axis) -> Plot:
    data, panels = list(ax.legend), []
    names = sorted(k for k in truth.series if k.startswith("wheel") and k.endswith("_rpm"))
    for i, k in enumerate(names):
        y = tr.axis(i)
        panels.append({"title": f"{k[:-4]} (rpm)"})
        if k in tel.series:
            data += tr.draw(tel.in_unit(k, ax.scale), "tachometer", tr.COLORS["real"], y,
                            group="tach", show=i == 0, mode="markers")
        data += tr.draw(truth.in_unit(k, ax.scale), "truth", tr.COLORS["truth"], y,
                        group="truth", show=i == 0)
    if "h_Nms" in truth.series:
        y = tr.axis(len(panels))
        panels.append({"title": "h (N m s)"})
        data += tr.draw(truth.in_unit("h_Nms", ax.scale), "h, truth", tr.COLORS["smoothed"], y)
    caption = ("Each wheel's speed, true and as the tachometer read it, and h, the wheels' "
               "momentum along body z (the filter's h state).")
    layout = tr.stacked_layout(panels, ax.title, 170, ax.shapes, ax.range)
    return Plot("sim-wheels", "Wheels and momentum", caption, {"data": data, "layout": layout})


def summary_table(scenario: dict, truth: streamed.Columns, tel: streamed.Columns, gaps_h,
                  eclipse_h) -> Table:
    rows = [[text(k), cell(scenario.get(k), SCENARIO, k)] for k in
            ("name", "seed", "epoch_utc", "duration_s", "sample_interval_s") if k in scenario]
    rows += [[text("truth.csv rows (here)"), cell(truth.rows)],
             [text("telemetry.csv rows (here)"), cell(tel.rows)],
             [text("samples with a Sun-sensor yaw (here)"),
              cell(tel.sums["yaw"] / tel.rows if tel.rows else None)],
             [text("Sun gaps (here)"), cell(len(gaps_h))],
             [text("longest Sun gap, h (here)"), cell(max((b - a for a, b in gaps_h),
                                                          default=None))],
             [text("eclipse, h in all (here)"), cell(eclipse_h)]]
    if "sun_head" in tel.series:
        for code, name in HEADS.items():
            rows.append([text(f"yaws from {name} (here)"), cell(tel.sums[code])])
    return Table("sim-summary", ["", "value"], rows, "The scenario (scenario.yaml) and what the "
                 "files hold (worked out here)")


def build(src: Source, command: str | None, requirement_deg: float | None = None) -> Page:
    scenario, path = src.scenario or {}, src.path
    truth = _read(path / "truth.csv", TRUTH_COLUMNS,
                  runs={"eclipse": lambda c: c["eclipse"] > 0}
                  if "eclipse" in streamed.header(path / "truth.csv") else None)
    if not truth.rows:
        raise ReportInputError(f"{path / 'truth.csv'}: no rows")
    tel = _tel(path / "telemetry.csv")
    scale, unit = tr.time_unit(truth.last_t - truth.first_t)
    min_h = float((scenario.get("estimator") or {}).get("sun_gap_min_h", 4.0))
    gaps = gaps_of([(a / scale, b / scale) for a, b in tel.runs["no_yaw"]],
                   min_h * 3600 / scale)
    ecl = [(a / scale, b / scale) for a, b in truth.runs.get("eclipse", [])]
    shapes = tr.shades(gaps, "sun_gap") + tr.shades(ecl, "eclipse")
    legend = ([tr.legend_only(f"Sun gap (≥ {min_h:g} h without yaw)", tr.SHADES["sun_gap"])]
              if gaps else []) + ([tr.legend_only("eclipse", tr.SHADES["eclipse"])]
                                  if ecl else [])
    ax = Axis(scale, f"time since epoch ({unit})", shapes, legend,
              (truth.first_t / scale, truth.last_t / scale))
    gaps_h = [(a * scale / 3600, b * scale / 3600) for a, b in gaps]
    eclipse_h = sum(b - a for a, b in ecl) * scale / 3600
    epoch = comments(path / "telemetry.csv").get("epoch_utc")
    intro = ("What `dynprop simulate` wrote: the truth and the telemetry, for `dynprop "
             "estimate` or `dynprop run`'s figures; nothing here is judged."
             + (f" telemetry.csv says it was taken from {epoch}." if epoch else ""))
    sections = [Section("summary", "Summary", intro,
                        tables=[summary_table(scenario, truth, tel, gaps_h, eclipse_h)])]
    sections.append(Section("attitude", "Attitude", plots=[attitude(truth, tel, ax)]))
    sections.append(Section("wheels", "Wheels", plots=[wheels(truth, tel, ax)]))
    return page(src, command, "simulate", f"{scenario.get('name')}: dynprop simulate",
                run_scale(scenario), sections)
