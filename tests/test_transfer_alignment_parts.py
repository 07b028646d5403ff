"""The transfer-alignment filter's parts against closed forms, scipy and hand values: the
configuration's checks, the truth, the error-state matrices, one Kalman step in information
form, and the simulated IMU noise against its stated densities (seed 000, section 2)."""

import math

import numpy as np
import pytest
from scipy.linalg import expm
from scipy.spatial.transform import Rotation

from montecarlo.seed000 import transfer_alignment as ta

G0 = 9.80665


# --- configuration -----------------------------------------------------------------------------


@pytest.mark.parametrize("kwargs, message", [
    ({"period": 0.0}, r"need period > 0 \(got 0.0 s\), speed > 0 \(got 200.0 m/s\) and "
                      r"\|bank\| < 90° \(got 0.5 rad\)"),
    ({"speed": 0.0}, r"speed > 0 \(got 0.0 m/s\)"),
    ({"bank": math.pi / 2}, r"\|bank\| < 90°"),
    ({"bank": -math.pi / 2}, r"\|bank\| < 90°"),
    ({"kf_interval": 0}, r"^duration 120.0 s: need dt > 0, kf_interval >= 1 and at least one "
                         r"Kalman update$"),
    ({"dt": 0.0}, "at least one Kalman update"),
    ({"duration": 0.2 - 1e-9}, "at least one Kalman update"),
])
def test_a_configuration_outside_its_domain_is_refused(kwargs, message):
    with pytest.raises(ValueError, match=message):
        ta.AlignmentConfig(**{"bank": 0.5, **kwargs})


def test_limits_of_the_configuration_and_its_counts():
    """One Kalman interval exactly (0.02 s x 10) is enough; a bank just under 90° is a bank.
    Steps are a whole number of Kalman intervals: 1.09 s -> round(5.45) = 5 updates, 50
    steps; 1.11 s -> 6 updates, 60 steps. 12 states, 15 with attitude matching."""
    one = ta.AlignmentConfig(duration=0.2)
    assert one.n_steps == 10
    assert ta.AlignmentConfig(bank=math.pi / 2 - 1e-6).bank < math.pi / 2
    assert ta.AlignmentConfig(duration=1.09).n_steps == 50
    assert ta.AlignmentConfig(duration=1.11).n_steps == 60
    assert ta.AlignmentConfig(duration=1.0, dt=0.01, kf_interval=4).n_steps == 100
    assert ta.AlignmentConfig().n_states == 12
    assert ta.AlignmentConfig(attitude_matching=True).n_states == 15
    with pytest.raises(ValueError, match=r"manoeuvre 'loop' not in \('level', 's_turn', "
                                         r"'wing_rock', 'surge'\)"):
        ta.AlignmentConfig(manoeuvre="loop")
    with pytest.raises(ValueError, match=r"need \|surge\| < speed \(got 20.0 m/s, speed 20.0"):
        ta.AlignmentConfig(manoeuvre="surge", speed=20.0)
    assert ta.AlignmentConfig(manoeuvre="surge", speed=20.0 + 1e-9).surge == 20.0


# --- small rotations ---------------------------------------------------------------------------


def test_skew_exp_log_against_the_cross_product_and_rodrigues():
    rng = np.random.default_rng(1)
    v, w = rng.normal(size=(2, 4, 3)), rng.normal(size=(2, 4, 3))
    np.testing.assert_allclose(np.einsum("...ij,...j->...i", ta._skew(v), w), np.cross(v, w),
                               atol=1e-14)
    c, s = math.cos(0.3), math.sin(0.3)
    np.testing.assert_allclose(ta._exp(np.array([0.0, 0.0, 0.3])),
                               [[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]], atol=1e-15)
    small = 0.1 * v
    assert ta._exp(small).shape == (2, 4, 3, 3)
    np.testing.assert_allclose(ta._log(ta._exp(small)), small, atol=1e-14)
    assert ta._log(ta._exp(small)).shape == (2, 4, 3)


