"""The scenario schema and loader (docs/scenario-reference.md).

Bad input must raise ``ScenarioError`` with one line that starts with the key
path (or the file); defaults must be the paper's GOES-Next numbers, written
here as literals from the paper rather than read back from the code.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from scenarios.config import build
from scenarios.config.loader import (
    ScenarioError,
    apply_override,
    bundled_names,
    load_scenario,
    read_raw,
    validate,
)
from scenarios.config.schema import resolved_yaml
from sim import ephemeris

RPM = 2.0 * math.pi / 60.0


def assert_error(exc_info: pytest.ExceptionInfo, prefix: str) -> str:
    """One line, starting with ``prefix`` (the key path or the file)."""
    msg = str(exc_info.value)
    assert "\n" not in msg and "\r" not in msg, f"message is not one line: {msg!r}"
    assert msg.startswith(prefix), f"{msg!r} does not start with {prefix!r}"
    assert "Traceback" not in msg
    return msg


def write(tmp_path: Path, text: str, name: str = "scenario.yaml") -> Path:
    path = tmp_path / name
    path.write_text(text)
    return path


# --------------------------------------------------------------------------- bad input

# (id, raw mapping given to validate(), the key path the message must start with)
BAD_MAPPINGS = [
    ("unknown-top-level", {"name": "x", "bogus": 1}, "bogus: unknown key"),
    ("unknown-nested", {"name": "x", "spacecraft": {"wheels": {"bogus": 1}}},
     "spacecraft.wheels.bogus: unknown key"),
    ("unknown-in-sensor", {"name": "x", "sensors": {"earth": {"fov": 3}}},
     "sensors.earth.fov: unknown key"),
    ("seed-string", {"name": "x", "seed": "abc"}, "seed:"),
    ("seed-float", {"name": "x", "seed": 1.5}, "seed:"),
    ("seed-bool", {"name": "x", "seed": True}, "seed:"),
    ("seed-negative", {"name": "x", "seed": -1}, "seed:"),
    ("control-enabled-int", {"name": "x", "control": {"enabled": 1}}, "control.enabled:"),
    ("control-enabled-string", {"name": "x", "control": {"enabled": "true"}},
     "control.enabled:"),
    ("duration-string", {"name": "x", "duration_s": "long"}, "duration_s:"),
    ("duration-bool", {"name": "x", "duration_s": True}, "duration_s:"),
    ("rate-element-string", {"name": "x", "initial_state": {"rate_wrt_orbit_degps": [0, "a", 0]}},
     "initial_state.rate_wrt_orbit_degps"),
    ("rate-too-short", {"name": "x", "initial_state": {"rate_wrt_orbit_degps": [0, 0]}},
     "initial_state.rate_wrt_orbit_degps"),
    ("rate-scalar", {"name": "x", "initial_state": {"rate_wrt_orbit_degps": 0.1}},
     "initial_state.rate_wrt_orbit_degps"),
    ("inertia-non-symmetric",
     {"name": "x", "spacecraft": {"inertia_kgm2": [[3, 0.5, 0], [0, 3, 0], [0, 0, 3]]}},
     "spacecraft.inertia_kgm2: inertia is not symmetric"),
    ("inertia-not-positive-definite",
     {"name": "x", "spacecraft": {"inertia_kgm2": [[1, 0, 0], [0, -1, 0], [0, 0, 1]]}},
     "spacecraft.inertia_kgm2: inertia is not positive definite"),
    ("inertia-triangle-inequality",
     {"name": "x", "spacecraft": {"inertia_kgm2": [[1, 0, 0], [0, 1, 0], [0, 0, 3]]}},
     "spacecraft.inertia_kgm2: inertia violates the triangle inequality"),
    ("inertia-2x2", {"name": "x", "spacecraft": {"inertia_kgm2": [[1, 0], [0, 1]]}},
     "spacecraft.inertia_kgm2"),
    ("inertia-flat", {"name": "x", "spacecraft": {"inertia_kgm2": [1, 2, 3]}},
     "spacecraft.inertia_kgm2"),
    ("inertia-3x4",
     {"name": "x", "spacecraft": {"inertia_kgm2": [[1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 0]]}},
     "spacecraft.inertia_kgm2"),
    ("duration-negative", {"name": "x", "duration_s": -1}, "duration_s:"),
    ("duration-above-366-days", {"name": "x", "duration_s": 366 * 86400 + 1}, "duration_s:"),
    ("sample-interval-zero", {"name": "x", "sample_interval_s": 0}, "sample_interval_s:"),
    ("sample-interval-negative", {"name": "x", "sample_interval_s": -0.512},
     "sample_interval_s:"),
    ("duration-nan", {"name": "x", "duration_s": math.nan}, "duration_s:"),
    ("duration-inf", {"name": "x", "duration_s": math.inf}, "duration_s:"),
    ("nested-nan", {"name": "x", "environment": {"solar": {"untrimmed_torque_Nm": math.nan}}},
     "environment.solar.untrimmed_torque_Nm:"),
    ("vector-element-inf",
     {"name": "x", "initial_state": {"rate_wrt_orbit_degps": [0, -math.inf, 0]}},
     "initial_state.rate_wrt_orbit_degps"),
    ("inertia-element-nan",
     {"name": "x", "spacecraft": {"inertia_kgm2": [[math.nan, 0, 0], [0, 1, 0], [0, 0, 1]]}},
     "spacecraft.inertia_kgm2"),
    ("epoch-unparseable", {"name": "x", "epoch_utc": "next tuesday"}, "epoch_utc:"),
    ("epoch-without-zone", {"name": "x", "epoch_utc": "2026-03-20T12:00:00"}, "epoch_utc:"),
    ("epoch-1949", {"name": "x", "epoch_utc": "1949-12-31T23:59:59Z"}, "epoch_utc:"),
    ("epoch-2050", {"name": "x", "epoch_utc": "2050-01-01T00:00:00Z"}, "epoch_utc:"),
    ("epoch-number", {"name": "x", "epoch_utc": 2026}, "epoch_utc:"),
    ("wheel-speed-zero", {"name": "x", "spacecraft": {"wheels": {"speed_rpm": 0}}},
     "spacecraft.wheels.speed_rpm:"),
    ("cant-90", {"name": "x", "spacecraft": {"wheels": {"cant_deg": 90}}},
     "spacecraft.wheels.cant_deg:"),
    ("cant-95", {"name": "x", "spacecraft": {"wheels": {"cant_deg": 95}}},
     "spacecraft.wheels.cant_deg:"),
    ("missing-name", {"seed": 1}, "name: required key is missing"),
    ("empty-name", {"name": ""}, "name:"),
    ("section-not-mapping", {"name": "x", "spacecraft": [1, 2]}, "spacecraft:"),
    ("bad-configuration", {"name": "x", "spacecraft": {"configuration": "spare"}},
     "spacecraft.configuration:"),
    ("max-gap-zero", {"name": "x", "estimator": {"max_gap_s": 0}}, "estimator.max_gap_s:"),
    ("max-gap-negative", {"name": "x", "estimator": {"max_gap_s": -1.0}},
     "estimator.max_gap_s:"),
    ("max-gap-nan", {"name": "x", "estimator": {"max_gap_s": math.nan}},
     "estimator.max_gap_s:"),
    ("max-gap-inf", {"name": "x", "estimator": {"max_gap_s": math.inf}},
     "estimator.max_gap_s:"),
    ("max-gap-string", {"name": "x", "estimator": {"max_gap_s": "1h"}},
     "estimator.max_gap_s:"),
    ("max-gap-bool", {"name": "x", "estimator": {"max_gap_s": True}},
     "estimator.max_gap_s:"),
]


@pytest.mark.parametrize(("raw", "prefix"), [c[1:] for c in BAD_MAPPINGS],
                         ids=[c[0] for c in BAD_MAPPINGS])
def test_validate_rejects_bad_values_naming_the_key_path(raw, prefix):
    with pytest.raises(ScenarioError) as exc_info:
        validate(raw)
    assert_error(exc_info, prefix)


# (id, file text, the key path the message must start with; None = the file path)
BAD_FILES = [
    ("yaml-syntax-unclosed-list", "name: x\nseed: [1, 2\n", None),
    ("yaml-syntax-bad-indent", "name: x\n  seed: 1\n", None),
    ("yaml-tab", "name: x\n\tseed: 1\n", None),
    ("yaml-python-tag", "name: !!python/object/apply:os.getcwd []\n", None),
    ("top-level-list", "- name\n- x\n", None),
    ("top-level-scalar", "just text\n", None),
    ("empty-file", "", "name: required key is missing"),
    ("yaml-nan", "name: x\nduration_s: .nan\n", "duration_s:"),
    ("yaml-inf", "name: x\nduration_s: .inf\n", "duration_s:"),
    ("yaml-negative-inf", "name: x\norbit: {longitude_deg: -.inf}\n", "orbit.longitude_deg:"),
    ("yaml-nested-unknown", "name: x\nspacecraft:\n  wheels:\n    bogus: 1\n",
     "spacecraft.wheels.bogus: unknown key"),
    ("yaml-date-without-zone", "name: x\nepoch_utc: 2026-03-20\n", "epoch_utc:"),
    ("yaml-null-section", "name: x\nspacecraft:\n", "spacecraft:"),
    ("yaml-null-seed", "name: x\nseed:\n", "seed:"),
]


@pytest.mark.parametrize(("text", "prefix"), [c[1:] for c in BAD_FILES],
                         ids=[c[0] for c in BAD_FILES])
def test_load_scenario_rejects_bad_files(tmp_path, text, prefix):
    path = write(tmp_path, text)
    with pytest.raises(ScenarioError) as exc_info:
        load_scenario(path)
    assert_error(exc_info, str(path) if prefix is None else prefix)


@pytest.mark.parametrize("source", ["no_such_scenario", "missing/dir/x.yaml", ""])
def test_missing_scenario_names_the_source_and_the_bundled_names(source):
    with pytest.raises(ScenarioError) as exc_info:
        load_scenario(source)
    msg = assert_error(exc_info, f"scenario {source}:")
    assert "goes_next_equinox" in msg


def test_a_directory_is_not_a_scenario(tmp_path):
    with pytest.raises(ScenarioError) as exc_info:
        read_raw(tmp_path)
    assert_error(exc_info, f"scenario {tmp_path}:")


def test_undecodable_file_names_the_file(tmp_path):
    path = tmp_path / "binary.yaml"
    path.write_bytes(b"\xff\xfe\x00name")
    with pytest.raises(ScenarioError) as exc_info:
        load_scenario(path)
    assert_error(exc_info, f"scenario {path}:")


@pytest.mark.parametrize("text", [
    "name: x\nseed: 1\nseed: 2\n",
    "name: x\nspacecraft:\n  wheels:\n    cant_deg: 1\n    cant_deg: 2\n",
], ids=["top-level", "nested"])
def test_duplicate_yaml_key_is_rejected_on_one_line(tmp_path, text):
    path = write(tmp_path, text)
    with pytest.raises(ScenarioError) as exc_info:
        load_scenario(path)
    msg = str(exc_info.value)
    assert "\n" not in msg
    assert "duplicate key" in msg
    assert f":{len(text.splitlines())}:" in msg  # file:line:col of the second occurrence


def test_duplicate_yaml_key_message_names_the_file(tmp_path):
    path = write(tmp_path, "name: x\nspacecraft:\n  wheels:\n    cant_deg: 1\n    cant_deg: 2\n")
    with pytest.raises(ScenarioError) as exc_info:
        load_scenario(path)
    msg = str(exc_info.value)
    assert msg.startswith(str(path)) or msg.startswith("spacecraft.wheels.cant_deg")


# (id, --set assignment, the key path the message must start with)
BAD_OVERRIDES = [
    ("unknown-top-level", "bogus=1", "bogus: unknown key"),
    ("unknown-nested", "spacecraft.wheels.bogus=1", "spacecraft.wheels.bogus: unknown key"),
    ("inside-a-scalar", "seed.x=1", "seed"),
    ("inside-a-missing-scalar", "duration_s.x=1", "duration_s"),
    ("no-equals", "seed", "--set seed"),
    ("empty-key", "=5", "--set =5"),
    ("empty-segment", "spacecraft..cant_deg=1", "--set spacecraft..cant_deg=1"),
    ("bad-yaml-value", "initial_state.rate_wrt_orbit_degps=[0, 1", "--set"),
    ("seed-string", "seed=abc", "seed:"),
    ("duration-string-nan", "duration_s=nan", "duration_s:"),
    ("duration-yaml-nan", "duration_s=.nan", "duration_s:"),
    ("duration-yaml-inf", "duration_s=.inf", "duration_s:"),
    ("solar-yaml-nan", "environment.solar.trim_tab_deg=.NaN", "environment.solar.trim_tab_deg:"),
    ("sample-interval-zero", "sample_interval_s=0", "sample_interval_s:"),
    ("cant-90", "spacecraft.wheels.cant_deg=90", "spacecraft.wheels.cant_deg:"),
    ("epoch-1900", "epoch_utc=1900-01-01T00:00:00Z", "epoch_utc:"),
    ("triangle-inertia", "spacecraft.inertia_kgm2=[[1,0,0],[0,1,0],[0,0,3]]",
     "spacecraft.inertia_kgm2:"),
    ("section-replaced-by-scalar", "spacecraft=5", "spacecraft:"),
]


@pytest.mark.parametrize(("assignment", "prefix"), [c[1:] for c in BAD_OVERRIDES],
                         ids=[c[0] for c in BAD_OVERRIDES])
def test_bad_override_names_the_key_path(assignment, prefix):
    with pytest.raises(ScenarioError) as exc_info:
        load_scenario("goes_next_equinox", [assignment])
    assert_error(exc_info, prefix)


# --------------------------------------------------------------------------- defaults


def test_named_empty_scenario_takes_the_papers_goes_next_numbers():
    s = validate({"name": "bare"})
    # Stored defaults, no arithmetic: compared exactly.
    np.testing.assert_array_equal(
        s.spacecraft.inertia_kgm2,
        [[3364.376, 0, 0], [0, 954.936, 0], [0, 0, 3461.393]])  # paper Section 2.3
    assert s.spacecraft.configuration == "nominal"
    assert s.spacecraft.wheels.spin_inertia_kgm2 == 0.1082
    assert s.spacecraft.wheels.cant_deg == 1.656
    assert s.spacecraft.wheels.speed_rpm == 5485
    assert s.spacecraft.yaw_wheel.spin_inertia_kgm2 == 0.008626
    assert s.sensors.earth.noise_deg == 0.01
    assert s.sensors.earth.quantum_deg == 0.01
    assert s.sensors.tachometer.quantum_rpm == 0.0163
    assert s.sensors.tachometer.noise_3sigma_rpm == 0.0978
    assert s.estimator.process_noise.q_x == 5.4e-7  # Eq. 45
    assert s.estimator.process_noise.q_z == 5.4e-7
    assert s.sample_interval_s == 0.512  # the paper's 0.512 s telemetry sample (Section 2)
    assert s.estimator.max_gap_s == 3600.0  # issue 13: an hour of dropout is propagated
    assert s.sensors.noise.enabled and s.control.enabled
    assert s.environment.gravity_gradient.enabled and s.environment.solar.enabled
    assert s.environment.magnetic.enabled
    assert s.dynprop_version is None
    ephemeris.parse_epoch(s.epoch_utc)  # the default epoch is itself valid


def test_default_spacecraft_has_the_papers_pitch_bias():
    sc = build.build_spacecraft(validate({"name": "bare"}))
    # H = −2 I_w Ω cos(c) for two wheels canted ±c from −y (Eq. 1)
    expected = -2 * 0.1082 * 5485 * RPM * math.cos(math.radians(1.656))
    assert sc.pitch_bias_Nms() == pytest.approx(expected, rel=1e-12)
    assert sc.pitch_bias_Nms() == pytest.approx(-124.2, abs=0.05)
    assert sc.yaw_momentum_Nms() == pytest.approx(0.0, abs=1e-12)
    np.testing.assert_array_equal(sc.J, np.diag([3364.376, 954.936, 3461.393]))  # stored


def test_default_solar_residual_is_a_trimmed_one():
    coefficient = build.build_environment(validate({"name": "bare"})).solar.coefficient_Nm
    assert 1e-7 <= abs(coefficient) <= 1e-5  # the paper's abstract: 1e-7 to 1e-5 N m


# --------------------------------------------------------------------------- bundled


EXPECTED_BUNDLED = {"goes_next_equinox", "goes_next_solstice", "untrimmed_solar", "torque_free",
                    "large_offset", "backup_wheel"}


def test_bundled_set_includes_the_documented_scenarios():
    assert EXPECTED_BUNDLED <= set(bundled_names())


@pytest.mark.parametrize("name", bundled_names())
def test_every_bundled_scenario_loads_with_a_description(name):
    s = load_scenario(name)
    assert s.name == name
    assert s.description.strip()
    assert "\n" not in s.description
    # and it builds into simulator objects
    build.build_spacecraft(s)
    build.build_environment(s)
    build.build_sensors(s)
    build.build_initial(s)
    build.epoch(s)


def test_untrimmed_solar_has_the_full_5e_5_imbalance():
    env = build.build_environment(load_scenario("untrimmed_solar"))
    assert env.solar.enabled
    assert env.solar.coefficient_Nm == pytest.approx(5e-5, rel=1e-12)  # paper Fig. 2


def test_torque_free_switches_off_every_torque_ripple_and_control():
    s = load_scenario("torque_free")
    e = s.environment
    assert not (e.gravity_gradient.enabled or e.solar.enabled or e.magnetic.enabled
                or e.ripple.enabled)
    assert not s.control.enabled
    env = build.build_environment(s)
    assert not (env.gravity_gradient.enabled or env.solar.enabled or env.magnetic.enabled
                or env.ripple.enabled)
    assert not build.build_control(s).enabled


def test_backup_wheel_has_the_yaw_reaction_wheel():
    sc = build.build_spacecraft(load_scenario("backup_wheel"))
    assert sc.n_wheels == 2
    yaw_wheel = sc.wheels[1]
    assert yaw_wheel.spin_inertia_kgm2 == 0.008626
    np.testing.assert_array_equal(yaw_wheel.axis, (0.0, 0.0, 1.0))  # stored constant
    # one momentum wheel: half the nominal bias, and the yaw wheel cancels its h
    half = -0.1082 * 5485 * RPM * math.cos(math.radians(1.656))
    assert sc.pitch_bias_Nms() == pytest.approx(half, rel=1e-12)
    assert sc.yaw_momentum_Nms() == pytest.approx(0.0, abs=1e-12)


def test_solstice_epoch_is_in_june_and_equinox_in_march():
    assert ephemeris.parse_epoch(load_scenario("goes_next_solstice").epoch_utc).month == 6
    assert ephemeris.parse_epoch(load_scenario("goes_next_equinox").epoch_utc).month == 3


# --------------------------------------------------------------------------- --set


def test_set_overrides_nested_keys_with_yaml_typed_values():
    s = load_scenario("goes_next_equinox", [
        "spacecraft.wheels.cant_deg=2.0",
        "control.enabled=false",
        "initial_state.rate_wrt_orbit_degps=[0.001,0,0]",
        "seed=7",
        "sensors.earth.noise_deg=0.02",
    ])
    assert s.spacecraft.wheels.cant_deg == 2.0
    assert s.control.enabled is False
    assert s.initial_state.rate_wrt_orbit_degps == (0.001, 0.0, 0.0)
    assert s.seed == 7
    assert s.sensors.earth.noise_deg == 0.02
    # siblings of the overridden keys keep their values
    assert s.spacecraft.wheels.speed_rpm == 5485
    assert s.control.pitch_loop is True
    assert s.sensors.earth.quantum_deg == 0.01
    assert s.name == "goes_next_equinox"


def test_set_one_sun_sensor_parameter_keeps_the_other_defaults():
    s = load_scenario("goes_next_equinox", ["sensors.sun.dss.noise_deg=0.01"])
    assert s.sensors.sun.dss.noise_deg == 0.01
    assert s.sensors.sun.dss.kind == "dss"
    assert s.sensors.sun.dss.quantum_deg == validate({"name": "x"}).sensors.sun.dss.quantum_deg


def test_file_with_one_sun_sensor_parameter_keeps_the_other_defaults(tmp_path):
    path = write(tmp_path, "name: x\nsensors:\n  sun:\n    cass1:\n      noise_deg: 0.5\n")
    s = load_scenario(path)
    assert s.sensors.sun.cass1.noise_deg == 0.5
    assert s.sensors.sun.cass1.kind == "cass"


def test_set_applies_in_order_and_in_place():
    raw = {"name": "x", "control": {"enabled": True}}
    apply_override(raw, "control.enabled=false")
    apply_override(raw, "control.pitch_loop=false")
    apply_override(raw, "control.enabled=true")
    assert raw == {"name": "x", "control": {"enabled": True, "pitch_loop": False}}


def test_set_value_may_contain_equals_signs():
    s = load_scenario("goes_next_equinox", ["description=a=b"])
    assert s.description == "a=b"


@pytest.mark.parametrize("value", ["1e-6", "1.5e5", "5E-5"])
def test_set_accepts_exponent_notation(value):
    s = load_scenario("goes_next_equinox", [f"environment.solar.untrimmed_torque_Nm={value}"])
    assert s.environment.solar.untrimmed_torque_Nm == float(value)


def test_max_gap_is_set_like_the_other_estimator_keys(tmp_path):
    s = load_scenario("goes_next_equinox", ["estimator.max_gap_s=7200"])
    assert s.estimator.max_gap_s == 7200.0
    assert s.estimator.sun_gap_min_h == 4.0  # its siblings keep their defaults
    path = write(tmp_path, "name: x\nestimator:\n  max_gap_s: 1.5e4\n")
    assert load_scenario(path).estimator.max_gap_s == 15000.0


def test_file_accepts_exponent_notation(tmp_path):
    path = write(tmp_path, "name: x\nestimator:\n  process_noise:\n    q_px: 3e-18\n")
    assert load_scenario(path).estimator.process_noise.q_px == 3e-18


# --------------------------------------------------------------------------- resolved YAML


def _reload(text: str, directory: Path) -> object:
    return load_scenario(write(directory, text, "resolved.yaml"))


@pytest.mark.parametrize("name", bundled_names())
def test_resolved_yaml_loads_back_to_the_same_scenario(tmp_path, name):
    s = load_scenario(name, ["seed=12345", "spacecraft.wheels.cant_deg=2.5",
                             "initial_state.rate_wrt_orbit_degps=[0.001,0,-0.002]"])
    text = resolved_yaml(s)
    again = _reload(text, tmp_path)
    # every key is written and read back unchanged (the version stamp aside)
    assert again.model_copy(update={"dynprop_version": None}) == s
    assert resolved_yaml(again) == text  # a fixed point


def test_keys_added_later_are_written_only_when_set(tmp_path):
    """The bias states, the gate and the outlier keys stay out of a scenario that does
    not set them (its scenario.yaml and Monte Carlo digest as before they existed),
    and round-trip when set."""
    plain = resolved_yaml(load_scenario("goes_next_equinox"))
    assert "bias_states" not in plain and "outlier" not in plain
    s = load_scenario("goes_next_equinox", [
        "estimator.bias_states.dss_yaw.model=constant", "estimator.outlier_gate_chi2=25",
        "sensors.sun.cass1.outlier_rate=0.01", "sensors.tachometer.outlier_size=30"])
    text = resolved_yaml(s)
    assert "bias_states" in text and "outlier_gate_chi2: 25" in text
    again = _reload(text, tmp_path)
    assert again.model_copy(update={"dynprop_version": None}) == s
    assert again.sensors.sun.cass1.outlier_rate == 0.01
    assert again.sensors.tachometer.outlier_size == 30


def test_resolved_yaml_is_stamped_with_the_package_version(tmp_path):
    from scenarios import __version__
    text = resolved_yaml(load_scenario("goes_next_equinox"))
    assert f"dynprop_version: {__version__}" in text
    raw, _ = read_raw(write(tmp_path, text))
    assert raw["dynprop_version"] == __version__
    # fully resolved: every top-level section is spelled out
    assert {"spacecraft", "orbit", "initial_state", "environment", "control", "sensors",
            "estimator", "seed", "epoch_utc", "duration_s", "sample_interval_s"} <= set(raw)
    assert raw["spacecraft"]["wheels"]["speed_rpm"] == 5485


def test_resolved_yaml_round_trip_gives_an_equal_scenario(tmp_path):
    s = load_scenario("goes_next_equinox")
    assert _reload(resolved_yaml(s), tmp_path) == s


_finite = st.floats(allow_nan=False, allow_infinity=False, width=64)


@settings(max_examples=60, deadline=None)
@given(speed=_finite.filter(lambda v: v != 0),
       cant=st.floats(0, 90, exclude_max=True),
       tab=_finite,
       rate=st.tuples(_finite, _finite, _finite),
       seed=st.integers(0, 2**64))
def test_resolved_yaml_round_trips_any_valid_numbers(tmp_path_factory, speed, cant, tab, rate,
                                                     seed):
    s = validate({"name": "h", "seed": seed,
                  "spacecraft": {"wheels": {"speed_rpm": speed, "cant_deg": cant}},
                  "environment": {"solar": {"trim_tab_deg": tab}},
                  "initial_state": {"rate_wrt_orbit_degps": list(rate)}})
    again = _reload(resolved_yaml(s), tmp_path_factory.mktemp("rt"))
    assert again.model_copy(update={"dynprop_version": None}) == s


# --------------------------------------------------------------------------- docs


# docs/scenario-reference.md against the schema: tests/scenarios/test_scenario_reference.py


def test_schema_defaults_are_the_simulator_defaults():
    """One source of defaults: a scenario that sets nothing builds exactly the
    simulator's default parameter objects."""
    from sim.control import Control
    from sim.environment import Environment
    from sim.frames import GeoOrbit
    from sim.sensors import SensorSuite
    from sim.spacecraft import goes_next

    s = validate({"name": "defaults"})
    assert build.build_control(s) == Control()
    assert build.build_environment(s) == Environment()
    assert build.build_sensors(s) == SensorSuite()
    assert build.orbit(s) == GeoOrbit()
    assert build.build_spacecraft(s) == goes_next()


