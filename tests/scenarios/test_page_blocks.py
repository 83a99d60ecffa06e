"""`dynprop report` of a long directory reads its CSVs in blocks (issue 44): the block
reader (``files.csvio.read_csv_blocks``) against the whole read, and each fold of
``review.streamed`` against the whole column's ``traces`` function or numpy's, on
small blocks whose boundaries fall inside bins, runs and breaks."""

from __future__ import annotations

import contextlib
import io

import numpy as np
import pytest
from dynprop.scenarios.files.csvio import read_csv, read_csv_blocks, write_csv
from dynprop.scenarios.review import streamed
from dynprop.scenarios.review import traces as tr


def _bits(a) -> np.ndarray:
    return np.asarray(a, dtype=float).view(np.int64)


def _joined(blocks) -> dict:
    blocks = list(blocks)
    return {k: np.concatenate([b[k] for b in blocks]) for k in blocks[0]}


@pytest.fixture
def table(tmp_path):
    """A CSV as dynprop writes one (10 digits, NaN as an empty field), with a comment
    line and a text column, and a blank line inside."""
    rng = np.random.default_rng(7)
    n = 53
    cols = {"t_s": np.arange(n) * 0.512, "a": rng.normal(size=n) * 1e3,
            "b": rng.normal(size=n) * 1e-9, "c": rng.integers(0, 3, n).astype(float)}
    cols["a"][[0, 13, 14, 52]] = np.nan
    cols["c"][[6, 7, 21]] = np.nan
    path = tmp_path / "t.csv"
    write_csv(path, cols, workers=1)
    lines = path.read_text().splitlines(keepends=True)
    lines.insert(30, "\n")
    names = lines[0].strip().split(",")
    lines[0] = ",".join([*names, "time_utc"]) + "\n"
    body = [ln if not ln.strip() else ln.rstrip("\n") + f",2026-03-20T12:00:{k:02d}Z\n"
            for k, ln in enumerate(lines[1:])]
    path.write_text("# epoch_utc: 2026-03-20T12:00:00Z\n" + lines[0] + "".join(body))
    return path


@pytest.mark.parametrize("only", [None, ["t_s", "c", "a"], ["b", "time_utc"]])
@pytest.mark.parametrize("block_rows", [1, 6, 7, 30, 1000])
def test_blocks_joined_are_the_whole_read_bit_for_bit(table, only, block_rows):
    whole = read_csv(table, only=only)
    parts = _joined(read_csv_blocks(table, only=only, block_rows=block_rows))
    assert list(parts) == list(whole)
    for k in whole:
        if k == "time_utc":
            assert parts[k].tolist() == whole[k].tolist()
        else:
            assert np.array_equal(_bits(parts[k]), _bits(whole[k])), k


@pytest.mark.parametrize("block_rows", [4, 7, 100])
@pytest.mark.parametrize("bad", ["1.5x", "1,2"])
def test_a_bad_row_in_a_later_block_gets_the_whole_reads_message(table, block_rows, bad):
    lines = table.read_text().splitlines(keepends=True)
    lines[25] = lines[25].replace(lines[25].split(",")[2], bad, 1)
    table.write_text("".join(lines))
    with pytest.raises(ValueError) as whole:
        read_csv(table)
    with pytest.raises(ValueError) as parts:
        list(read_csv_blocks(table, block_rows=block_rows))
    assert str(parts.value) == str(whole.value)
    assert "row 25" in str(whole.value)     # the comment line is not counted


def _t_with_breaks(n: int, rng) -> np.ndarray:
    t = np.cumsum(rng.uniform(0.4, 0.6, n))
    t[[0 + 5, 6, 1000, 3001, 4095, n - 1]] = np.nan   # one break right after another
    return t


@pytest.mark.parametrize("block", [1, 2, 3, 7, 500, 4096, 10**6])
def test_series_fold_is_traces_reduced_of_the_whole_column(block):
    """Binned (7001 rows: bins of 3) with breaks in t, a break at a block's last row,
    bins across block boundaries, an all-NaN stretch, zeros of both signs."""
    rng = np.random.default_rng(1)
    n = 7001
    t = _t_with_breaks(n, rng)
    y = rng.normal(size=n)
    y[2000:2100] = np.nan
    y[3000:3600] = rng.choice([0.0, -0.0], 600)     # which zero a bin keeps is reduceat's
    y = np.column_stack([t, y])[:, 1]    # a column of one array, as read_csv gives it
    fold = streamed.SeriesFold(n, ["y"])
    for i in range(0, n, block):
        fold.add(t[i:i + block], {"y": y[i:i + block]})
    got, want = fold.reduced("y"), tr.reduced(t, y)
    assert got.step == want.step == 3 and got.y is None
    for a, b in ((got.x, want.x), (got.lo, want.lo), (got.hi, want.hi)):
        assert np.array_equal(_bits(a), _bits(b))


def test_series_fold_keeps_the_rows_of_a_short_column():
    rng = np.random.default_rng(2)
    t, y = np.arange(300.0), rng.normal(size=300)
    fold = streamed.SeriesFold(300, ["y"])
    for i in range(0, 300, 7):
        fold.add(t[i:i + 7], {"y": y[i:i + 7]})
    got = fold.reduced("y")
    assert got.step == 0 and np.array_equal(got.x, t) and np.array_equal(got.y, y)


