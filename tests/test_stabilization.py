"""Seed 001 (patent CN102288133B): exact kinematics, eq. (4) loop, derived linear model.

References are independent of the code under test: scipy's Rotation, finite differences of the
exact simulator, analytic properties (a perfect loop holds the LOS), and the printed eqs. (5)-(6).
"""

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from montecarlo.geometry.camera import pixels_from_direction
from montecarlo.seed001 import kinematics as kin
from montecarlo.seed001 import linear_model as lin
from montecarlo.seed001 import simulate as sim
from montecarlo.seed001.estimate import carrier_attitude

D = np.pi / 180.0
rng = np.random.default_rng(20110429)  # the patent's filing date
ROCK = kin.Rocking(np.full(3, 5 * D), [0.25, 0.4, 0.32], [0.0, 1.0, 2.0])
SETUP = sim.Setup(duration=10.0, rate=100.0, aim_azimuth=20 * D, aim_pitch=10 * D,
                 image_noise=0.0)


def _random_state(n=50):
    omega = rng.normal(scale=0.2, size=(n, 3))
    eta = rng.uniform(-1.0, 1.0, n)
    eps = rng.uniform(-1.0, 1.0, n)
    return omega, eta, eps


def _los_rate_xz(omega, eta, eps, delta_g, delta_p, bias=0.0):
    """x and z camera rates when the loop integrates eq. (4) from the measured rate."""
    eta_dot, eps_dot = kin.gimbal_rates(kin.measured_rate(omega, delta_g, bias), eta, eps)
    return kin.camera_rate(omega, eta, eps, eta_dot, eps_dot, delta_p)[..., [0, 2]]


# --- frames and kinematics -------------------------------------------------------------------


def test_carrier_attitude_is_scipy_zxy_and_body_rate_is_its_derivative():
    """C_n^b = Rotation.from_euler('ZXY', angles).as_matrix().T; -[w x] = dC/dt C^T."""
    t = np.linspace(0.0, 7.0, 71)
    C = ROCK.attitude(t)
    ref = Rotation.from_euler("ZXY", ROCK.angles(t)).as_matrix()
    np.testing.assert_allclose(C, np.swapaxes(ref, -1, -2), atol=1e-15)
    h = 1e-6
    dC = (ROCK.attitude(t + h) - ROCK.attitude(t - h)) / (2 * h)
    W = -dC @ np.swapaxes(C, -1, -2)
    omega = np.stack([W[:, 2, 1], W[:, 0, 2], W[:, 1, 0]], -1)
    np.testing.assert_allclose(ROCK.body_rate(t), omega, atol=1e-8)


def test_eq1_small_angle_matrices_are_first_order_of_imu_matrix():
    """Eq. (1): R_y(dgy) R_x(dgx) R_z(dgz) as printed equals C_b^g to second order."""
    for scale in (1e-2, 1e-3):
        gx, gy, gz = scale * np.array([0.7, -0.4, 0.9])
        Ry = np.array([[1, 0, -gy], [0, 1, 0], [gy, 0, 1]])
        Rx = np.array([[1, 0, 0], [0, 1, gx], [0, -gx, 1]])
        Rz = np.array([[1, gz, 0], [-gz, 1, 0], [0, 0, 1]])
        err = np.abs(Ry @ Rx @ Rz - kin.imu_matrix([gx, gy, gz])).max()
        assert err < 1.1 * scale**2


def test_eq4_rates_hold_the_los():
    """With the true carrier rate, eq. (4) zeroes the x and z camera rates (LOS fixed)."""
    omega, eta, eps = _random_state()
    np.testing.assert_allclose(_los_rate_xz(omega, eta, eps, 0.0, 0.0), 0.0, atol=1e-15)


def test_eq2_camera_rate_is_the_derivative_of_the_simulated_camera_attitude():
    """Eq. (2) with the pitch rate along x, against finite differences of C_n^c in time.

    The printed ``[0 0 eps']`` would put the pitch rate about z: the same check fails for it.
    """
    delta_g, delta_p = np.array([0.5, -0.3, 0.7]) * D, np.array([0.4, 0.6, -0.6]) * D
    setup = sim.Setup(duration=2.0, rate=1000.0, aim_azimuth=20 * D, aim_pitch=10 * D)
    run = sim.simulate(ROCK, setup, delta_g, delta_p, rng=0)
    C = kin.camera_matrix(run.eta, run.eps, delta_p) @ ROCK.attitude(run.t)
    h = 1.0 / setup.rate
    W = -(C[2:] - C[:-2]) / (2 * h) @ np.swapaxes(C[1:-1], -1, -2)
    fd = np.stack([W[:, 2, 1], W[:, 0, 2], W[:, 1, 0]], -1)
    omega = ROCK.body_rate(run.t[1:-1])
    eta_dot, eps_dot = kin.gimbal_rates(kin.measured_rate(omega, delta_g), run.eta[1:-1],
                                       run.eps[1:-1])
    model = kin.camera_rate(omega, run.eta[1:-1], run.eps[1:-1], eta_dot, eps_dot, delta_p)
    scale = np.abs(model).max()
    assert np.abs(fd - model).max() < 1e-5 * scale  # central differences: O(h^2)
    # the printed vector [0, 0, eps']: remove eps' from x, add it to z (turned by dpy)
    printed = model.copy()
    printed[:, 0] -= np.cos(delta_p[1]) * eps_dot
    printed[:, 2] += np.cos(delta_p[1]) * eps_dot
    assert np.abs(fd - printed).max() > 0.1 * scale


