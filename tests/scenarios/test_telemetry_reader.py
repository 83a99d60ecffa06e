"""Real telemetry files (docs/telemetry.md): ISO 8601 UTC time tags or seconds from
an epoch the file (or the command line) gives, other column names, µrad and rad/s,
Parquet; the file's epoch checked against the scenario's; dynprop's own
telemetry.csv carrying its epoch and UTC tags while every other column keeps its
bytes.  Every refusal is one line naming the column or the key."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest

from scenarios.cli import main
from scenarios.config.loader import load_scenario
from scenarios.config.schema import resolved_yaml
from scenarios.files.columns import UtcTags
from scenarios.files.csvio import CsvAppender, read_csv, write_csv
from scenarios.files.rundir import RunDirError
from scenarios.files.telemetry_file import read_telemetry
from scenarios.files.telemetry_reader import SUN_ANGLE_COLUMNS
from scenarios.units import DEG, RPM2RADPS

EPOCH = "2026-03-20T12:00:00Z"          # the bundled scenario's
MEASURED = ("roll_deg", "pitch_deg", "yaw_deg", "wheel1_rpm", "wheel2_rpm", "yaw_sigma_deg",
            "sun_head")
# A deg → µrad → deg (or rpm → rad/s → rpm) round trip costs one rounding per product
# and per factor (DEG·RAD2DEG is 1 within 2 ulps): under 8 ulps, 8 × 1.1e-16 relative.
ROUND_TRIP_RTOL = 1e-15


@pytest.fixture(scope="module")
def own(tmp_path_factory) -> Path:
    """Five minutes of `dynprop simulate` (Sun-sensor yaw on every sample at noon)."""
    out = tmp_path_factory.mktemp("reader") / "sim"
    assert main(["simulate", "goes_next_equinox", "--duration-s", "300", "--out", str(out)]) == 0
    return out


@pytest.fixture(scope="module")
def scenario(own):
    return load_scenario(own / "scenario.yaml")


def _with(scenario_dir: Path, *sets: str):
    """The own scenario with ``--set``s applied."""
    return load_scenario(scenario_dir / "scenario.yaml", list(sets))


@pytest.fixture(scope="module")
def canonical(own, scenario):
    """The own file's columns as read_telemetry gives them (the reference)."""
    return read_telemetry(own / "telemetry.csv", scenario)


def _cli(capsys, *argv: str) -> tuple[int, list[str]]:
    rc = main(list(argv))
    err = capsys.readouterr().err
    return rc, [line.removeprefix("dynprop: error: ") for line in err.splitlines()]


def _refused(s, path: Path) -> list[str]:
    with pytest.raises(RunDirError) as info:
        read_telemetry(path, s)
    return str(info.value).splitlines()


def _write(path: Path, columns: dict, head: str = "") -> Path:
    """A CSV of number and text columns, written plainly (as another tool would)."""
    names = list(columns)
    n = len(columns[names[0]])
    text = [",".join(names)]
    for i in range(n):
        fields = []
        for name in names:
            v = columns[name][i]
            fields.append(v if isinstance(v, str) else ("" if np.isnan(v) else repr(float(v))))
        text.append(",".join(fields))
    path.write_text(head + "\n".join(text) + "\n")
    return path


def _tags(t_s: np.ndarray, unit: str = "ms", epoch: str = EPOCH) -> list[str]:
    return list(UtcTags(epoch, unit).text(t_s))


# --------------------------------------------------------------------------- own file


def test_own_file_carries_its_epoch_and_utc_tags_and_keeps_every_other_byte(own):
    lines = (own / "telemetry.csv").read_text().splitlines()
    assert lines[0] == f"# epoch_utc: {EPOCH}"
    assert lines[1].split(",")[-1] == "time_utc"
    cols = read_csv(own / "telemetry.csv")
    tags = cols.pop("time_utc")
    # Every tag is the epoch + t_s to the millisecond (0.512 s steps are whole ms).
    assert tags[0] == "2026-03-20T12:00:00.000Z" and tags[1] == "2026-03-20T12:00:00.512Z"
    ns = np.array([t.rstrip("Z") for t in tags], dtype="datetime64[ns]")
    offset = (ns - np.datetime64("2026-03-20T12:00:00", "ns")).astype(np.int64)
    np.testing.assert_array_equal(offset, np.rint(cols["t_s"] * 1e9).astype(np.int64))
    # Without the tags the same columns give the very lines the file holds, each
    # minus its last field: every existing column is byte for byte what it was.
    plain = own / "plain.csv"
    write_csv(plain, cols, exact=True)
    untagged = [line.rsplit(",", 1)[0] for line in lines[1:]]
    assert untagged == plain.read_text().splitlines()
    plain.unlink()


