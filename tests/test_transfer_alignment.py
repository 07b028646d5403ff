"""Transfer alignment filter (seed 000, Table 2): truth, error model, consistency, observability."""

import numpy as np
import pytest
from scipy import stats
from scipy.spatial.transform import Rotation

from montecarlo import units
from montecarlo.seed000 import table2 as t2
from montecarlo.seed000 import transfer_alignment as ta


@pytest.fixture(scope="module")
def short_truth():
    cfg = ta.AlignmentConfig(duration=10.0)
    return cfg, ta.make_truth(cfg)


def test_table2_as_printed():
    """Seed 000, Table 2: five rows, 1σ; gyro in °/h, accelerometer in g, angles in arc-min."""
    printed = [(0.05, 5e-4, 13, 20), (0.05, 1e-4, 8, 12), (0.05, 5e-5, 3, 5),
               (0.50, 5e-5, 3, 5), (1.00, 5e-5, 3, 5)]
    assert [(r.gyro_deg_h, r.accel_g, r.heading_arcmin, r.level_arcmin)
            for r in t2.TABLE2_ROWS] == printed
    assert t2.TABLE2_ROWS[4].gyro_drift == pytest.approx(np.radians(1.0) / 3600, rel=1e-12)
    assert t2.TABLE2_ROWS[0].accel_bias == pytest.approx(5e-4 * 9.80665, rel=1e-12)


def test_s_turn_is_a_coordinated_turn():
    """Aircraft body (mount = 0): specific force along body z; bank = atan(V w / g)."""
    cfg = ta.AlignmentConfig(mount=(0.0, 0.0, 0.0))
    truth = ta.make_truth(cfg)
    f_b = truth.f_b
    # finite-difference specific force: relative error O((w dt)^2) ~ 1e-7
    assert np.abs(f_b[:, :2]).max() < 1e-5 * np.linalg.norm(f_b, axis=-1).min()
    horizontal = np.linalg.norm(truth.f_n[:, :2], axis=-1)
    bank = np.arctan(horizontal.max() / units.G0)
    assert bank == pytest.approx(cfg.bank, rel=1e-5)
    # heading swings back: the S-turn returns to its initial heading after one period
    C0, v = ta.aircraft_motion(cfg, np.array([0.0, cfg.period]))
    np.testing.assert_allclose(C0[1], C0[0], atol=1e-12)
    np.testing.assert_allclose(np.linalg.norm(v, axis=-1), cfg.speed, rtol=1e-12)


def test_aircraft_attitude_matches_scipy_zxy():
    """C_{b_f}^g = Rotation.from_euler('ZXY', [psi, theta, gamma]) (active),
    docs/reference/conventions.md."""
    cfg = ta.AlignmentConfig(manoeuvre="wing_rock", bank=0.3, period=8.0)
    t = np.array([1.0, 2.5])
    C_bn, _ = ta.aircraft_motion(cfg, t)
    gamma = cfg.bank * np.sin(2 * np.pi * t / cfg.period)
    expect = Rotation.from_euler("ZXY", np.stack([0 * t, 0 * t, gamma], -1)).as_matrix()
    np.testing.assert_allclose(C_bn, expect, atol=1e-14)


def test_error_free_mechanisation_reproduces_truth(short_truth):
    """With perfect IMU outputs the slave stays on the truth (round-off only)."""
    cfg, truth = short_truth
    C, v = truth.C_bn[0], truth.v_n[0]
    for k in range(cfg.n_steps):
        C, v = ta.mechanisation_step(C, v, truth.dtheta[k], truth.f_b[k], cfg.dt)
    np.testing.assert_allclose(v, truth.v_n[-1], atol=1e-9)
    np.testing.assert_allclose(C, truth.C_bn[-1], atol=1e-12)


def test_error_model_matches_nonlinear_mechanisation(short_truth):
    """F (phi' = -C b_g, dv' = f x phi + C b_a) against the nonlinear slave, a finite difference.

    The residual of the linear model must be second order: halving the injected error quarters
    it, and it is a small fraction of the propagated error.
    """
    cfg, truth = short_truth

    def nonlinear(x0):
        C = ta._exp(-x0[:3]) @ truth.C_bn[0]
        v = truth.v_n[0] + x0[3:6]
        for k in range(cfg.n_steps):
            C, v = ta.mechanisation_step(C, v, truth.dtheta[k] + x0[6:9] * cfg.dt,
                                         truth.f_b[k] + x0[9:12], cfg.dt)
        return np.concatenate([ta._misalignment(C, truth.C_bn[-1]), v - truth.v_n[-1]])

    Phi = np.eye(12)
    for k in range(cfg.n_steps):
        Fdt = ta._system_matrices(cfg, truth.C_mid[k], truth.f_n[k]) * cfg.dt
        Phi = (np.eye(12) + Fdt + 0.5 * Fdt @ Fdt) @ Phi
    scale = np.r_[[1e-3] * 3, [1e-2] * 3, [1e-5] * 3, [1e-3] * 3]
    x0 = np.random.default_rng(3).standard_normal(12) * scale
    residuals = []
    for s in (1.0, 0.5):
        linear = (Phi @ (s * x0))[:6]
        residuals.append(np.linalg.norm(nonlinear(s * x0) - linear))
        assert residuals[-1] < 1e-2 * np.linalg.norm(linear)
    assert residuals[0] / residuals[1] == pytest.approx(4.0, rel=0.05)


def _nees_bounds(runs, dof, p=0.999):
    lo, hi = stats.chi2.ppf([(1 - p) / 2, (1 + p) / 2], dof * runs)
    return lo / runs, hi / runs


