"""The streamed telemetry reader (``files.spool``, issue 44) against the whole read.

``open_source`` reads a file in blocks into scratch columns; every answer it gives
(samples by range, steps off the grid, the median step, the stats, the screen's report
and the screened rows' times) must be ``WholeSource``'s, bit for bit, whatever the
block size, and every bad file must get the whole read's message.  The reference is
the whole read (``read_screened`` + ``on_grid``) of the same file, an independent code
path; the files are slices of a run's telemetry.csv edited as text the way a ground
system's file differs from dynprop's: rows dropped, jittered tags, ISO tags alone,
spikes and ``nan`` text, Parquet.  Blocks of 1 and 7 rows and hypothesis' sizes put a
block boundary next to every edit.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from scenarios.config.loader import load_scenario
from scenarios.files.rundir import RunDirError
from scenarios.files.spool import blocks, disk, select, times
from scenarios.files.telemetry_reader import tag_ns
from scenarios.files.telemetry_source import open_source, whole_source

ROWS = 500                  # rows of the run kept: 4 min at 0.512 s
EPOCH_NS = np.datetime64("2026-03-20T12:00:00", "ns")


@pytest.fixture(scope="module")
def base(run6):
    """The run's comment line, header and first ROWS rows, as cells."""
    with open(run6 / "telemetry.csv") as fh:
        comment = fh.readline()
        header = fh.readline().rstrip("\n").split(",")
        rows = [next(fh).rstrip("\n").split(",") for _ in range(ROWS)]
    return comment, header, rows


@pytest.fixture(scope="module")
def scenario(run6):
    # A shorter max gap, so that the holes below are listed in the stats' gaps.
    return load_scenario(run6 / "scenario.yaml", ["estimator.max_gap_s=10"])


def _write(path: Path, comment: str, header: list[str], rows: list[list[str]],
           newline: str = "\n") -> Path:
    path.write_text("".join([comment, ",".join(header) + newline]
                            + [",".join(r) + newline for r in rows]), newline="")
    return path


def _drop(header, rows, name):
    j = header.index(name)
    return [h for i, h in enumerate(header) if i != j], [r[:j] + r[j + 1:] for r in rows]


def _set(header, rows, row, name, text):
    rows[row][header.index(name)] = text


def _tags(t_s: np.ndarray) -> list[str]:
    ns = EPOCH_NS + np.rint(t_s * 1e9).astype(np.int64).astype("timedelta64[ns]")
    return [x + "Z" for x in np.datetime_as_string(ns, unit="ms")]


def _bits(a: np.ndarray) -> np.ndarray:
    return np.asarray(a, dtype=np.float64).view(np.int64)