def test_written_a_block_at_a_time_the_tagged_file_has_the_bytes_of_one_written_whole(tmp_path):
    t = np.arange(1000) * 0.512
    cols = {"t_s": t, "roll_deg": np.round(np.sin(t), 2), "yaw_deg": np.where(t > 99, np.nan, t)}
    tags = UtcTags.of(EPOCH, 0.512)
    write_csv(tmp_path / "whole.csv", cols, exact=True, tags=tags)
    appender = CsvAppender(tmp_path / "blocks.csv", exact=True, tags=tags)
    for a in range(0, 1000, 333):
        appender.append({k: v[a:a + 333] for k, v in cols.items()})
    appender.close()
    assert (tmp_path / "blocks.csv").read_bytes() == (tmp_path / "whole.csv").read_bytes()
    # A step that is no whole number of ms is tagged to the µs.
    assert UtcTags.of(EPOCH, 0.5125).unit == "us" and UtcTags.of(EPOCH, 1.024).unit == "ms"


def test_own_file_reads_back_bit_for_bit(own, scenario, canonical):
    """Identity is the requirement: `estimate` on a run's telemetry is the run's filter."""
    written = read_csv(own / "telemetry.csv")
    # The raw Sun angles come along, read for the screen's field-of-view rule.
    assert set(canonical) == {"t_s", *MEASURED, *SUN_ANGLE_COLUMNS}
    for name, values in canonical.items():
        assert values.tobytes() == written[name].tobytes(), name


# --------------------------------------------------------------------------- time tags


@pytest.mark.parametrize("form", ["Z", "", "+00:00"])
def test_iso_utc_tags_in_place_of_t_s(tmp_path, scenario, canonical, form):
    cols = {"time_utc": [tag.removesuffix("Z") + form for tag in _tags(canonical["t_s"])],
            **{k: canonical[k] for k in MEASURED}}
    got = read_telemetry(_write(tmp_path / "iso.csv", cols), scenario)
    # ms tags of k·0.512 s: the seconds agree to the double's rounding (1e-13 s at 300 s).
    np.testing.assert_allclose(got["t_s"], canonical["t_s"], rtol=0, atol=1e-12)
    for name in MEASURED:
        assert got[name].tobytes() == canonical[name].tobytes(), name


def test_sub_millisecond_tags_keep_their_precision(tmp_path, scenario, canonical):
    t = canonical["t_s"] + 250e-6    # 250 µs after each sample: the tags need µs
    cols = {"time_utc": _tags(t, "us"), **{k: canonical[k] for k in MEASURED}}
    got = read_telemetry(_write(tmp_path / "us.csv", cols), scenario)
    assert got["t_s"][0] == 250e-6
    np.testing.assert_allclose(got["t_s"], t, rtol=0, atol=1e-12)


def test_seconds_from_the_epoch_the_file_gives(tmp_path, own, scenario, canonical):
    """Half a second off the scenario's epoch (inside the 1 s tolerance): t_s counts
    from the scenario's, so it moves by that half second."""
    cols = {"t_s": canonical["t_s"], **{k: canonical[k] for k in MEASURED}}
    path = _write(tmp_path / "head.csv", cols, "# source: a ground system\n"
                  "# epoch_utc: 2026-03-20T11:59:59.5Z\n")
    got = read_telemetry(path, scenario)
    np.testing.assert_array_equal(got["t_s"], canonical["t_s"] - 0.5)
    # Without the line, the epoch the command line gives (--epoch-utc).
    bare = _write(tmp_path / "bare.csv", cols)
    s = _with(own, "telemetry.epoch_utc=2026-03-20T12:00:00.25Z")
    np.testing.assert_array_equal(read_telemetry(bare, s)["t_s"], canonical["t_s"] + 0.25)


