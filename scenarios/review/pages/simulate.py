"""The page of a `dynprop simulate` directory: the truth's attitude, wheels and
momentum against the telemetry over time (docs/outputs.md, "truth.csv",
"telemetry.csv").  A simulation judges nothing, so the page has no verdict; its
table gives what the scenario asked for and what the files hold (worked out
here: the rows, the share of samples with a Sun-sensor yaw, the Sun gaps and the
eclipses).
"""

from __future__ import annotations

import numpy as np

from ...files.csvio import comments, read_csv
from .. import traces as tr
from ..cells import Table, cell, text
from ..page_parts import page, run_scale
from ..render import Page, Section
from ..run_figures import Plot
from ..source import ReportInputError, Source

SCENARIO = "scenario.yaml"
TRUTH_COLUMNS = ("t_s", "yaw_deg", "roll_deg", "pitch_deg", "h_Nms", "eclipse")
TEL_COLUMNS = ("t_s", "yaw_deg", "roll_deg", "pitch_deg", "yaw_sigma_deg", "sun_head")
HEADS = {0: "dss", 1: "cass1", 2: "cass2"}


def _read(path, wanted: tuple[str, ...]) -> dict:
    """The columns of a CSV the page draws (the wheels' too, whatever their number);
    a file that is not one is bad input."""
    with open(path) as fh:
        header = next(line for line in fh if not line.startswith("#")).strip().split(",")
    only = [c for c in header if c in wanted or (c.startswith("wheel") and c.endswith("_rpm"))]
    try:
        return read_csv(path, only=only)
    except ValueError as exc:
        raise ReportInputError(str(exc)) from None


def gaps_of(x, present, min_len: float) -> list[tuple[float, float]]:
    """Runs without a yaw at least ``min_len`` long (axis units): the Sun gaps."""
    return [s for s in tr.spans(x, ~present) if s[1] - s[0] >= min_len]


def _range(truth, measured, pad: float = 1.15):
    """A symmetric y range holding the truth and 99% of the readings: the coarse Sun
    sensors' yaw near noon reaches tens of degrees and would flatten the rest (the
    autoscale button shows it all)."""
    m = np.abs(np.asarray(measured, dtype=float))
    m = m[np.isfinite(m)]
    top = max(float(np.nanmax(np.abs(truth))) if len(truth) else 0.0,
              float(np.percentile(m, 99)) if len(m) else 0.0)
    return (-pad * top, pad * top) if top > 0 and np.isfinite(top) else None


def attitude(truth: dict, tel: dict, x_truth, x_tel, title: str, shapes, legend) -> Plot:
    """Yaw, roll and pitch: the truth beside what the sensors gave (the ground's yaw
    absent in the Sun gaps), then which Sun-sensor head gave the yaw."""
    data, panels = list(legend), []
    for i, n in enumerate(("yaw", "roll", "pitch")):
        y = tr.axis(i)
        panels.append({"title": f"{n} (deg)", "range": _range(truth[f"{n}_deg"],
                                                             tel[f"{n}_deg"])})
        data += tr.series(x_tel, tel[f"{n}_deg"], "telemetry" if i else "telemetry (ground yaw)",
                          tr.COLORS["real"], y, group="tel", show=i == 0, mode="markers")
        data += tr.series(x_truth, truth[f"{n}_deg"], "truth", tr.COLORS["truth"], y,
                          group="truth", show=i == 0)
    if "sun_head" in tel:
        y = tr.axis(len(panels))
        panels.append({"title": "Sun head (0 dss, 1/2 cass)"})
        data += tr.series(x_tel, tel["sun_head"], "Sun-sensor head", tr.COLORS["linear"], y,
                          mode="markers")
    caption = ("The truth (3-1-2 Euler angles of the body against the orbit frame) and the "
               "telemetry: Earth-sensor roll and pitch, the ground's yaw from the Sun sensors "
               "(absent in the Sun gaps, shaded) and the head that gave it; the initial "
               "scales hold the truth and 99% of the readings. Beyond "
               f"{tr.MAX_POINTS} rows each series is the band of its extremes per bin.")
    layout = tr.stacked_layout(panels, title, 190, shapes, (float(x_truth[0]),
                                                            float(x_truth[-1])))
    return Plot("sim-attitude", "Attitude: truth and telemetry", caption,
                {"data": data, "layout": layout})


