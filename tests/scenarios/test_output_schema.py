"""The scenario's `output` section: defaults, what auto resolves to, and bad values
rejected in one line naming the key, through the CLI's own path (exit 2)."""

from __future__ import annotations

import pytest

from scenarios.config.loader import ScenarioError, load_scenario
from scenarios.config.schema import output_stride, output_writes_telemetry

from .test_cli_run import assert_one_line, run_cli


def test_defaults_are_64_s_rows_and_telemetry_for_two_days():
    s = load_scenario("goes_next_equinox")
    assert s.output.interval_s is None and s.output.telemetry == "auto"
    assert output_stride(s) == 125                       # 64 s of 0.512 s samples
    assert output_writes_telemetry(s)                    # 172800 s: two days
    longer = load_scenario("goes_next_equinox", ["duration_s=172800.512"])
    assert not output_writes_telemetry(longer)
    year = load_scenario("goes_next_equinox", ["duration_s=31536000", "output.telemetry=true"])
    assert output_writes_telemetry(year)
    # Another step: the default takes the multiple of it nearest 64 s.
    coarse = load_scenario("goes_next_equinox", ["sample_interval_s=1.024"])
    assert output_stride(coarse) == 62
    assert output_stride(load_scenario("goes_next_equinox",
                                       ["output.interval_s=0.512"])) == 1


@pytest.mark.parametrize(("override", "message"), [
    ("output.interval_s=100", "output.interval_s: 100 s is not a whole multiple of "
     "sample_interval_s (0.512 s); nearest: 99.84 or 100.352"),
    ("output.interval_s=0", "output.interval_s: must be greater than 0"),
    ("output.interval_s=-64", "output.interval_s: must be greater than 0"),
    ("output.interval_s=nan", "output.interval_s:"),
    ("output.interval_s=abc", "output.interval_s:"),
    ("output.telemetry=maybe", "output.telemetry: must be 'auto', true or false"),
    ("output.intervall_s=64", "output.intervall_s: unknown key; did you mean 'interval_s'?"),
])
def test_bad_output_values_get_one_line_naming_the_key(override, message, tmp_path):
    with pytest.raises(ScenarioError) as exc:
        load_scenario("goes_next_equinox", [override])
    assert str(exc.value).startswith(message), str(exc.value)
    rc, out, err = run_cli("run", "goes_next_equinox", "--set", override, "--out",
                           str(tmp_path / "run"))
    assert rc == 2 and out == ""
    assert assert_one_line(err).startswith(f"dynprop: error: {message}")
    assert not (tmp_path / "run").exists()


def test_a_year_validates_and_the_whole_array_commands_refuse_it(tmp_path):
    assert load_scenario("goes_next_equinox", ["duration_s=31536000"]).duration_s == 31536000
    rc, _, err = run_cli("simulate", "goes_next_equinox", "--duration-s", "31536000", "--out",
                         str(tmp_path / "sim"))
    assert rc == 2
    assert assert_one_line(err).startswith("dynprop: error: duration_s: 3.1536e+07 s is over")
    with pytest.raises(ScenarioError):
        load_scenario("goes_next_equinox", [f"duration_s={366 * 86400 + 1}"])