def test_misalignment_is_phi_of_c_hat_equal_exp_minus_phi_c_true():
    phi = np.array([[1e-3, -2e-3, 5e-4], [0.0, 0.0, -1e-2]])
    C_true = Rotation.from_euler("ZXY", [0.3, 0.2, 0.1]).as_matrix()
    C_hat = Rotation.from_rotvec(-phi).as_matrix() @ C_true
    np.testing.assert_allclose(ta._misalignment(C_hat, C_true), phi, atol=1e-15)


def test_mechanisation_step_by_hand():
    """C = I, a turn dtheta = 0.4 rad about z and a specific force (1, 0, 0) over dt = 0.5 s:
    the force is taken at the mid-step attitude (0.2 rad): v gains (cos 0.2, sin 0.2, -g) 0.5."""
    C, v = ta.mechanisation_step(np.eye(3), np.array([1.0, 2.0, 3.0]),
                                 np.array([0.0, 0.0, 0.4]), np.array([1.0, 0.0, 0.0]), 0.5)
    np.testing.assert_allclose(v, [1.0 + 0.5 * math.cos(0.2), 2.0 + 0.5 * math.sin(0.2),
                                   3.0 - 0.5 * G0], atol=1e-14)
    np.testing.assert_allclose(C, Rotation.from_euler("z", 0.4).as_matrix(), atol=1e-15)


# --- truth -------------------------------------------------------------------------------------


def test_s_turn_at_a_quarter_period_by_hand():
    """At t = T/4: turn rate w0 = g tan(bank) / V, heading w0 T / (2 pi), bank -bank
    (coordinated: gamma = -atan(V w0 / g) = -bank); nose along (-sin psi, cos psi, 0)."""
    cfg = ta.AlignmentConfig(speed=150.0, bank=math.radians(25.0), period=40.0)
    w0 = G0 * math.tan(cfg.bank) / cfg.speed
    psi = w0 * cfg.period / (2 * math.pi)
    C, v = ta.aircraft_motion(cfg, np.array([cfg.period / 4]))
    expect = Rotation.from_euler("ZXY", [psi, 0.0, -cfg.bank]).as_matrix()
    np.testing.assert_allclose(C[0], expect, atol=1e-14)
    np.testing.assert_allclose(v[0], [-150.0 * math.sin(psi), 150.0 * math.cos(psi), 0.0],
                               atol=1e-12)
    level = ta.AlignmentConfig(manoeuvre="level", speed=90.0)
    C, v = ta.aircraft_motion(level, np.array([0.0, 7.0]))
    np.testing.assert_allclose(C, np.broadcast_to(np.eye(3), (2, 3, 3)), atol=0)
    np.testing.assert_allclose(v, [[0.0, 90.0, 0.0]] * 2, atol=0)


def test_truth_of_level_flight_is_the_mounting_and_gravity():
    """Level flight: the slave's attitude is the mounting C_a^{b_f} (seed 000, eq. 5; scipy's
    active Z-X-Y), its specific force is 1 g up, its gyros see nothing; t = k dt."""
    mount = (0.3, -0.2, 0.1)
    cfg = ta.AlignmentConfig(manoeuvre="level", duration=0.4, mount=mount)
    truth = ta.make_truth(cfg)
    np.testing.assert_allclose(truth.t, np.arange(21) * 0.02, atol=1e-15)
    C = Rotation.from_euler("ZXY", mount).as_matrix()
    np.testing.assert_allclose(truth.C_bn, np.broadcast_to(C, (21, 3, 3)), atol=1e-15)
    np.testing.assert_allclose(truth.f_n, [[0.0, 0.0, G0]] * 20, atol=1e-12)
    np.testing.assert_allclose(truth.f_b, np.broadcast_to(C.T @ [0.0, 0.0, G0], (20, 3)),
                               atol=1e-12)
    np.testing.assert_allclose(truth.dtheta, 0.0, atol=1e-15)
    np.testing.assert_allclose(truth.C_mid, np.broadcast_to(C, (20, 3, 3)), atol=1e-15)
    np.testing.assert_allclose(truth.v_n, [[0.0, 200.0, 0.0]] * 21, atol=1e-12)


