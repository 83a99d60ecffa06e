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

    from estimator.linear.noise import h_variance, tach_variance
    from scenarios.config.build import estimator_sensor_specs
    from scenarios.config.loader import load_scenario

    kc = 0.1082 * np.sin(np.deg2rad(1.656))
    nominal = estimator_sensor_specs(load_scenario("goes_next_equinox"))
    backup = estimator_sensor_specs(load_scenario("backup_wheel"))
    # A few products of the same inputs: a few ulps apart at most.
    assert h_variance(nominal) == pytest.approx(2 * kc**2 * tach_variance(nominal), rel=1e-12)
    assert h_variance(backup) == pytest.approx((kc**2 + 0.008626**2) * tach_variance(backup),
                                               rel=1e-12)


# The DSS as the paper gives it (Section 2.1) and the run filter's correlation time of
# its quantisation error (estimator.dss_error_correlation_s): the yaw variance a run's
# filter gives a DSS reading is noise² + quantum²/12 · (600 s / 0.512 s), by hand.
DSS_NOISE_DEG, DSS_QUANTUM_DEG = 0.0042, 0.125
RUN_YAW_INFLATION = (DSS_NOISE_DEG**2 + DSS_QUANTUM_DEG**2 / 12 * 600 / 0.512) / \
    (DSS_NOISE_DEG**2 + DSS_QUANTUM_DEG**2 / 12)


def test_covariance_weighs_yaw_as_a_run_does_and_says_so(capsys):
    """`dynprop covariance` takes the yaw variance a run's filter uses (the DSS's,
    down-weighted for its correlated quantisation error), prints it, and follows the
    scenario's correlation time."""
    import numpy as np

    assert main(["covariance", "goes_next_equinox"]) == 0
    out = capsys.readouterr().out
    white = (DSS_NOISE_DEG**2 + DSS_QUANTUM_DEG**2 / 12) * (np.pi / 180) ** 2
    m = re.search(r"R_yaw x ([\d.]+) = ([\d.e+-]+) rad\^2", out)
    # printed to 4 and 3 significant digits
    assert float(m[1]) == pytest.approx(RUN_YAW_INFLATION, rel=1e-3)
    assert float(m[2]) == pytest.approx(white * RUN_YAW_INFLATION, rel=5e-3)
    assert f"R_yaw = {white:.2e} rad^2" in out and "600 s" in out and "CASS" in out
    # A ten times shorter correlation time weighs the DSS ten times more: the daily
    # minimum, set by the yaw updates, falls (measured 0.0174° to 0.0101°).
    def gap_min(text):
        line = next(s for s in text.splitlines() if "daily minimum" in s)
        return float(line.split()[-1].rstrip("°"))
    assert main(["covariance", "goes_next_equinox", "--set",
                 "estimator.dss_error_correlation_s=60"]) == 0
    assert gap_min(capsys.readouterr().out) < 0.8 * gap_min(out)


@pytest.mark.parametrize("inflation", [1.0, RUN_YAW_INFLATION])
def test_nine_state_yaw_all_day_is_the_dare(inflation):
    """With yaw every sample (no gap) the report's 9-state σ_yaw is the a-priori steady
    state of the discrete filter: scipy's solve_discrete_are on the closed-form Φ, Q_d
    (estimator.linear.transition) with roll, yaw and h rows, R_yaw = spec × ``inflation``."""
    import numpy as np
    from scipy.linalg import solve_discrete_are

    from estimator.analysis.covariance_report import covariance_report
    from estimator.linear.model import H_WHEEL, N_STATES, R, Y
    from estimator.linear.noise import h_variance, roll_variance, yaw_variance
    from estimator.linear.transition import discretize
    from scenarios.config.build import estimator_model, estimator_sensor_specs
    from scenarios.config.loader import load_scenario

    s = load_scenario("goes_next_equinox")
    p, noise = estimator_model(s)
    specs = estimator_sensor_specs(s)
    report = covariance_report(p, noise, specs, gap_s=0.0, yaw_inflation=inflation)
    d = discretize(p, noise, specs.dt_s)
    # States scaled to comparable sizes (h by H, the torques by H ω0) for the solver.
    k = np.array([1.0] * 4 + [abs(p.H_Nms)] + [abs(p.H_Nms) * p.omega0_radps] * 4)
    Phi, Qd = d.Phi * k[None, :] / k[:, None], d.Qd / np.outer(k, k)
    rows = np.eye(N_STATES)[[R, Y, H_WHEEL]] * k[None, :]
    Rm = np.diag([roll_variance(specs), yaw_variance(specs) * inflation, h_variance(specs)])
    P = solve_discrete_are(Phi.T, rows.T, Qd, Rm) * np.outer(k, k)
    # Two solvers of one Riccati equation (doubling, Van Loan Φ; scipy's Schur method,
    # closed-form Φ): measured 9e-11 and 8e-12 relative; 1e-8.
    assert report["methods"]["gap_end"]["sigma_yaw_deg"] == \
        pytest.approx(np.rad2deg(np.sqrt(P[Y, Y])), rel=1e-8)
