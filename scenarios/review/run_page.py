"""The page of a `run` or `estimate` directory (and `run --montecarlo-case`): the
verdict, the interactive figures, the tables, the scenario and where it all came
from (docs/report.md)."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from ..figures.marks import cut_at_gaps, summary_events
from ..files.csvio import read_csv
from . import events as ev
from . import provenance, run_figures, verdict
from .cells import Table, cell, flatten, text, unit_of
from .render import Page, Section
from .source import Source

SUMMARY = "summary.json"
DAILY = "daily.csv"
# summary.json's keys shown elsewhere on the page (the verdict, the checks table).
SHOWN_ELSEWHERE = ("checks", "warnings")


def eclipses(path: Path) -> list[tuple[float, float]]:
    """[start, end) of each eclipse in s, from truth.csv's ``eclipse`` column (its
    stored rows); none without the file or the column.  pandas's parser skips the
    other 36 columns unparsed: a year's 200 MB truth.csv in 0.3 s, not 2.7."""
    import pandas as pd
    truth = path / "truth.csv"
    if not truth.is_file():
        return []
    with open(truth) as fh:
        header = fh.readline().strip().split(",")
    if "eclipse" not in header:
        return []
    cols = pd.read_csv(truth, usecols=["t_s", "eclipse"], dtype="float64")
    from .traces import spans
    return spans(cols["t_s"].to_numpy(), cols["eclipse"].to_numpy() > 0)


def _checks_table(summary: dict) -> Table:
    rows = []
    for name, c in (summary.get("checks") or {}).items():
        passed = c.get("passed")
        status = "not tested" if passed is None else ("passed" if passed else "failed")
        rows.append([text(name), cell(passed, SUMMARY, f"checks.{name}.passed",
                                      css="" if passed is not False else "failed"),
                     text(status, "failed" if passed is False else ""),
                     cell(c.get("detail"), SUMMARY, f"checks.{name}.detail")])
    return Table("checks", ["check", "passed", "verdict", "what was judged"], rows,
                 "The run's own checks (summary.json)")


def _gap_table(summary: dict) -> Table | None:
    gaps = summary.get("sun_gaps_h") or []
    if not gaps:
        return None
    errs = summary.get("yaw_error_at_gap_end_deg") or []
    lin = summary.get("yaw_error_linear_at_gap_end_deg") or []
    sig = summary.get("yaw_sigma_at_gap_end_deg") or []
    rows = []
    for i, (a, b) in enumerate(gaps):
        row = [text(str(i + 1)), cell(a, SUMMARY, f"sun_gaps_h[{i}][0]"),
               cell(b, SUMMARY, f"sun_gaps_h[{i}][1]"), cell(b - a)]
        for values, key in ((errs, "yaw_error_at_gap_end_deg"),
                            (lin, "yaw_error_linear_at_gap_end_deg"),
                            (sig, "yaw_sigma_at_gap_end_deg")):
            row.append(cell(values[i], SUMMARY, f"{key}[{i}]") if i < len(values)
                       else text("—"))
        e, s = (errs[i] if i < len(errs) else None), (sig[i] if i < len(sig) else None)
        ratio = e / s if e is not None and s else None
        row.append(cell(ratio, css="failed" if ratio is not None and abs(ratio) > 3 else ""))
        rows.append(row)
    return Table("gap-ends", ["gap", "start (h)", "end (h)", "length (h)",
                              "yaw error at end (°)", "linearized (°)", "filter σ (°)", "e/σ"],
                 rows, "Sun gaps and the yaw at their ends (summary.json; length and e/σ "
                 "worked out here)")


def _summary_table(summary: dict) -> Table:
    rows = []
    for key, value in flatten(summary):
        if key.split(".")[0].split("[")[0] in SHOWN_ELSEWHERE:
            continue
        rows.append([text(key), cell(value, SUMMARY, key), text(unit_of(key))])
    return Table("summary", ["key", "value", "unit"], rows,
                 "summary.json, every figure (docs/outputs.md says what each is)")


def _daily(path: Path) -> dict | None:
    f = path / DAILY
    return read_csv(f) if f.is_file() else None


def _daily_table(daily: dict) -> Table:
    names = list(daily)
    rows = [[cell(_num(daily[n][r]), DAILY, f"{r}:{n}") for n in names]
            for r in range(len(daily[names[0]]))]
    return Table("daily", names, rows, "daily.csv, one row per day of the run")


def _num(v):
    v = float(v)
    if math.isfinite(v) and v == int(v) and abs(v) < 2 ** 53:
        return int(v)
    return None if math.isnan(v) else v