def test_truth_increments_and_mid_step_attitude_in_a_turn():
    """exp([dtheta x]) = C_k^T C_{k+1} and C_mid = C_k exp([dtheta/2 x]) (scipy), and
    f_n = (v_{k+1} - v_k) / dt + (0, 0, g)."""
    cfg = ta.AlignmentConfig(duration=1.0)
    truth = ta.make_truth(cfg)
    Ck, Ck1 = Rotation.from_matrix(truth.C_bn[:-1]), Rotation.from_matrix(truth.C_bn[1:])
    np.testing.assert_allclose(truth.dtheta, (Ck.inv() * Ck1).as_rotvec(), atol=1e-14)
    half = Rotation.from_rotvec(truth.dtheta / 2)
    np.testing.assert_allclose(truth.C_mid, (Ck * half).as_matrix(), atol=1e-14)
    f_n = np.diff(truth.v_n, axis=0) / cfg.dt + [0.0, 0.0, G0]
    np.testing.assert_allclose(truth.f_n, f_n, atol=1e-9)
    np.testing.assert_allclose(truth.f_b, np.einsum("kji,kj->ki", truth.C_mid, f_n), atol=1e-9)
    assert np.abs(truth.dtheta).max() > 1e-4  # the turn is under way


# --- error-state model -------------------------------------------------------------------------


def test_error_state_matrices_block_by_block():
    """F: phi' = -C b_g, dv' = f x phi + C b_a, nothing else (the mounting error mu is
    constant); Q: angle and velocity random walk densities on phi and dv; H and R: velocity
    matching, and phi - C mu for the attitude difference."""
    C = Rotation.from_euler("ZXY", [0.4, 0.1, -0.2]).as_matrix()
    f = np.array([0.5, -1.0, G0])
    for matching in (False, True):
        cfg = ta.AlignmentConfig(attitude_matching=matching, gyro_arw=2e-6, accel_vrw=3e-4,
                                 velocity_noise=0.07, attitude_noise=4e-4)
        n = cfg.n_states
        F = ta._system_matrices(cfg, C, f)
        expect = np.zeros((n, n))
        expect[0:3, 6:9] = -C
        expect[3:6, 9:12] = C
        for j in range(3):
            e = np.zeros(3)
            e[j] = 1.0
            expect[3:6, j] = np.cross(f, e)  # column j: f x e_j
        np.testing.assert_array_equal(F, expect)
        Q = ta._process_noise(cfg)
        np.testing.assert_allclose(np.diag(Q), [4e-12] * 3 + [9e-8] * 3 + [0.0] * (n - 6),
                                   rtol=1e-15, atol=0)
        assert np.count_nonzero(Q - np.diag(np.diag(Q))) == 0
        H, R = ta.measurement_matrix(cfg, C)
        expect_H = np.zeros((6 if matching else 3, n))
        expect_H[0:3, 3:6] = np.eye(3)
        expect_R = np.diag([0.07**2] * 3 + ([4e-4**2] * 3 if matching else []))
        if matching:
            expect_H[3:6, 0:3] = np.eye(3)
            expect_H[3:6, 12:15] = -C
        np.testing.assert_array_equal(H, expect_H)
        np.testing.assert_allclose(R, expect_R, rtol=1e-15, atol=0)
        P0 = ta.initial_covariance(cfg)
        d = ([cfg.initial_level**2] * 2 + [cfg.initial_heading**2] + [0.1**2] * 3
             + [cfg.gyro_drift**2] * 3 + [cfg.accel_bias**2] * 3
             + ([math.radians(1.0) ** 2] * 3 if matching else []))
        np.testing.assert_allclose(P0, np.diag(d), rtol=1e-15, atol=0)