def wheels(truth: dict, tel: dict, x_truth, x_tel, title: str, shapes, legend) -> Plot:
    data, panels = list(legend), []
    names = sorted(k for k in truth if k.startswith("wheel") and k.endswith("_rpm"))
    for i, k in enumerate(names):
        y = tr.axis(i)
        panels.append({"title": f"{k[:-4]} (rpm)"})
        if k in tel:
            data += tr.series(x_tel, tel[k], "tachometer", tr.COLORS["real"], y, group="tach",
                              show=i == 0, mode="markers")
        data += tr.series(x_truth, truth[k], "truth", tr.COLORS["truth"], y, group="truth",
                          show=i == 0)
    if "h_Nms" in truth:
        y = tr.axis(len(panels))
        panels.append({"title": "h (N m s)"})
        data += tr.series(x_truth, truth["h_Nms"], "h, truth", tr.COLORS["smoothed"], y)
    caption = ("Each wheel's speed, true and as the tachometer read it, and h, the wheels' "
               "momentum along body z (the filter's h state).")
    layout = tr.stacked_layout(panels, title, 170, shapes, (float(x_truth[0]),
                                                            float(x_truth[-1])))
    return Plot("sim-wheels", "Wheels and momentum", caption, {"data": data, "layout": layout})


def summary_table(scenario: dict, truth: dict, tel: dict, gaps_h, eclipse_h) -> Table:
    rows = [[text(k), cell(scenario.get(k), SCENARIO, k)] for k in
            ("name", "seed", "epoch_utc", "duration_s", "sample_interval_s") if k in scenario]
    yaw = np.isfinite(tel["yaw_deg"])
    rows += [[text("truth.csv rows (here)"), cell(len(truth["t_s"]))],
             [text("telemetry.csv rows (here)"), cell(len(tel["t_s"]))],
             [text("samples with a Sun-sensor yaw (here)"),
              cell(float(yaw.mean()) if len(yaw) else None)],
             [text("Sun gaps (here)"), cell(len(gaps_h))],
             [text("longest Sun gap, h (here)"), cell(max((b - a for a, b in gaps_h),
                                                          default=None))],
             [text("eclipse, h in all (here)"), cell(eclipse_h)]]
    if "sun_head" in tel:
        heads = tel["sun_head"][np.isfinite(tel["sun_head"])].astype(int)
        for code, name in HEADS.items():
            rows.append([text(f"yaws from {name} (here)"), cell(int(np.sum(heads == code)))])
    return Table("sim-summary", ["", "value"], rows, "The scenario (scenario.yaml) and what the "
                 "files hold (worked out here)")


def build(src: Source, command: str | None, requirement_deg: float | None = None) -> Page:
    scenario, path = src.scenario or {}, src.path
    truth = _read(path / "truth.csv", TRUTH_COLUMNS)
    tel = _read(path / "telemetry.csv", TEL_COLUMNS)
    t = truth["t_s"]
    scale, unit = tr.time_unit(float(t[-1] - t[0]) if len(t) else 0.0)
    title = f"time since epoch ({unit})"
    x_truth, x_tel = t / scale, tel["t_s"] / scale
    min_h = float((scenario.get("estimator") or {}).get("sun_gap_min_h", 4.0))
    gaps = gaps_of(x_tel, np.isfinite(tel["yaw_deg"]), min_h * 3600 / scale)
    ecl = tr.spans(x_truth, truth["eclipse"] > 0) if "eclipse" in truth else []
    shapes = tr.shades(gaps, "sun_gap") + tr.shades(ecl, "eclipse")
    legend = ([tr.legend_only(f"Sun gap (≥ {min_h:g} h without yaw)", tr.SHADES["sun_gap"])]
              if gaps else []) + ([tr.legend_only("eclipse", tr.SHADES["eclipse"])]
                                  if ecl else [])
    gaps_h = [(a * scale / 3600, b * scale / 3600) for a, b in gaps]
    eclipse_h = sum(b - a for a, b in ecl) * scale / 3600
    epoch = comments(path / "telemetry.csv").get("epoch_utc")
    intro = ("What `dynprop simulate` wrote: the truth and the telemetry, for `dynprop "
             "estimate` or `dynprop run`'s figures; nothing here is judged."
             + (f" telemetry.csv says it was taken from {epoch}." if epoch else ""))
    sections = [Section("summary", "Summary", intro,
                        tables=[summary_table(scenario, truth, tel, gaps_h, eclipse_h)])]
    sections.append(Section("attitude", "Attitude", plots=[
        attitude(truth, tel, x_truth, x_tel, title, shapes, legend)]))
    sections.append(Section("wheels", "Wheels", plots=[
        wheels(truth, tel, x_truth, x_tel, title, shapes, legend)]))
    return page(src, command, "simulate", f"{scenario.get('name')}: dynprop simulate",
                run_scale(scenario), sections)