def _daily_rms(summary: dict, daily: dict | None, c: dict) -> list:
    """Per day: (day, the Cell showing its RMS yaw error, value): daily.csv's where the
    run wrote one; otherwise from the stored rows (`estimate` stores every sample)."""
    if daily is not None and "yaw_error_rms_deg" in daily:
        return [(int(d), cell(_num(v), DAILY, f"{r}:yaw_error_rms_deg", "°"), _num(v))
                for r, (d, v) in enumerate(zip(daily["day"], daily["yaw_error_rms_deg"],
                                               strict=True))]
    if "err_real" not in c:
        return []
    day = np.floor(c["t_s"] / 86400.0).astype(int)
    out = []
    for d in np.unique(day):
        e = c["err_real"][day == d, run_figures.STATE["yaw"]].astype(float)
        e = e[np.isfinite(e)]
        if len(e):
            rms = float(np.sqrt(np.mean(e ** 2)))
            out.append((int(d), cell(rms, unit="°"), rms))
    return out


def requirement_of(scenario: dict, override: float | None) -> float | None:
    if override is not None:
        return override
    return ((scenario.get("report") or {}).get("yaw_requirement_deg"))


def build(src: Source, command: str | None, requirement_deg: float | None = None) -> Page:
    # Read key by key as the figures ask (an array is read again when asked again):
    # the whole file at once would hold a year's 274 MB in memory.
    with np.load(src.path / "comparison.npz") as c:
        return _build(src, command, requirement_deg, c)


def _build(src: Source, command: str | None, requirement_deg: float | None, c) -> Page:
    summary, scenario, path = src.record, src.scenario or {}, src.path
    daily = _daily(path)
    duration = float(summary.get("duration_s") or (c["t_s"][-1] - c["t_s"][0]))
    min_gap_h = float((scenario.get("estimator") or {}).get("sun_gap_min_h", 4.0))
    # The figures draw the rows cut at the telemetry gaps; the numbers read every row.
    raw, c = c, cut_at_gaps(c)
    events = summary_events(summary)
    ax = run_figures.time_axis(c, summary, duration, eclipses(path), min_gap_h, events)
    eq55 = summary.get("analytic_sigma_yaw_deg")
    requirement = requirement_of(scenario, requirement_deg)
    kind = "estimate" if summary.get("telemetry") else "run"

    verdicts = [verdict.against_filter(summary), verdict.against_paper(summary),
                verdict.against_requirement(summary, requirement,
                                            _daily_rms(summary, daily, raw))]
    if summary.get("ekf"):
        verdicts.insert(1, verdict.against_filter(summary, "EKF σ",
                                                  "ekf_gap_end_yaw_within_3sigma"))
    tables = [t for t in (_gap_table(summary), _checks_table(summary)) if t is not None]
    sections = [Section("verdict", "Verdict", _verdict_intro(summary), verdicts, tables)]
    if events:
        sections.append(Section("events", "Events", EVENTS_INTRO, tables=[ev.table(events)]))

    figures = [run_figures.errors(c, ax, eq55)]
    sections.append(Section("errors", "Errors", plots=figures))
    extra = [p for p in (run_figures.consistency(c, ax, summary), run_figures.torques(c, ax),
                         run_figures.telemetry(c, ax)) if p is not None]
    for p in extra:
        sections.append(Section(p.id, p.title.split(":")[0], plots=[p]))
    # daily.csv's days start at the first row (t = 0 in a run).
    days = run_figures.season(daily, events, float(raw["t_s"][0])) \
        if daily is not None else None
    tables = [_summary_table(summary)]
    if daily is not None:
        tables.append(_daily_table(daily))
    sections.append(Section("tables", "Tables", plots=[days] if days else [], after=tables))
    sections += provenance.sections(src, command, kind)
    title = f"{summary.get('scenario')}: dynprop {kind}"
    subtitle = (f"seed {summary.get('seed')}, epoch {summary.get('epoch_utc')}, "
                f"{duration / 86400:.3g} days, filters {', '.join(summary.get('filters') or [])}"
                f", dynprop {summary.get('dynprop_version')}")
    return Page(title, kind, subtitle, sections)


EVENTS_INTRO = ("The scenario's scheduled events (every occurrence of a periodic one), also "
                "marked on every time figure: a band over a thruster firing or a sensor "
                "outage, a dashed line at a command.")


def _verdict_intro(summary: dict) -> str:
    n = len(summary.get("yaw_error_at_gap_end_deg") or [])
    return (f"The yaw error at the end of each Sun gap ({n} judged), where the paper's "
            "question lies: how well does the filter carry yaw across the night without "
            "the Sun sensors? Judged against the filter's own σ, against the paper's "
            "0.040° (Eq. 56) and against the requirement.")