def test_one_step_one_update_in_information_form():
    """dt = 1 ms, one step per update: P- = Phi P0 Phi' + Q dt with Phi = expm(F dt) (the
    module's second-order series differs by (F dt)^3 / 6, 1e-9 here), and the posterior is
    (P-^-1 + H' R^-1 H)^-1, the information form of the Joseph update; K = P+ H' R^-1."""
    cfg = ta.AlignmentConfig(dt=0.001, kf_interval=1, duration=0.001, attitude_matching=True,
                             initial_velocity=0.3)
    truth = ta.make_truth(cfg)
    cov = ta.covariance_analysis(cfg)
    assert cov.P.shape == (1, 15, 15) and cov.K.shape == (1, 15, 6)
    np.testing.assert_allclose(cov.t, [0.001], rtol=1e-15)
    F = ta._system_matrices(cfg, truth.C_mid[0], truth.f_n[0])
    Phi = expm(F * cfg.dt)
    prior = Phi @ ta.initial_covariance(cfg) @ Phi.T + ta._process_noise(cfg) * cfg.dt
    H, R = ta.measurement_matrix(cfg, truth.C_bn[1])
    post = np.linalg.inv(np.linalg.inv(prior) + H.T @ np.linalg.inv(R) @ H)
    scale = np.sqrt(np.outer(np.diag(post), np.diag(post)))
    np.testing.assert_allclose(cov.P[0] / scale, post / scale, atol=1e-7)
    np.testing.assert_allclose(cov.K[0], post @ H.T @ np.linalg.inv(R), rtol=1e-6, atol=1e-12)
    np.testing.assert_allclose(cov.attitude_sigma()[0], np.sqrt(np.diag(post)[:3]), rtol=1e-7)


def test_updates_come_every_kf_interval_steps():
    cfg = ta.AlignmentConfig(duration=1.0, kf_interval=5)
    cov = ta.covariance_analysis(cfg)
    np.testing.assert_allclose(cov.t, 0.1 * np.arange(1, 11), rtol=1e-12)


def test_nees_by_hand():
    cov = ta.CovarianceHistory(np.array([1.0]), np.diag([4.0, 9.0])[None], np.zeros((1, 2, 1)))
    res = ta.MonteCarloResult(cov, np.zeros((1, 2, 3)), np.array([[2.0, 3.0], [1.0, 0.0]]),
                             np.zeros((2, 3)))
    np.testing.assert_allclose(res.nees(), [2.0, 0.25], rtol=1e-15)


def test_observability_matrix_blocks():
    """Two segments: rows [H; H F1; ...; H F1^(n-1)], then the same of F2 times expm(F1)."""
    cfg = ta.AlignmentConfig()
    C1, C2 = np.eye(3), Rotation.from_euler("z", 0.5).as_matrix()
    f1, f2 = np.array([0.0, 0.0, G0]), np.array([2.0, 0.0, G0])
    obs = ta.observability_matrix(cfg, [(C1, f1), (C2, f2)])
    n = cfg.n_states
    assert obs.shape == (2 * n * 3, n)
    F1, F2 = ta._system_matrices(cfg, C1, f1), ta._system_matrices(cfg, C2, f2)
    H, _ = ta.measurement_matrix(cfg, C1)
    np.testing.assert_allclose(obs[:3], H, atol=0)
    np.testing.assert_allclose(obs[3:6], H @ F1, atol=0)
    np.testing.assert_allclose(obs[3 * (n - 1):3 * n], H @ np.linalg.matrix_power(F1, n - 1),
                               atol=1e-9)
    np.testing.assert_allclose(obs[3 * n:3 * n + 3], H @ expm(F1), atol=1e-12)
    np.testing.assert_allclose(obs[3 * n + 3:3 * n + 6], H @ F2 @ expm(F1), atol=1e-12)


# --- the simulated IMU noise -------------------------------------------------------------------


def _free_running(**kwargs):
    """Level flight, no initial errors or biases, and a master velocity so noisy (1e6 m/s)
    that the filter's gain is ~1e-19: the slave runs free and its errors are the IMU noise."""
    base = dict(manoeuvre="level", duration=10.0, initial_level=0.0, initial_heading=0.0,
                initial_velocity=0.0, gyro_drift=0.0, accel_bias=0.0, velocity_noise=1e6)
    return ta.AlignmentConfig(**{**base, **kwargs})