# --------------------------------------------------------------------------- sensor biases

BIAS_KEYS = ("earth.roll_bias_deg", "earth.pitch_bias_deg", "tachometer.bias_rpm",
             *(f"sun.{h}.{k}" for h in ("dss", "cass1", "cass2")
               for k in ("in_plane_bias_deg", "out_of_plane_bias_deg")))


def _sensor_key(s, key: str):
    node = s.sensors
    for part in key.split("."):
        node = getattr(node, part)
    return node


def test_sensor_biases_default_to_zero_and_reach_the_built_sensors(tmp_path):
    bare = validate({"name": "x"})
    for key in BIAS_KEYS:
        assert _sensor_key(bare, key) == 0.0, key
    path = write(tmp_path, "name: x\nsensors:\n"
                 "  earth: {roll_bias_deg: 0.02, pitch_bias_deg: -0.03}\n"
                 "  tachometer: {bias_rpm: 0.05}\n"
                 "  sun:\n"
                 "    dss: {in_plane_bias_deg: 0.125, out_of_plane_bias_deg: -0.25}\n"
                 "    cass2: {out_of_plane_bias_deg: 1}\n")
    s = load_scenario(path)
    # Setting a bias keeps the head's other values (and the other heads' biases at 0).
    assert s.sensors.sun.dss.kind == "dss" and s.sensors.sun.dss.quantum_deg == 0.125
    assert s.sensors.sun.cass2.in_plane_bias_deg == 0.0
    assert s.sensors.sun.cass2.boresight_hour_angle_deg == 15.0
    suite = build.build_sensors(s)
    assert (suite.earth.roll_bias_deg, suite.earth.pitch_bias_deg) == (0.02, -0.03)
    assert suite.tachometer.bias_rpm == 0.05
    heads = {h.name: h for h in suite.sun_heads}
    assert (heads["dss"].in_plane_bias_deg, heads["dss"].out_of_plane_bias_deg) == (0.125, -0.25)
    assert (heads["cass2"].in_plane_bias_deg, heads["cass2"].out_of_plane_bias_deg) == (0.0, 1.0)
    assert (heads["cass1"].in_plane_bias_deg, heads["cass1"].out_of_plane_bias_deg) == (0.0, 0.0)
    # And by --set, and as Monte Carlo dispersions (offsets from the nominal 0).
    s = load_scenario("goes_next_equinox", ["sensors.sun.cass1.in_plane_bias_deg=-0.5",
                                            "sensors.tachometer.bias_rpm=1e-2"])
    assert s.sensors.sun.cass1.in_plane_bias_deg == -0.5 and s.sensors.tachometer.bias_rpm == 0.01
    validate({"name": "x", "montecarlo": {"dispersions": {
        f"sensors.{key}": {"distribution": "normal", "sigma": 0.01} for key in BIAS_KEYS}}})


@pytest.mark.parametrize("key", BIAS_KEYS)
@pytest.mark.parametrize("bad", [math.nan, math.inf, "0.1", True],
                         ids=["nan", "inf", "str", "bool"])
def test_sensor_biases_reject_non_numbers_naming_the_key(key, bad):
    raw: dict = {"name": "x"}
    apply_override(raw, f"sensors.{key}=0")
    node = raw["sensors"]
    *parents, leaf = key.split(".")
    for part in parents:
        node = node[part]
    node[leaf] = bad
    with pytest.raises(ScenarioError) as exc_info:
        validate(raw)
    assert_error(exc_info, f"sensors.{key}:")


def test_yaml_nan_bias_is_rejected(tmp_path):
    path = write(tmp_path, "name: x\nsensors:\n  sun:\n    dss:\n      in_plane_bias_deg: .nan\n")
    with pytest.raises(ScenarioError) as exc_info:
        load_scenario(path)
    assert_error(exc_info, "sensors.sun.dss.in_plane_bias_deg:")