def assert_same(path: Path, s, block_rows, folder: Path) -> None:
    """Every answer of the streamed source equals the whole read's, or both refuse
    the file with the same message."""
    try:
        whole, expected = whole_source(path, s), None
    except RunDirError as exc:
        whole, expected = None, str(exc)
    try:
        src, got = open_source(path, s, folder, block_rows), None
    except RunDirError as exc:
        src, got = None, str(exc)
    assert got == expected
    assert list(folder.iterdir()) == [] if src is None else len(list(folder.iterdir())) == 1
    if whole is None:
        return
    try:
        assert (src.regular, src.n, src.n_rows, src.names) == \
            (whole.regular, whole.n, whole.n_rows, whole.names)
        n = whole.n
        for a, b in [(0, n), (0, 1), (n - 3, n + 5), (5, 6), (n // 3, 2 * n // 3), (7, 7)]:
            w, g = whole.columns(a, b), src.columns(a, b)
            assert list(w) == list(g)
            for name in w:
                assert np.array_equal(_bits(w[name]), _bits(g[name])), (name, a, b)
            ws, gs = whole.steps(a, b), src.steps(a, b)
            assert (ws is None) == (gs is None)
            if ws is not None:
                assert np.array_equal(_bits(ws), _bits(gs)), (a, b)
        assert _bits(src.median_step_s()) == _bits(whole.median_step_s())
        for dt in (s.sample_interval_s, 0.25):
            assert src.stats(dt) == whole.stats(dt)
        assert np.array_equal(_bits(src.screened_t_s()), _bits(whole.screened_t_s()))
        assert src.screen.count == whole.screen.count
        assert np.array_equal(src.screen.rows_any(), whole.screen.rows_any())
        assert src.screen.summary() == whole.screen.summary()
    finally:
        src.close()
    assert list(folder.iterdir()) == []


# --------------------------------------------------------------------------- files

def clean(base, tmp: Path) -> Path:
    comment, header, rows = base
    return _write(tmp / "clean.csv", comment, header, [list(r) for r in rows])


def holes(base, tmp: Path) -> Path:
    """On the grid with steps missing: single rows, a run of rows, every other row
    for a while (a 1.024 s stretch) and a 13 s hole; and two rows on one grid step
    (1 ms apart, within the grid's tolerance: the later one is the sample)."""
    comment, header, rows = base
    gone = {3, 7, 8, 200, *range(50, 75), *range(300, 340, 2)}
    kept = [list(r) for i, r in enumerate(rows) if i not in gone]
    # The repeated step just before the 13 s hole, whose start the stats list.
    k = kept.index(list(rows[49]))
    again = list(kept[k])
    again[0] = repr(float(kept[k][0]) + 0.001)
    again[1] = "0.03"
    return _write(tmp / "holes.csv", comment, header, kept[:k + 1] + [again] + kept[k + 1:])


def repeat_and_hole(base, tmp: Path) -> Path:
    """A row missing and, later, two rows on one grid step: as many rows as grid
    steps, which ``on_grid`` takes as they are (every row a sample, none missing)."""
    comment, header, rows = base
    kept = [list(r) for i, r in enumerate(rows) if i != 10]
    again = list(kept[300])
    again[0] = repr(float(kept[299][0]) + 0.002)
    return _write(tmp / "repeat_and_hole.csv", comment, header,
                  kept[:300] + [again] + kept[300:])


def jittered(base, tmp: Path, iso_only: bool = False) -> Path:
    """Off the grid: ±50 ms on every tag, some rows dropped (dropouts), with the
    tags written as ISO UTC alone when ``iso_only``."""
    comment, header, rows = base
    rng = np.random.default_rng(44)
    rows = [list(r) for i, r in enumerate(rows) if i % 9 != 4 and not 300 <= i < 330]
    t = np.array([float(r[0]) for r in rows]) + rng.uniform(-0.05, 0.05, len(rows))
    t[0] = 0.0
    for r, v, tag in zip(rows, t, _tags(t), strict=True):
        r[0], r[-1] = repr(float(v)), tag
    if iso_only:
        header, rows = _drop(header, rows, "t_s")
    return _write(tmp / f"jitter{'_iso' * iso_only}.csv", comment, header, rows)


def iso_only(base, tmp: Path) -> Path:
    comment, header, rows = base
    header, rows = _drop(header, [list(r) for r in rows], "t_s")
    return _write(tmp / "iso.csv", comment, header, rows)


def spiked(base, tmp: Path) -> Path:
    """Values the screen takes out, next to 7-row block edges and at the file's ends:
    wheel jumps (rows 6, 7, 13, 14), the first wheel1 reading out of range and the
    last wheel2 reading a jump (both held from the nearest good one), the last two
    roll readings and the first two pitch readings jumps (judged in the file's last
    and first full windows),
    ``nan``/``inf`` text, an out-of-range wheel, a Sun angle outside its head's field of view,
    a yaw σ of 0 (its yaw goes with it) and a sun_head left empty."""
    comment, header, rows = base
    rows = [list(r) for r in rows]
    for k in (6, 7, 13, 14):
        _set(header, rows, k, "wheel1_rpm", "6500.0")
    _set(header, rows, 0, "wheel1_rpm", "99999.0")
    _set(header, rows, ROWS - 1, "wheel2_rpm", "4000.5")
    _set(header, rows, ROWS - 2, "roll_deg", "5.0")
    _set(header, rows, ROWS - 1, "roll_deg", "5.0")
    _set(header, rows, 0, "pitch_deg", "-5.0")
    _set(header, rows, 1, "pitch_deg", "-5.0")
    _set(header, rows, 20, "pitch_deg", "nan")
    _set(header, rows, 21, "yaw_deg", "NaN")
    _set(header, rows, 22, "wheel2_rpm", "-inf")
    _set(header, rows, 200, "wheel2_rpm", "1e308")
    _set(header, rows, 201, "yaw_sigma_deg", "0.0")
    _set(header, rows, 202, "sun_head", "")
    lit = next(c for c in ("dss_alpha_deg", "cass1_alpha_deg", "cass2_alpha_deg")
               if rows[205][header.index(c)])
    _set(header, rows, 205, lit, "120.0")
    _set(header, rows, 30, "roll_deg", "")      # a dropout between jump readings
    _set(header, rows, 31, "roll_deg", "")
    return _write(tmp / "spiked.csv", comment, header, rows, newline="\r\n")


def parquet(base, tmp: Path, timestamps: bool) -> Path:
    """The spiked rows as Parquet: numbers as doubles (empty cells null), the tags
    as text or as a timestamp column, the epoch in the metadata."""
    pa = pytest.importorskip("pyarrow")
    pq = pytest.importorskip("pyarrow.parquet")
    comment, header, rows = base
    src = spiked(base, tmp)
    lines = src.read_text().splitlines()[2:]
    cells = [line.split(",") for line in lines if line]
    cols = {}
    for j, name in enumerate(header):
        text = [c[j] for c in cells]
        if name == "time_utc":
            cols[name] = (pa.array(np.array([x.rstrip("Z") for x in text],
                                            dtype="datetime64[ms]"), pa.timestamp("ms"))
                          if timestamps else pa.array(text))
        else:
            cols[name] = pa.array([float(x) if x else None for x in text], pa.float64())
    table = pa.table(cols).replace_schema_metadata({"epoch_utc": comment.split(": ")[1].strip()})
    path = tmp / f"spiked{'_ts' * timestamps}.parquet"
    pq.write_table(table, path, row_group_size=200)
    return path


FILES = {"clean": clean, "holes": holes, "repeat_and_hole": repeat_and_hole,
         "jittered": jittered,
         "jittered_iso": lambda b, t: jittered(b, t, iso_only=True), "iso": iso_only,
         "spiked": spiked}


@pytest.fixture(scope="module")
def files(base, tmp_path_factory):
    tmp = tmp_path_factory.mktemp("spool_files")
    return {name: make(base, tmp) for name, make in FILES.items()}


# --------------------------------------------------------------------------- equivalence

@pytest.fixture
def short_sweeps(monkeypatch):
    """The scratch columns swept 5 rows at a time (the grid's spreading, the median,
    the stats), so that their chunk boundaries fall inside these short files."""
    monkeypatch.setattr(disk, "READ_ROWS", 5)


# Blocks of one row for the files whose edits sit on every kind of boundary; 7 rows
# and whole for all.
CASES = [(name, rows) for name in FILES for rows in (7, None)] + \
    [(name, 1) for name in ("holes", "jittered_iso", "spiked")]


@pytest.mark.parametrize(("name", "block_rows"), CASES)
def test_every_answer_is_the_whole_reads(files, scenario, tmp_path, name, block_rows,
                                         short_sweeps):
    assert_same(files[name], scenario, block_rows, tmp_path)


@settings(max_examples=12, deadline=None,
          suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(block_rows=st.integers(2, 400), name=st.sampled_from(list(FILES)))
def test_any_block_size(files, scenario, tmp_path_factory, block_rows, name):
    assert_same(files[name], scenario, block_rows, tmp_path_factory.mktemp("spool"))


@pytest.mark.parametrize("how", ["crlf", "cr", "no final newline", "blank lines"])
def test_line_ends(base, scenario, tmp_path, how):
    """Lines ended as other systems end them, read as Python's text mode reads them."""
    path = clean(base, tmp_path)
    text = path.read_text()
    if how == "crlf":
        text = text.replace("\n", "\r\n")
    elif how == "cr":
        text = text.replace("\n", "\r")
    elif how == "no final newline":
        text = text.rstrip("\n")
    else:
        lines = text.split("\n")
        text = "\n".join(lines[:100] + ["", ""] + lines[100:]) + "\n\n"
    path.write_text(text, newline="")
    (tmp_path / "scratch").mkdir()
    for block_rows in (7, None):
        assert_same(path, scenario, block_rows, tmp_path / "scratch")


def test_the_edits_are_screened(files, scenario, tmp_path):
    """The spiked file exercises what it is meant to: every rule, and both held ends."""
    src = open_source(files["spiked"], scenario, tmp_path, 7)
    summary = src.screen.summary()
    src.close()
    reasons = {r for c in summary["columns"].values() for r in c["reasons"]}
    assert reasons == {"non-finite", "range", "field of view", "jump"}
    assert [(h["column"], h["row"]) for h in summary["held_at_ends"]] == \
        [("wheel1_rpm", 2), ("wheel2_rpm", ROWS + 1)]
    assert summary["columns"]["wheel1_rpm"]["reasons"]["jump"]["first_rows"] == [8, 9, 15, 16]
    assert summary["columns"]["roll_deg"]["reasons"]["jump"]["first_rows"] == [ROWS, ROWS + 1]
    assert summary["columns"]["pitch_deg"]["reasons"]["jump"]["first_rows"] == [2, 3]


@pytest.mark.parametrize("timestamps", [False, True])
@pytest.mark.parametrize("block_rows", [7, 133, None])
def test_parquet(base, scenario, tmp_path, timestamps, block_rows):
    path = parquet(base, tmp_path, timestamps)
    (tmp_path / "scratch").mkdir()
    assert_same(path, scenario, block_rows, tmp_path / "scratch")


# --------------------------------------------------------------------------- bad files

def _bad(base, tmp: Path, what: str) -> Path:
    comment, header, rows = base
    rows = [list(r) for r in rows]
    late = ROWS - 30
    if what == "decreasing":
        # The tags stop increasing late in the file (the day 20, in small).
        rows[late][0], rows[late + 1][0] = rows[late + 1][0], rows[late][0]
    elif what == "non-finite tag":
        rows[late][0] = "nan"
    elif what == "bad iso tag":
        header, rows = _drop(header, rows, "t_s")
        rows[late][-1] = "2026-03-20T12:99:00Z"
    elif what == "empty and zoned tags":
        header, rows = _drop(header, rows, "t_s")
        rows[10][-1] = "2026-03-20T12:00:05+01:00"
        rows[late][-1] = ""
    elif what == "sun head":
        rows[late][header.index("sun_head")] = "3.0"
    elif what == "ragged row":
        rows[late] = rows[late][:-2]
    elif what == "wheel end":
        rows[-1][header.index("wheel2_rpm")] = ""
    elif what == "text cell":
        rows[late][1] = "1.5x"
    elif what == "space line":
        rows[late] = ["   "]
    elif what == "nan tag":
        rows[late][-1] = "nan"
    elif what == "not utf-8":
        path = _write(tmp / "not_utf8.csv", comment, header, rows)
        data = path.read_bytes()
        path.write_bytes(data[:-2000] + b"\xff" + data[-2000:])
        return path
    elif what == "units":
        j = header.index("wheel1_rpm")
        for r in rows:
            r[j] = repr(float(r[j]) * math.pi / 30)
    return _write(tmp / f"{what.replace(' ', '_')}.csv", comment, header, rows)


BAD = ("decreasing", "non-finite tag", "bad iso tag", "empty and zoned tags", "sun head",
       "ragged row", "wheel end", "units", "text cell", "space line", "nan tag", "not utf-8")


BAD_CASES = [(what, rows) for what in BAD for rows in (7, None)] + \
    [(what, 1) for what in ("decreasing", "empty and zoned tags", "ragged row")]


@pytest.mark.parametrize(("what", "block_rows"), BAD_CASES)
def test_bad_files_get_the_whole_reads_message(base, scenario, tmp_path, what, block_rows):
    path = _bad(base, tmp_path, what)
    with pytest.raises(RunDirError) as whole:
        whole_source(path, scenario)
    (tmp_path / "scratch").mkdir()
    with pytest.raises(RunDirError) as streamed:
        open_source(path, scenario, tmp_path / "scratch", block_rows)
    assert str(streamed.value) == str(whole.value)
    assert list((tmp_path / "scratch").iterdir()) == []


def test_a_parquet_file_without_a_tag(base, scenario, tmp_path):
    """A null timestamp late in a Parquet file: read_parquet's line, its row."""
    pa = pytest.importorskip("pyarrow")
    pq = pytest.importorskip("pyarrow.parquet")
    table = pq.read_table(parquet(base, tmp_path, timestamps=True))
    tags = table.column("time_utc").to_pylist()
    tags[ROWS - 30] = None
    table = table.set_column(table.schema.get_field_index("time_utc"), "time_utc",
                             pa.array(tags, table.schema.field("time_utc").type))
    path = tmp_path / "no_tag.parquet"
    pq.write_table(table, path, row_group_size=200)
    with pytest.raises(RunDirError) as whole:
        whole_source(path, scenario)
    for block_rows in (7, None):
        with pytest.raises(RunDirError) as streamed:
            open_source(path, scenario, tmp_path, block_rows)
        assert str(streamed.value) == str(whole.value)


def test_units_are_judged_on_the_first_two_days(base, scenario, tmp_path):
    """A 3-day file (a row every 64 s, on the grid) whose wheel1 is in rad/s for two
    days and in rpm after: the streamed read's unit line is the whole read's of the
    file cut after two days (the medians of those rows), not of the whole file's.
    The two-day rows alternate 560 and 590 rad/s, an odd count of them: without its
    last row, the median would be 575."""
    comment, header, rows = base
    j = header.index("wheel1_rpm")
    three = []
    for i in range(3 * 1350 + 1):
        r = list(rows[i % ROWS])
        r[0], r[-1] = repr(64.0 * i), _tags(np.array([64.0 * i]))[0]
        if 64.0 * i <= 2 * 86400:
            r[j] = ("560.0", "590.0")[i % 2]
        three.append(r)
    full = _write(tmp_path / "three_days.csv", comment, header, three)
    cut = _write(tmp_path / "two_days.csv", comment, header, three[:2701])

    def unit_line(path, read):
        with pytest.raises(RunDirError) as exc:
            read(path)
        return [x.replace(str(path), "FILE") for x in str(exc.value).splitlines()
                if "wheel1_rpm reads" in x]
    expected = unit_line(cut, lambda p: whole_source(p, scenario))
    assert expected and "median 560" in expected[0]
    for block_rows in (7, None):
        (tmp_path / "scratch").mkdir(exist_ok=True)
        assert unit_line(full, lambda p, b=block_rows: open_source(
            p, scenario, tmp_path / "scratch", b)) == expected
    assert unit_line(full, lambda p: whole_source(p, scenario)) != expected


# --------------------------------------------------------------------------- parts

@settings(max_examples=60, deadline=None)
@given(st.lists(st.floats(-1e300, 1e300), min_size=1, max_size=60), st.integers(1, 9))
def test_select_median_is_numpys(values, parts):
    x = np.array(values)
    chunks = np.array_split(x, parts)
    got = select.median(lambda: iter(chunks))
    assert got == np.median(x)
    if np.median(x) != 0:
        assert _bits(got) == _bits(np.median(x))


@settings(max_examples=60, deadline=None)
@given(st.integers(-2208988800 * 10**9, 7258118399 * 10**9), st.integers(0, 9),
       st.booleans())
def test_fixed_layout_tags_are_numpys(ns, digits, zulu):
    """The fast reading of telemetry.csv's tags gives tag_ns' nanoseconds (1900–2199,
    any number of fraction digits)."""
    unit = {0: "s", 3: "ms", 6: "us", 9: "ns"}.get(digits)
    if unit is None:
        text = np.datetime_as_string(np.array([ns], dtype="datetime64[ns]"), unit="ns")[0]
        text = text[:20 + digits] if digits else text[:19]
    else:
        text = np.datetime_as_string(np.array([ns], dtype="datetime64[ns]"), unit=unit)[0]
    tags = np.array([text + "Z" * zulu] * 3)
    expected, problems = tag_ns(Path("x"), "time_utc", tags)
    assert not problems
    assert np.array_equal(times.fixed_layout_ns(tags), expected)


@pytest.mark.parametrize("tag", ["2026-02-29T00:00:00Z", "2024-04-31T00:00:00",
                                 "2026-03-20T24:00:00", "2026-03-20T12:00:60",
                                 "2026-03-20T12:00:00.Z", "2026-03-20 12:00:00",
                                 "2026-03-20T12:00:00.1234567891"])
def test_fixed_layout_leaves_the_rest_to_numpy(tag):
    assert times.fixed_layout_ns(np.array([tag])) is None


def test_arrow_reads_as_loadtxt_does():
    """The CSV fast path is taken only when pyarrow reads every hard cell to loadtxt's
    double (it does with the pyarrow this suite installs)."""
    pytest.importorskip("pyarrow")
    assert blocks.arrow_agrees()