def test_angle_random_walk_grows_as_its_density_times_root_time():
    """phi(T) ~ N(0, arw^2 T) per axis: arw = 1e-4 rad/sqrt(s), T = 10 s gives sigma =
    3.162e-4 rad. 300 runs x 3 axes: the pooled variance is known to sqrt(2/900) = 4.7 %,
    so 20 % is 4 of its standard errors (dividing instead of multiplying by sqrt(dt) is 50x)."""
    cfg = _free_running(gyro_arw=1e-4, accel_vrw=0.0)
    res = ta.simulate(cfg, np.random.default_rng(4), 300)
    var = np.mean(res.phi[-1] ** 2)
    assert var == pytest.approx(1e-8 * 10.0, rel=0.2)
    assert res.phi.shape == (50, 300, 3)


def test_velocity_random_walk_grows_as_its_density_times_root_time():
    """dv(T) ~ N(0, vrw^2 T) per axis with no gyro noise: vrw = 2e-3 m/s/sqrt(s), T = 10 s:
    sigma 6.32e-3 m/s; the same 20 % (4 standard errors of the pooled variance)."""
    cfg = _free_running(gyro_arw=0.0, accel_vrw=2e-3)
    res = ta.simulate(cfg, np.random.default_rng(5), 300)
    dv = res.x_true[:, 3:6]
    assert np.mean(dv ** 2) == pytest.approx(4e-6 * 10.0, rel=0.2)
    np.testing.assert_allclose(res.phi[-1], 0.0, atol=1e-12)


def test_random_constant_biases_are_drawn_from_their_sigmas():
    """With no noise and no updates, the final gyro and accelerometer bias errors are the drawn
    biases themselves, N(0, sigma^2): 300 runs x 3 axes, 20 % on the variance; the initial tilt
    is drawn with its sigma too (the heading error with its own)."""
    cfg = _free_running(gyro_arw=0.0, accel_vrw=0.0, gyro_drift=1e-5, accel_bias=1e-3,
                        initial_level=2e-3, initial_heading=5e-3, duration=0.2)
    res = ta.simulate(cfg, np.random.default_rng(6), 300)
    assert np.mean(res.x_true[:, 6:9] ** 2) == pytest.approx(1e-10, rel=0.2)
    assert np.mean(res.x_true[:, 9:12] ** 2) == pytest.approx(1e-6, rel=0.2)
    phi = res.phi[0]  # after 0.2 s the drift has moved it by 2e-6 at most
    assert np.mean(phi[:, :2] ** 2) == pytest.approx(4e-6, rel=0.2)
    assert np.mean(phi[:, 2] ** 2) == pytest.approx(25e-6, rel=0.25)


def test_a_free_running_gyro_drift_turns_the_slave_by_minus_c_b_t():
    """phi' = -C_b^n b_g (the error model's first block): in level flight with no noise and no
    updates, phi(T) = -C b_g T per run, T = 10 s (b_g T ~ 1e-4 rad: first order to 1e-4).
    The error is recorded at every Kalman update, the last one at T itself."""
    cfg = _free_running(gyro_arw=0.0, accel_vrw=0.0, gyro_drift=1e-5)
    res = ta.simulate(cfg, np.random.default_rng(7), 20)
    C = ta.make_truth(cfg).C_bn[0]
    b_g = res.x_true[:, 6:9]
    np.testing.assert_allclose(res.phi[-1], -(b_g @ C.T) * 10.0, rtol=2e-3, atol=1e-12)
    np.testing.assert_allclose(res.phi[0], -(b_g @ C.T) * 0.2, rtol=2e-3, atol=1e-12)


def test_a_free_running_accelerometer_bias_moves_the_slave_by_c_b_t():
    """dv' = C_b^n b_a with no attitude error: dv(T) = C b_a T per run."""
    cfg = _free_running(gyro_arw=0.0, accel_vrw=0.0, accel_bias=1e-3)
    res = ta.simulate(cfg, np.random.default_rng(8), 20)
    C = ta.make_truth(cfg).C_bn[0]
    b_a = res.x_true[:, 9:12]
    np.testing.assert_allclose(res.x_true[:, 3:6], (b_a @ C.T) * 10.0, rtol=1e-6, atol=1e-12)