def test_a_file_starting_elsewhere_is_refused_in_one_line_naming_both_epochs(
        tmp_path, own, canonical, capsys):
    cols = {"time_utc": _tags(canonical["t_s"], epoch="2026-06-21T12:00:00Z"),
            **{k: canonical[k] for k in MEASURED}}
    path = _write(tmp_path / "june.csv", cols)
    out = tmp_path / "est"
    rc, lines = _cli(capsys, "estimate", str(path), "--scenario", str(own / "scenario.yaml"),
                     "--out", str(out))
    assert rc == 2 and not out.exists()
    assert lines == [f"{path}: its epoch 2026-06-21T12:00:00Z (the first time_utc) is "
                     f"93 days after the scenario's epoch_utc {EPOCH} (tolerance 1 s): set "
                     "epoch_utc to the file's start"]


def test_a_seconds_file_whose_epoch_is_off_is_refused(tmp_path, own, scenario, canonical):
    cols = {"t_s": canonical["t_s"], **{k: canonical[k] for k in MEASURED}}
    path = _write(tmp_path / "late.csv", cols, "# epoch_utc: 2026-03-20T12:00:05Z\n")
    (line,) = _refused(scenario, path)
    assert "2026-03-20T12:00:05Z" in line and EPOCH in line and "5 s after" in line
    # Wider tolerance, accepted (and t_s moved by those 5 s).
    s = _with(own, "telemetry.epoch_tolerance_s=10")
    np.testing.assert_array_equal(read_telemetry(path, s)["t_s"], canonical["t_s"] + 5)


def test_with_both_time_columns_t_s_is_taken_and_the_tags_must_agree(tmp_path, scenario,
                                                                      canonical):
    cols = {"t_s": canonical["t_s"], "time_utc": _tags(canonical["t_s"] + 10.0),
            **{k: canonical[k] for k in MEASURED}}
    path = _write(tmp_path / "both.csv", cols, f"# epoch_utc: {EPOCH}\n")
    assert _refused(scenario, path) == [
        f"{path}: its first time_utc is 10 s after its epoch_utc + t_s (tolerance 1 s): the "
        "two time columns disagree"]


def test_a_zone_other_than_utc_is_one_line(tmp_path, scenario, canonical):
    tags = _tags(canonical["t_s"])
    tags[3] = "2026-03-20T14:00:01.536+02:00"    # the same instant, but not in UTC
    cols = {"time_utc": tags, **{k: canonical[k] for k in MEASURED}}
    path = _write(tmp_path / "zone.csv", cols)
    assert _refused(scenario, path) == [
        f"{path}: row 5, column time_utc: '2026-03-20T14:00:01.536+02:00' is not UTC; time "
        "tags must be UTC (Z, +00:00 or no zone)"]


def test_a_tag_that_is_no_time_is_one_line(tmp_path, scenario, canonical):
    tags = _tags(canonical["t_s"])
    tags[6] = "2026-03-20T12:00:03.072Q"
    cols = {"time_utc": tags, **{k: canonical[k] for k in MEASURED}}
    path = _write(tmp_path / "bad.csv", cols)
    (line,) = _refused(scenario, path)
    assert line.startswith(f"{path}: row 8, column time_utc: ") and "ISO 8601" in line


# --------------------------------------------------------------------------- mapping, units

GROUND = {"roll": "ES_ROLL", "yaw": "YAW_EST", "pitch": "ES_PITCH", "wheel1": "TACH1",
          "wheel2": "TACH2", "yaw_sigma": "YAW_SIG", "sun_head": "HEAD", "time_utc": "UTC"}