def test_perfect_loop_holds_the_target_in_the_image_centre():
    """No installation angles, bias or noise: the LOS error stays at round-off level."""
    run = sim.simulate(ROCK, SETUP, 0.0, 0.0)
    assert run.los_error.max() < 1e-9
    assert np.abs(run.los_px_true).max() < 1e-5


def test_equal_dpz_and_dgz_leave_the_los_exactly_stabilised():
    """Exact (not first-order): dpz = dgz cancel, since only delta_z = dpz - dgz matters."""
    a = 0.8 * D
    run = sim.simulate(ROCK, SETUP, [0.0, 0.0, a], [0.0, 0.0, a])
    assert run.los_error.max() < 1e-9
    single = sim.simulate(ROCK, SETUP, [0.0, 0.0, a], 0.0)
    assert single.los_error.max() > 1e-4


def test_rk4_gimbal_matches_the_closed_form_loop():
    """The loop of eq. (4) keeps its LOS fixed relative to the attitude integrated from w_m.

    Independent route: integrate w_m to an attitude (Magnus), carry the initial LOS with it,
    read azimuth and pitch back. Gyro noise off (the two routes hold noise differently).
    """
    delta_g = np.array([0.5, -0.3, 0.7]) * D
    run = sim.simulate(ROCK, SETUP, delta_g, 0.0, gyro_bias=[1e-4, -2e-4, 3e-4])
    R = carrier_attitude(run.t, run.gyro)
    los = np.swapaxes(R, -1, -2) @ kin.los_direction(run.eta[0], run.eps[0])
    np.testing.assert_allclose(run.eta, np.arctan2(-los[:, 0], los[:, 1]), atol=1e-9)
    np.testing.assert_allclose(run.eps, np.arcsin(los[:, 2]), atol=1e-9)


def test_pixel_signs():
    """A LOS turned left (about +z) puts the target right (+x); turned up puts it down (-z)."""
    a, cam = 1e-3, sim.DEFAULT_CAMERA
    target = kin.camera_matrix(0.0, 0.0)[1]  # LOS at zero gimbal angles, carrier axes
    x, z = pixels_from_direction(kin.camera_matrix(a, 0.0) @ target, cam)
    assert x == pytest.approx(cam.k_x * a, rel=1e-6) and abs(z) < 1e-9
    x, z = pixels_from_direction(kin.camera_matrix(0.0, a) @ target, cam)
    assert z == pytest.approx(-cam.k_z * a, rel=1e-6) and abs(x) < 1e-9


def test_batch_shapes_and_reproducibility():
    delta = rng.normal(scale=0.01, size=(4, 3))
    setup = sim.Setup(duration=1.0, rate=50.0, gyro_noise=1e-5, image_noise=0.1)
    a = sim.simulate(ROCK, setup, delta, 0.0, rng=3)
    b = sim.simulate(ROCK, setup, delta, 0.0, rng=3)
    assert a.gyro.shape == (4, 51, 3) and a.los_px.shape == (4, 51, 2) and a.eta.shape == (4, 51)
    np.testing.assert_array_equal(a.los_px, b.los_px)
    one = sim.simulate(ROCK, sim.Setup(duration=1.0, rate=50.0), delta[2], 0.0)
    all_ = sim.simulate(ROCK, sim.Setup(duration=1.0, rate=50.0), delta, 0.0)
    np.testing.assert_allclose(all_.los_px_true[2], one.los_px_true, rtol=1e-12, atol=1e-12)


def test_compensation_with_the_truth_restores_a_perfect_loop():
    """Claim 1, fourth step: compensating the true combinations and bias cancels the error."""
    delta_g, delta_p = np.array([0.9, -0.5, 0.7]) * D, np.array([0.4, 0.6, -0.6]) * D
    bias = np.array([3e-5, -2e-5, 1e-5])
    truth = [delta_p[0], delta_g[0], delta_g[1], delta_p[2] - delta_g[2]]
    before = sim.simulate(ROCK, SETUP, delta_g, delta_p, bias)
    after = sim.simulate(ROCK, SETUP, delta_g, delta_p, bias,
                        compensation=sim.Compensation(truth, bias))
    assert before.los_error.max() > 1e-3
    assert after.los_error.max() < 1e-9