def test_an_error_free_slave_stays_on_the_truth_through_a_turn():
    """No initial error, no bias, no noise in an S-turn: the slave's attitude and velocity stay
    on the truth (round-off only), from the first step on."""
    cfg = _free_running(gyro_arw=0.0, accel_vrw=0.0, manoeuvre="s_turn", duration=2.0)
    res = ta.simulate(cfg, np.random.default_rng(9), 2)
    assert np.abs(res.phi).max() < 1e-12
    assert np.abs(res.x_true[:, 3:6]).max() < 1e-9


def test_observability_with_attitude_matching_sees_the_mounting_through_c():
    """Attitude matching: the measurement rows are [0 I 0 0 0; I 0 0 0 -C] for the segment's C."""
    cfg = ta.AlignmentConfig(attitude_matching=True)
    C = Rotation.from_euler("z", 0.5).as_matrix()
    obs = ta.observability_matrix(cfg, [(C, np.array([0.0, 0.0, G0]))])
    assert obs.shape == (15 * 6, 15)
    np.testing.assert_array_equal(obs[3:6, 12:15], -C)
    np.testing.assert_array_equal(obs[3:6, 0:3], np.eye(3))


def test_a_short_period_and_a_slow_speed_are_allowed():
    """The limits are period > 0 and speed > 0, not 1 s and 1 m/s."""
    cfg = ta.AlignmentConfig(period=0.5, speed=0.5)
    assert (cfg.period, cfg.speed) == (0.5, 0.5)


def test_two_steps_of_the_covariance_with_an_exact_transition():
    """Without the mounting states F is nilpotent (b_g -> phi -> dv, b_a -> dv; F^3 = 0), so
    Phi = I + F dt + (F dt)^2 / 2 equals expm(F dt) exactly at any dt: at dt = 0.1 s with a
    large gyro drift the second-order term (b_g into dv, g dt^2 / 2) is 5e-4 of the
    covariances. Two updates, each P- = Phi P Phi' + Q dt (angle and velocity random walk
    large enough to count) and P+ = (P-^-1 + H' R^-1 H)^-1; attitude matching measures
    phi - C mu with the attitude after the step, which turns by about a milliradian per step
    at the start of the S-turn."""
    cfg = ta.AlignmentConfig(dt=0.1, kf_interval=1, duration=0.2, gyro_drift=1e-3,
                             gyro_arw=1e-3, accel_vrw=1e-2, attitude_matching=True)
    truth = ta.make_truth(cfg)
    cov = ta.covariance_analysis(cfg)
    P = ta.initial_covariance(cfg)
    for k in range(2):
        F = ta._system_matrices(cfg, truth.C_mid[k], truth.f_n[k])
        assert np.abs(np.linalg.matrix_power(F, 3)).max() == 0.0
        Phi = expm(F * cfg.dt)
        prior = Phi @ P @ Phi.T + ta._process_noise(cfg) * cfg.dt
        H, R = ta.measurement_matrix(cfg, truth.C_bn[k + 1])
        P = np.linalg.inv(np.linalg.inv(prior) + H.T @ np.linalg.inv(R) @ H)
        scale = np.sqrt(np.outer(np.diag(P), np.diag(P)))
        np.testing.assert_allclose(cov.P[k] / scale, P / scale, atol=1e-8)
    assert np.abs(ta._log(truth.C_bn[2] @ truth.C_bn[0].T)).max() > 1e-3


def test_a_strongly_drifting_gyro_is_estimated_and_compensated_consistently():
    """A 2e-4 rad/s (41 °/h) gyro drift over a 30 s S-turn: the filter learns it, the slave
    compensates it, and the mean NEES of the final state over 100 runs lies in its chi-square
    99.9 % interval (the compensation applied with the wrong sign gives a NEES of 3e5)."""
    from scipy import stats

    runs = 100
    cfg = ta.AlignmentConfig(gyro_drift=2e-4, duration=30.0)
    res = ta.simulate(cfg, np.random.default_rng(11), runs)
    lo, hi = stats.chi2.ppf([0.0005, 0.9995], cfg.n_states * runs) / runs
    assert lo < res.nees().mean() < hi