def _ground_file(tmp_path: Path, canonical) -> Path:
    """What a ground system might deliver: its own names, µrad, rad/s, UTC tags."""
    c = canonical
    cols = {"UTC": _tags(c["t_s"]), "ES_ROLL": c["roll_deg"] * DEG * 1e6,
            "ES_PITCH": c["pitch_deg"], "YAW_EST": c["yaw_deg"] * DEG * 1e6,
            "YAW_SIG": c["yaw_sigma_deg"] * DEG * 1e6, "HEAD": c["sun_head"],
            "TACH1": c["wheel1_rpm"] * RPM2RADPS, "TACH2": c["wheel2_rpm"] * RPM2RADPS,
            "QUALITY": np.ones(len(c["t_s"]))}
    return _write(tmp_path / "ground.csv", cols)


def _mapped(own: Path, **units):
    sets = [f'telemetry.columns.{k}="{v}"' for k, v in GROUND.items()]
    sets += [f"telemetry.units.{k}={v}" for k, v in units.items()]
    return _with(own, *sets)


def test_other_names_and_units_round_trip_to_degrees_and_rpm(tmp_path, own, canonical):
    s = _mapped(own, roll="urad", yaw="urad", yaw_sigma="urad", wheels="rad/s")
    got = read_telemetry(_ground_file(tmp_path, canonical), s)
    assert set(got) == {"t_s", *MEASURED}
    for name in ("roll_deg", "yaw_deg", "yaw_sigma_deg", "wheel1_rpm", "wheel2_rpm"):
        np.testing.assert_allclose(got[name], canonical[name], rtol=ROUND_TRIP_RTOL, atol=0,
                                   err_msg=name)
    for name in ("pitch_deg", "sun_head"):     # degrees and no unit: as they are
        assert got[name].tobytes() == canonical[name].tobytes()


def test_estimate_takes_the_mapping_and_units_from_the_command_line(tmp_path, own, canonical,
                                                                    capsys):
    path = _ground_file(tmp_path, canonical)
    argv = ["estimate", str(path), "--scenario", str(own / "scenario.yaml")]
    for key, col in GROUND.items():
        argv += ["--column", f"{key}={col}"]
    for key, unit in (("roll", "urad"), ("yaw", "urad"), ("yaw_sigma", "urad"),
                      ("wheels", "rad/s")):
        argv += ["--unit", f"{key}={unit}"]
    rc, err = _cli(capsys, *argv, "--out", str(tmp_path / "est"))
    assert rc == 0, err
    rc, err = _cli(capsys, "estimate", str(own / "telemetry.csv"), "--scenario",
                   str(own / "scenario.yaml"), "--out", str(tmp_path / "ref"))
    assert rc == 0, err
    mapped, ref = read_csv(tmp_path / "est" / "estimate.csv"), read_csv(tmp_path / "ref" /
                                                                       "estimate.csv")
    # The inputs differ by a few ulps; the filter carries them through, far below 1e-9°.
    np.testing.assert_allclose(mapped["yaw_deg"], ref["yaw_deg"], rtol=0, atol=1e-9)
    # The directory's scenario.yaml records how the file was read.
    again = load_scenario(tmp_path / "est" / "scenario.yaml")
    assert again.telemetry.columns.roll == "ES_ROLL" and again.telemetry.units.wheels == "rad/s"


def test_an_unknown_unit_is_one_line_naming_the_key(tmp_path, own, canonical, capsys):
    path = _ground_file(tmp_path, canonical)
    rc, lines = _cli(capsys, "estimate", str(path), "--scenario", str(own / "scenario.yaml"),
                     "--unit", "roll=mrad", "--out", str(tmp_path / "est"))
    assert rc == 2 and len(lines) == 1
    assert lines[0].startswith("telemetry.units.roll: must be 'deg', 'rad' or 'urad'")


def test_a_mapped_column_the_file_lacks_is_one_line_with_the_likely_one(tmp_path, own,
                                                                         canonical):
    # Every other column and unit as the file has them (a yaw in µrad read as degrees
    # would be refused too, for its unit: test_screen.py).
    s = _with(own, *[f'telemetry.columns.{k}="{v}"' for k, v in GROUND.items()],
              'telemetry.columns.roll="ES_ROL"', "telemetry.units.wheels=rad/s",
              "telemetry.units.yaw=urad", "telemetry.units.yaw_sigma=urad")
    path = _ground_file(tmp_path, canonical)
    assert _refused(s, path) == [f"{path}: no column ES_ROL (telemetry.columns.roll); did you "
                                 "mean 'ES_ROLL'?"]