# --- linearised model ------------------------------------------------------------------------


def _fd_columns(omega, eta, eps, h=1e-7):
    """Central differences of the exact x, z camera rates for dpx, dgx, dgy, dpz, dgz."""
    moves = {"dpx": (0, 0, 0, 1, 0, 0), "dgx": (1, 0, 0, 0, 0, 0), "dgy": (0, 1, 0, 0, 0, 0),
             "dpz": (0, 0, 0, 0, 0, 1), "dgz": (0, 0, 1, 0, 0, 0)}
    out = {}
    for name, m in moves.items():
        m = h * np.array(m, float)
        out[name] = (_los_rate_xz(omega, eta, eps, m[:3], m[3:])
                     - _los_rate_xz(omega, eta, eps, -m[:3], -m[3:])) / (2 * h)
    return out


def test_rate_model_matches_finite_differences_of_the_exact_rate():
    omega, eta, eps = _random_state()
    H = lin.los_rate_matrix(omega, eta, eps)
    fd = _fd_columns(omega, eta, eps)
    for j, name in enumerate(["dpx", "dgx", "dgy", "dpz"]):
        np.testing.assert_allclose(H[..., j], fd[name], atol=1e-8)
    # dpz and dgz enter only as delta_z = dpz - dgz
    np.testing.assert_allclose(fd["dgz"], -fd["dpz"], atol=1e-8)


def test_bias_model_matches_finite_differences_and_has_orthonormal_rows():
    omega, eta, eps = _random_state()
    G = lin.bias_rate_matrix(eta, eps)
    h = 1e-7
    for j, e in enumerate(np.eye(3)):
        fd = (_los_rate_xz(omega, eta, eps, 0.0, 0.0, h * e)
              - _los_rate_xz(omega, eta, eps, 0.0, 0.0, -h * e)) / (2 * h)
        np.testing.assert_allclose(G[..., j], fd, atol=1e-8)
    np.testing.assert_allclose(G @ np.swapaxes(G, -1, -2), np.broadcast_to(np.eye(2), (50, 2, 2)),
                               atol=1e-15)


def test_patent_eq6_against_the_derived_model():
    """Row 1, H_23, H_24 agree; H_22 agrees once its stray eps is dropped; H_21 differs by
    sin(eps) eta' (the eta' term of eq. (2) not turned by dpx), zero for a level LOS."""
    omega, eta, eps = _random_state()
    ours = lin.los_rate_matrix(omega, eta, eps)
    printed = lin.patent_eq6_matrix(omega, eta, eps)
    fixed = lin.patent_eq6_matrix(omega, eta, eps, as_printed=False)
    np.testing.assert_allclose(printed[..., 0, :], ours[..., 0, :], atol=1e-15)
    np.testing.assert_allclose(fixed[..., 1, 1:], ours[..., 1, 1:], atol=1e-15)
    assert np.abs(printed[..., 1, 1] - ours[..., 1, 1]).max() > 1e-2
    eta_dot, _ = kin.gimbal_rates(omega, eta, eps)
    np.testing.assert_allclose(printed[..., 1, 0] - ours[..., 1, 0], np.sin(eps) * eta_dot,
                               atol=1e-15)
    level = lin.patent_eq6_matrix(omega, eta, 0.0)
    np.testing.assert_allclose(level, lin.los_rate_matrix(omega, eta, 0.0), atol=1e-15)


def test_patent_eq5_against_the_first_order_exact_rate():
    """Eq. (5), rows x and z: A w_b equals the first-order change of the exact camera rate,
    except the dpx terms of the z row (missing -dpx sin(eps) eta')."""
    omega, eta, eps = _random_state()
    delta_g = np.array([0.3, -0.2, 0.4]) * 1e-4
    for delta_p in (np.array([0.0, 0.0, -0.5e-4]), np.array([0.6e-4, 0.0, -0.5e-4])):
        exact = _los_rate_xz(omega, eta, eps, delta_g, delta_p)
        A = lin.patent_eq5_matrix(eta, eps, delta_g, delta_p)
        patent = (A @ omega[..., None])[..., [0, 2], 0]
        np.testing.assert_allclose(patent[:, 0], exact[:, 0], atol=1e-8)  # O(delta^2)
        eta_dot, _ = kin.gimbal_rates(omega, eta, eps)
        missing = -delta_p[0] * np.sin(eps) * eta_dot
        np.testing.assert_allclose(patent[:, 1] + missing, exact[:, 1], atol=1e-8)
    assert np.abs(missing).max() > 1e-6  # the difference is visible at this scale