@pytest.mark.parametrize("kwargs", [
    {},
    {"manoeuvre": "wing_rock", "attitude_matching": True, "bank": np.radians(15.0),
     "period": 4.0, "duration": 30.0},
])
def test_filter_is_consistent_with_its_truth(kwargs):
    """Mean NEES of the final error state over the runs lies in its chi-square 99.9 % interval.

    Also the actual rms attitude error of each axis agrees with the filter's 1σ within the
    chi-square interval of a sample variance.
    """
    runs = 100
    cfg = ta.AlignmentConfig(**kwargs)
    res = ta.simulate(cfg, np.random.default_rng(11), runs)
    lo, hi = _nees_bounds(runs, cfg.n_states)
    assert lo < res.nees().mean() < hi
    var = np.mean(res.phi[-1] ** 2, axis=0)
    sigma2 = res.cov.attitude_sigma()[-1] ** 2
    lo, hi = stats.chi2.ppf([0.0005, 0.9995], runs) / runs
    assert np.all((lo < var / sigma2) & (var / sigma2 < hi)), var / sigma2


def test_same_seed_same_numbers():
    cfg = ta.AlignmentConfig(duration=4.0)
    a = ta.simulate(cfg, np.random.default_rng(5), 3)
    b = ta.simulate(cfg, np.random.default_rng(5), 3)
    np.testing.assert_array_equal(a.phi, b.phi)


def _level_flight_segment():
    truth = ta.make_truth(ta.AlignmentConfig(manoeuvre="level", duration=1.0))
    return truth.C_mid[0], truth.f_n[0]


def test_heading_unobservable_in_level_flight():
    """f^n = [0, 0, g] makes f x e_U = 0: heading is in the null space of the observability matrix.

    Adding a turn segment (horizontal specific force, rotated body) makes it observable.
    """
    cfg = ta.AlignmentConfig()
    C, f = _level_flight_segment()
    e_heading = np.zeros(cfg.n_states)
    e_heading[2] = 1.0
    O_level = ta.observability_matrix(cfg, [(C, f)])
    assert np.linalg.norm(O_level @ e_heading) == 0.0
    turn = ta.make_truth(cfg)
    k = int(np.argmax(np.linalg.norm(turn.f_n[:, :2], axis=-1)))
    O_turn = ta.observability_matrix(cfg, [(C, f), (turn.C_mid[k], turn.f_n[k])])
    assert np.linalg.norm(O_turn @ e_heading) > 1.0
    assert np.linalg.matrix_rank(O_turn) > np.linalg.matrix_rank(O_level)


def test_level_tilt_and_horizontal_bias_inseparable_without_manoeuvre():
    """In level flight only phi_N - b_E/g (and phi_E + b_N/g) are seen: the level error tends to
    the posterior of that one combination, 1/sigma^2 = 1/sigma_level0^2 + g^2/sigma_bias^2.

    Finite velocity noise adds (sigma_v / (g T))^2 at most, 0.4 % of the variance here.
    """
    cfg = ta.AlignmentConfig(manoeuvre="level", accel_bias=5e-4 * units.G0)
    sigma = np.sqrt(np.diag(ta.final_attitude_covariance(cfg)))
    limit = 1.0 / np.sqrt(1.0 / cfg.initial_level**2 + units.G0**2 / cfg.accel_bias**2)
    np.testing.assert_allclose(sigma[:2], limit, rtol=0.01)
    # and the heading has learned nothing: its sigma only grew (drift, angle random walk)
    assert sigma[2] >= cfg.initial_heading


def test_s_turn_makes_heading_observable():
    cfg = ta.AlignmentConfig()
    sigma = ta.covariance_analysis(cfg).attitude_sigma()
    assert sigma[-1, 2] < cfg.initial_heading / 100


def test_table2_trend_level_is_driven_by_the_accelerometer():
    """Seed 000, Table 2: 'IMU alignment accuracy is mainly affected by the accelerometer'.

    Our level error grows with the accelerometer bias (rows 3 -> 2 -> 1) by more than it grows
    with a 20-fold gyro drift (rows 3 -> 5).
    """
    level = []
    for row in t2.TABLE2_ROWS:
        P = ta.final_attitude_covariance(t2.grade_config(row.gyro_drift, row.accel_bias))
        level.append(np.sqrt(P[0, 0] + P[1, 1]))
    assert level[2] < level[1] < level[0]
    assert level[0] / level[2] > 2.0
    assert level[4] / level[2] < 1.2


def test_covariance_does_not_depend_on_the_mounting():
    """Isotropic random biases: the slave's mounting on the aircraft changes nothing."""
    a = ta.final_attitude_covariance(ta.AlignmentConfig(duration=30.0))
    b = ta.final_attitude_covariance(ta.AlignmentConfig(duration=30.0, mount=(0.0, 0.0, 0.0)))
    np.testing.assert_allclose(a, b, rtol=1e-9, atol=1e-20)


def test_bad_config_rejected():
    with pytest.raises(ValueError, match="manoeuvre"):
        ta.AlignmentConfig(manoeuvre="barrel_roll")
    with pytest.raises(ValueError, match="Kalman"):
        ta.AlignmentConfig(duration=0.01)


def test_default_table2_grid_regression():
    """Stored values (docs/reference/air.md, Table 2 comparison): filter 1σ heading and level RSS
    [′],
    default configuration, to the two decimals printed there."""
    heading, level = [], []
    for row in t2.TABLE2_ROWS:
        P = ta.final_attitude_covariance(t2.grade_config(row.gyro_drift, row.accel_bias))
        heading.append(round(np.sqrt(P[2, 2]) / units.ARCMIN, 2))
        level.append(round(np.sqrt(P[0, 0] + P[1, 1]) / units.ARCMIN, 2))
    assert heading == [0.20, 0.20, 0.20, 0.31, 0.34]
    assert level == [0.57, 0.37, 0.23, 0.25, 0.25]