def test_default_scenarios_resolve_without_the_section_and_a_set_one_round_trips(
        tmp_path, own, scenario):
    assert "\ntelemetry:" not in resolved_yaml(scenario)
    s = _mapped(own, roll="urad")
    (tmp_path / "s.yaml").write_text(resolved_yaml(s))
    assert "\ntelemetry:" in (tmp_path / "s.yaml").read_text()
    assert load_scenario(tmp_path / "s.yaml") == s


# --------------------------------------------------------------------------- Parquet


def _parquet(path: Path, columns: dict, epoch: str | None = None) -> Path:
    pa = pytest.importorskip("pyarrow", reason="pyarrow is not installed (pip install "
                             "'dynprop[parquet]'): Parquet files cannot be read")
    import pyarrow.parquet as pq
    table = pa.table(columns)
    if epoch is not None:
        table = table.replace_schema_metadata({"epoch_utc": epoch})
    pq.write_table(table, path)
    return path


def test_parquet_with_a_timestamp_column_and_urad(tmp_path, own, canonical):
    pa = pytest.importorskip("pyarrow", reason="pyarrow is not installed (pip install "
                             "'dynprop[parquet]'): Parquet files cannot be read")
    c = canonical
    start = np.datetime64("2026-03-20T12:00:00", "us")
    stamps = start + np.rint(c["t_s"] * 1e6).astype("timedelta64[us]")
    cols = {"UTC": pa.array(stamps, pa.timestamp("us", tz="UTC")),
            "ES_ROLL": c["roll_deg"] * DEG * 1e6, "ES_PITCH": c["pitch_deg"],
            "YAW_EST": c["yaw_deg"] * DEG * 1e6, "YAW_SIG": c["yaw_sigma_deg"] * DEG * 1e6,
            "HEAD": c["sun_head"], "TACH1": c["wheel1_rpm"] * RPM2RADPS,
            "TACH2": c["wheel2_rpm"] * RPM2RADPS}
    path = _parquet(tmp_path / "ground.parquet", cols)
    s = _mapped(own, roll="urad", yaw="urad", yaw_sigma="urad", wheels="rad/s")
    got = read_telemetry(path, s)
    np.testing.assert_allclose(got["t_s"], c["t_s"], rtol=0, atol=1e-12)
    for name in ("roll_deg", "yaw_deg", "wheel1_rpm", "wheel2_rpm"):
        np.testing.assert_allclose(got[name], c[name], rtol=ROUND_TRIP_RTOL, atol=0,
                                   err_msg=name)


def test_parquet_with_seconds_and_its_epoch_in_the_metadata(tmp_path, scenario, canonical):
    cols = {"t_s": canonical["t_s"], **{k: canonical[k] for k in MEASURED}}
    path = _parquet(tmp_path / "own.pq", cols, epoch="2026-03-20T11:59:59.5Z")
    got = read_telemetry(path, scenario)
    np.testing.assert_array_equal(got["t_s"], canonical["t_s"] - 0.5)
    assert got["roll_deg"].tobytes() == canonical["roll_deg"].tobytes()
    # And a string time column, in place of a timestamp.
    tagged = _parquet(tmp_path / "tags.parquet", {"time_utc": _tags(canonical["t_s"]),
                                                  **{k: canonical[k] for k in MEASURED}})
    np.testing.assert_allclose(read_telemetry(tagged, scenario)["t_s"], canonical["t_s"],
                               rtol=0, atol=1e-12)


def test_parquet_without_pyarrow_is_one_line(tmp_path, scenario, monkeypatch):
    path = tmp_path / "x.parquet"
    path.write_bytes(b"PAR1")
    monkeypatch.setitem(sys.modules, "pyarrow", None)      # import pyarrow fails
    monkeypatch.setitem(sys.modules, "pyarrow.parquet", None)
    assert _refused(scenario, path) == [f"{path}: reading Parquet needs pyarrow: pip install "
                                        "'dynprop[parquet]'"]