@pytest.mark.parametrize("block", [1, 2, 5, 64, 10**6])
def test_runs_fold_is_traces_spans_of_the_whole_column(block):
    """Runs across block boundaries, ending on a NaN time (its row before, in the
    block before), one running to the end of the file on a NaN last time."""
    rng = np.random.default_rng(3)
    n = 400
    t = np.arange(n) * 0.5
    mask = rng.uniform(size=n) < 0.4
    mask[-30:] = True
    t[np.flatnonzero(~mask)[::4]] = np.nan
    t[[-1, 64, 65]] = np.nan
    mask[63:65], mask[65] = True, False
    fold = streamed.RunsFold()
    for i in range(0, n, block):
        fold.add(t[i:i + block], mask[i:i + block])
    want = tr.spans(t, mask)
    assert len(want) > 20
    assert np.array_equal(_bits(fold.spans()), _bits(want))


@pytest.mark.parametrize("n", [1, 2, 3, 99, 100, 101, 257, 1000, 12345])
def test_top_fold_is_numpys_99th_percentile(n):
    rng = np.random.default_rng(n)
    for v in (np.abs(rng.standard_cauchy(n)), np.round(rng.normal(size=n), 1) ** 2):
        v[rng.uniform(size=n) < 0.1] = np.nan
        fold = streamed.TopFold(n)
        for i in range(0, n, 13):
            fold.add(v[i:i + 13])
        finite = v[np.isfinite(v)]
        want = float(np.percentile(finite, 99)) if finite.size else None
        assert fold.percentile99() == want


def test_read_columns_is_the_whole_read_with_blank_lines_and_small_blocks(table):
    """The row count (a blank line makes the first count one too many: the bins are
    made again) and every fold, against the whole columns."""
    whole = read_csv(table, only=["t_s", "a", "c"])
    got = streamed.read_columns(table, ["a", "c"], runs={"gap": lambda c: np.isnan(c["a"])},
                                p99=["a"], sums={"c": lambda c: int(np.nansum(c["c"]))},
                                block_rows=5)
    assert got.rows == len(whole["t_s"]) == streamed.count_rows(table) - 1
    assert (got.first_t, got.last_t) == (whole["t_s"][0], whole["t_s"][-1])
    assert got.runs["gap"] == tr.spans(whole["t_s"], np.isnan(whole["a"]))
    assert got.p99["a"] == np.percentile(np.abs(whole["a"][np.isfinite(whole["a"])]), 99)
    assert got.abs_max["a"] == np.nanmax(np.abs(whole["a"]))
    assert got.sums["c"] == np.nansum(whole["c"])
    assert np.array_equal(got.series["a"].y, whole["a"], equal_nan=True)


@pytest.fixture(scope="module")
def simulated(tmp_path_factory):
    """`dynprop simulate` over 3000 s (5860 rows: bins of 2)."""
    from dynprop.scenarios.cli import main
    out = tmp_path_factory.mktemp("sim") / "sim"
    with contextlib.redirect_stdout(io.StringIO()):
        assert main(["simulate", "goes_next_equinox", "--duration-s", "3000",
                     "--out", str(out)]) == 0
    return out


def test_the_simulate_page_is_drawn_from_the_whole_columns_values(simulated, monkeypatch):
    """Every series, range and count of the page, read in blocks of 97 rows, is the
    whole columns' (traces.reduced, np.percentile, np.nanmax)."""
    from dynprop.scenarios.review.pages import simulate as page
    monkeypatch.setattr(streamed, "BLOCK_ROWS", 97)
    truth, tel = (page._read(simulated / "truth.csv", page.TRUTH_COLUMNS),
                  page._tel(simulated / "telemetry.csv"))
    whole_truth, whole_tel = read_csv(simulated / "truth.csv"), read_csv(simulated /
                                                                         "telemetry.csv")
    assert truth.rows == len(whole_truth["t_s"]) == 5860
    for got, whole in ((truth, whole_truth), (tel, whole_tel)):
        for k, r in got.series.items():
            want = tr.reduced(whole["t_s"], whole[k])
            assert r.step == want.step == 2, k
            for a, b in ((r.x, want.x), (r.lo, want.lo), (r.hi, want.hi)):
                assert np.array_equal(_bits(a), _bits(b)), k
    for k in page.ANGLES:
        assert truth.abs_max[k] == np.nanmax(np.abs(whole_truth[k]))
        m = np.abs(whole_tel[k])
        assert tel.p99[k] == np.percentile(m[np.isfinite(m)], 99)
    assert tel.sums["yaw"] == np.isfinite(whole_tel["yaw_deg"]).sum()
    assert tel.runs["no_yaw"] == tr.spans(whole_tel["t_s"], ~np.isfinite(whole_tel["yaw_deg"]))
    heads = whole_tel["sun_head"][np.isfinite(whole_tel["sun_head"])].astype(int)
    assert [tel.sums[c] for c in page.HEADS] == [np.sum(heads == c) for c in page.HEADS]
    assert sum(tel.sums[c] for c in page.HEADS) > 0
