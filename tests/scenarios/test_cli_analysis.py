"""`dynprop observability` and `dynprop covariance` (issue 4) through the CLI."""

import re

import pytest

from scenarios.cli import main


def test_observability_prints_the_paper_rank_progressions(capsys):
    assert main(["observability", "goes_next_equinox"]) == 0
    out = capsys.readouterr().out
    rows = {line.split("(")[0].strip(): line for line in out.splitlines() if "(Eq" in line}
    assert re.search(r"3\s+5\s+7\s+9\s+9", rows["G: roll, yaw, h; 9 states"])
    assert "never (8/9)" in rows["G'': roll, h; 9 states"]
    assert re.search(r"k=6\s+full at k=6", rows["G': roll, h; 8 states, no N_cz"])
    assert "N_cz" in out and "unobservable" in out


def test_covariance_prints_every_method_next_to_the_paper(capsys):
    assert main(["covariance", "goes_next_equinox"]) == 0
    out = capsys.readouterr().out
    sig = {line[:44].strip(): float(line.split()[-1].rstrip("°"))
           for line in out.splitlines() if line.endswith("°")}
    assert sig["paper (Eq. 56)"] == 0.040
    for method in ("Eq. 54 closed form", "Eq. 55 approximation q/(w0 H^2)",
                   "Eq. 49 steady state (solve_continuous_are)"):
        assert abs(sig[method] - 0.0397) < 0.0005
    assert 0.035 < sig["9-state, daily yaw gap: at the gap end"] < 0.05


def test_covariance_follows_the_scenario(capsys):
    """σ_yaw ≈ √(q/(ω0 H²)) (Eq. 55): four times q doubles it."""
    main(["covariance", "goes_next_equinox"])
    base = capsys.readouterr().out
    main(["covariance", "goes_next_equinox", "--set", "estimator.process_noise.q_x=2.16e-6",
          "--set", "estimator.process_noise.q_z=2.16e-6"])
    quad = capsys.readouterr().out

    def eq55(text):
        line = next(s for s in text.splitlines() if s.startswith("Eq. 55"))
        return float(line.split()[-1].rstrip("°"))

    assert eq55(quad) == pytest.approx(2 * eq55(base), rel=0.02)


@pytest.mark.parametrize("command", ["observability", "covariance"])
def test_bad_scenario_is_one_line_exit_2(command, capsys):
    assert main([command, "goes_next_equinox", "--set", "spacecraft.wheels.speed_rpm=0"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "spacecraft.wheels.speed_rpm" in err[0]


def test_h_variance_follows_the_wheel_configuration():
    """h = Σ k_i Ω_i: two canted wheels give 2 (I_w sin c)² R_tach (Eqs. 2, 46); the
    backup configuration (I_w sin c)² + I_rw², its yaw reaction wheel along z."""
    import numpy as np

    from estimator.covariance import h_variance, tach_variance
    from scenarios.config.build import estimator_sensor_specs
    from scenarios.config.loader import load_scenario

    kc = 0.1082 * np.sin(np.deg2rad(1.656))
    nominal = estimator_sensor_specs(load_scenario("goes_next_equinox"))
    backup = estimator_sensor_specs(load_scenario("backup_wheel"))
    # A few products of the same inputs: a few ulps apart at most.
    assert h_variance(nominal) == pytest.approx(2 * kc**2 * tach_variance(nominal), rel=1e-12)
    assert h_variance(backup) == pytest.approx((kc**2 + 0.008626**2) * tach_variance(backup),
                                               rel=1e-12)