def test_drift_model_matches_finite_differences_of_the_exact_simulator():
    """Image drift per unit parameter vs central differences of noise-free simulations.

    Tolerance: trapezoidal integration at 100 Hz of rocking up to 0.4 Hz has relative error
    about (2 pi 0.4 / 100)^2 / 12 = 5e-5; first-order terms about h = 1e-6 rad are exact.
    """
    run = sim.simulate(ROCK, SETUP, 0.0, 0.0)
    M = lin.drift_matrix(run.t, run.gyro, run.eta, run.eps, SETUP.camera)
    cases = [((0, 0, 0), (1, 0, 0), 0, 1e-6), ((1, 0, 0), (0, 0, 0), 1, 1e-6),
             ((0, 1, 0), (0, 0, 0), 2, 1e-6), ((0, 0, 0), (0, 0, 1), 3, 1e-6)]
    for dg, dp, j, h in cases:
        plus = sim.simulate(ROCK, SETUP, h * np.array(dg), h * np.array(dp))
        minus = sim.simulate(ROCK, SETUP, -h * np.array(dg), -h * np.array(dp))
        fd = (plus.los_px_true - minus.los_px_true) / (2 * h)
        assert np.abs(fd - M[..., j]).max() < 2e-4 * np.abs(fd).max()
    for j, e in enumerate(np.eye(3)):
        h = 1e-8
        fd = (sim.simulate(ROCK, SETUP, 0.0, 0.0, h * e).los_px_true
              - sim.simulate(ROCK, SETUP, 0.0, 0.0, -h * e).los_px_true) / (2 * h)
        assert np.abs(fd - M[..., 4 + j]).max() < 2e-4 * np.abs(fd).max()


def test_printed_h21_biases_the_single_pass_estimate():
    """The documented difference matters: one least-squares pass on noise-free exact data with
    the printed H (stray eps dropped) misses dpx by tens of percent; with the derived H the
    single pass is off only by the second-order terms (a few percent for 0.5 deg angles)."""
    delta_g, delta_p = np.array([0.5, -0.3, 0.7]) * D, np.array([0.4, 0.0, -0.6]) * D
    truth = np.array([delta_p[0], delta_g[0], delta_g[1], delta_p[2] - delta_g[2]])
    setup = sim.Setup(duration=20.0, rate=50.0, aim_azimuth=20 * D, aim_pitch=10 * D)
    run = sim.simulate(ROCK, setup, delta_g, delta_p)
    errors = {}
    for name, model in (("derived", None),
                        ("patent", lambda w, a, e: lin.patent_eq6_matrix(w, a, e,
                                                                        as_printed=False))):
        M = lin.drift_matrix(run.t, run.gyro, run.eta, run.eps, setup.camera, rate_matrix=model)
        A = np.concatenate([M, np.broadcast_to(np.eye(2), (run.t.size, 2, 2))], -1)
        x = np.linalg.lstsq(A.reshape(-1, 9), run.los_px_true.ravel(), rcond=None)[0]
        errors[name] = np.abs(x[:4] - truth) / np.abs(truth)
    assert errors["derived"].max() < 0.05
    assert errors["patent"][0] > 0.2


# --- observability ---------------------------------------------------------------------------


def _observe(amplitude_deg, aim_deg=(20.0, 10.0)):
    rock = kin.Rocking(np.radians(amplitude_deg), [0.25, 0.4, 0.32], [0.0, 1.0, 2.0])
    setup = sim.Setup(duration=20.0, rate=50.0, aim_azimuth=np.radians(aim_deg[0]),
                     aim_pitch=np.radians(aim_deg[1]))
    return lin.observability(sim.simulate(rock, setup, 0.0, 0.0), setup.camera, 0.1)


def test_three_axis_rocking_sees_four_combinations_not_five_angles():
    obs = _observe([5.0, 5.0, 5.0])
    assert obs.rank == 4 and obs.raw_rank == 4
    np.testing.assert_allclose(obs.raw_null_space, [[0, 1, 0, 0, 1] / np.sqrt(2)], atol=1e-9)
    assert np.all(np.isfinite(obs.sigma))


def test_single_axis_profiles_leave_combinations_unseen():
    """From the rate model: yaw alone never sees dpx (its column has no w_z); roll alone at a
    level LOS sees only dgy = 0 and delta_z, dgx - dpx; pitch alone misses dgx."""
    yaw = _observe([5.0, 0.0, 0.0])
    assert yaw.rank < 4 and np.isinf(yaw.sigma[0])
    roll_level = _observe([0.0, 0.0, 5.0], aim_deg=(0.0, 0.0))
    assert roll_level.rank == 2 and np.isinf(roll_level.sigma[2])
    assert np.isfinite(roll_level.sigma[3])
    pitch = _observe([0.0, 5.0, 0.0])
    assert pitch.rank < 4 and np.isinf(pitch.sigma[1])
