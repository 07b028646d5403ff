"""Seed 001 models against references the code did not compute: the patent's printed eq. (5)
transcribed here, hand values of the kinematics at right angles, and the Cramer-Rao bound by
inverting the whole Fisher matrix (the code projects the other columns out instead).
"""

import dataclasses

import numpy as np
import pytest

from montecarlo.seed001 import kinematics as kin
from montecarlo.seed001 import linear_model as lin
from montecarlo.seed001 import simulate as sim

D = np.pi / 180.0


def test_eq5_matrix_is_the_printed_one():
    """Seed 001, eq. (5), as printed (d = dgz - dpz; s_, c_ sine and cosine)::

        A = [[d s_eta, -d c_eta, dgy c_eta - dgx s_eta],
             [d c_eps c_eta + dpx s_eps s_eta - dgy s_eps,
              d c_eps s_eta - dpx s_eps c_eta + dgx s_eps,
              dpx c_eps - dgy c_eps s_eta - dgx c_eps c_eta],
             [-d s_eps c_eta + dpx c_eps s_eta - dgy c_eps,
              -d s_eps s_eta - dpx c_eps c_eta + dgx c_eps,
              -dpx s_eps + dgy s_eps s_eta + dgx s_eps c_eta]]
    """
    g = np.random.default_rng(5)
    for _ in range(5):
        eta, eps = g.uniform(-1.5, 1.5, 2)
        dgx, dgy, dgz, dpx, dpy, dpz = g.normal(size=6)
        se, ce, sa, ca = np.sin(eps), np.cos(eps), np.sin(eta), np.cos(eta)
        d = dgz - dpz
        printed = [[d * sa, -d * ca, dgy * ca - dgx * sa],
                   [d * ce * ca + dpx * se * sa - dgy * se,
                    d * ce * sa - dpx * se * ca + dgx * se,
                    dpx * ce - dgy * ce * sa - dgx * ce * ca],
                   [-d * se * ca + dpx * ce * sa - dgy * ce,
                    -d * se * sa - dpx * ce * ca + dgx * ce,
                    -dpx * se + dgy * se * sa + dgx * se * ca]]
        got = lin.patent_eq5_matrix(eta, eps, [dgx, dgy, dgz], [dpx, dpy, dpz])
        np.testing.assert_allclose(got, printed, rtol=1e-13, atol=1e-15)


def test_camera_rate_at_right_angles_by_hand():
    """No installation angles (the default). Passive turns: R_z(90 deg) v = [v_y, -v_x, v_z],
    R_x(90 deg) v = [v_x, v_z, -v_y]. eta = 90 deg, eps = 0: w_i = [w_y + eps', -w_x,
    w_z + eta']; eta = 0, eps = 90 deg: w_i = [w_x + eps', w_z + eta', -w_y]."""
    w, eta_dot, eps_dot = np.array([0.1, 0.2, 0.3]), 0.05, -0.07
    np.testing.assert_allclose(kin.camera_rate(w, np.pi / 2, 0.0, eta_dot, eps_dot),
                               [0.2 + eps_dot, -0.1, 0.3 + eta_dot], atol=1e-15)
    np.testing.assert_allclose(kin.camera_rate(w, 0.0, np.pi / 2, eta_dot, eps_dot),
                               [0.1 + eps_dot, 0.3 + eta_dot, -0.2], atol=1e-15)
    np.testing.assert_allclose(kin.camera_rate(w, np.pi / 2, 0.0, eta_dot, eps_dot,
                                               mount="inner-gimbal"),
                               [0.2 + eps_dot, -0.1, 0.3 + eta_dot], atol=1e-15)


def test_gimbal_rates_and_los_at_right_angles_by_hand():
    """Eq. (4) at eta = eps = 0: eps' = -w_x, eta' = -w_z; at eta = 90 deg: eps' = -w_y,
    eta' = -w_z; the LOS at (0, 0) is +y, at eta = 90 deg -x, at eps = 90 deg +z."""
    w = np.array([0.1, 0.2, 0.3])
    eta_dot, eps_dot = kin.gimbal_rates(w, 0.0, 0.0)
    assert (eta_dot, eps_dot) == pytest.approx((-0.3, -0.1), abs=1e-15)
    eta_dot, eps_dot = kin.gimbal_rates(w, np.pi / 2, 0.0)
    assert (eta_dot, eps_dot) == pytest.approx((-0.3, -0.2), abs=1e-15)
    np.testing.assert_allclose(kin.los_direction(0.0, 0.0), [0, 1, 0], atol=1e-15)
    np.testing.assert_allclose(kin.los_direction(np.pi / 2, 0.0), [-1, 0, 0], atol=1e-15)
    np.testing.assert_allclose(kin.los_direction(0.3, np.pi / 2), [0, 0, 1], atol=1e-15)


def test_default_mount_and_sampling_names():
    assert lin.model_names() == lin.OBSERVABLE_NAMES == (
        "delta_px", "delta_gx", "delta_gy", "delta_z")
    assert lin.model_names("inner-gimbal") == (*lin.OBSERVABLE_NAMES, "delta_gz")
    with pytest.raises(ValueError, match="mount must be one of patent, inner-gimbal, not 'x'"):
        kin.check_mount("x")
    with pytest.raises(ValueError, match="gyro sampling must be one of point, interval-mean, "
                                         "not 'x'"):
        sim.check_sampling("x")


def test_encoder_angles_are_taken_within_half_a_turn_of_zero_by_default():
    """An LOS at eta = -170 deg: the default ``eta_near = 0`` gives an encoder azimuth in
    (-180, 180] deg, near -170 deg (the installation angles are small)."""
    angles, dgz = np.array([0.01, 0.0, 0.0, 0.02]), 0.005
    eta, eps = sim.encoder_angles(np.array([-170 * D]), np.array([10 * D]), angles, dgz)
    assert -np.pi < eta[0] <= np.pi and abs(eta[0] + 170 * D) < 3 * D
    back = sim.pointing_angles(eta, eps, angles, dgz)
    np.testing.assert_allclose([back[0][0], back[1][0]], [-170 * D, 10 * D], atol=1e-12)


def _fisher_sigma(record, camera, image_noise, nuisance, mount):
    """sqrt of the diagonal of the inverse Fisher matrix of [X, bias, image offset]."""
    M = lin.drift_matrix(record.t, record.gyro, record.eta, record.eps, camera, mount=mount)
    n_x = len(lin.model_names(mount))
    offset = np.broadcast_to(np.eye(2), (record.t.size, 2, 2))
    A = np.concatenate([M, offset], -1) if nuisance else M[..., :n_x]
    A = A.reshape(-1, A.shape[-1]) / image_noise
    return np.sqrt(np.diag(np.linalg.inv(A.T @ A)))[:n_x]


@pytest.mark.parametrize("mount", kin.MOUNTS)
def test_observability_sigma_is_the_cramer_rao_bound(mount):
    rock = kin.Rocking(np.full(3, 5 * D), [0.25, 0.4, 0.32], [0.0, 1.0, 2.0])
    setup = sim.Setup(duration=10.0, rate=25.0, aim_azimuth=20 * D, aim_pitch=10 * D,
                      mount=mount)
    run = sim.simulate(rock, setup, 0.0, 0.0)
    for noise in (0.1, 0.4):
        obs = lin.observability(run, setup.camera, noise, mount=mount)
        np.testing.assert_allclose(obs.sigma, _fisher_sigma(run, setup.camera, noise, True,
                                                             mount), rtol=1e-6)
        known = lin.observability(run, setup.camera, noise, nuisance=False, mount=mount)
        np.testing.assert_allclose(known.sigma, _fisher_sigma(run, setup.camera, noise, False,
                                                              mount), rtol=1e-6)
        assert np.all(known.sigma < obs.sigma)  # estimating the nuisance costs precision
    assert obs.rank == len(lin.model_names(mount))
    if mount == "patent":  # equal changes of dpz and dgz, the largest component made positive
        np.testing.assert_allclose(obs.raw_null_space, [[0, 1, 0, 0, 1] / np.sqrt(2)],
                                   atol=1e-9)


def test_drift_rows_take_the_batch_from_whichever_input_has_it():
    """A batch of two in the gyro output only, in eta only, or in eps only: the compiled rows
    broadcast the others and equal the numpy path's, run by run."""
    rock = kin.Rocking(np.full(3, 5 * D), [0.25, 0.4, 0.32], [0.0, 1.0, 2.0])
    setup = sim.Setup(duration=2.0, rate=25.0, aim_azimuth=20 * D, aim_pitch=10 * D)
    run = sim.simulate(rock, setup, [0.01, -0.02, 0.0], [0.0, 0.01, 0.02])
    inputs = {"gyro": run.gyro, "eta": run.eta, "eps": run.eps}
    for name in inputs:
        batched = dict(inputs, **{name: np.stack([inputs[name], 1.01 * inputs[name]])})
        got = lin.drift_matrix(run.t, batched["gyro"], batched["eta"], batched["eps"],
                               setup.camera)
        ref = lin.drift_matrix(run.t, batched["gyro"], batched["eta"], batched["eps"],
                               setup.camera, reference=True)
        assert got.shape == (2, run.t.size, 2, 7)
        np.testing.assert_allclose(got, ref, rtol=1e-9, atol=1e-9 * np.abs(ref).max())


def test_imu_output_without_a_bias_by_default_is_eq1_of_the_body_rate():
    """Point rows: the IMU output at the sample times is ``C_b^g w_b`` (eq. (1)) of the
    rocking's closed-form body rate; the half-step samples lie between them."""
    rock = kin.Rocking(np.full(3, 5 * D), [0.25, 0.4, 0.32], [0.0, 1.0, 2.0])
    setup = sim.Setup(duration=1.0, rate=20.0)
    delta_g = np.array([0.5, -0.3, 0.7]) * D
    motion = sim.imu_motion(rock, setup, delta_g)
    t = setup.times
    np.testing.assert_allclose(motion.gyro, kin.measured_rate(rock.body_rate(t), delta_g),
                               rtol=0, atol=1e-15)
    assert motion.omega_m.shape == (2 * t.size - 1, 3)
    np.testing.assert_allclose(motion.omega_m[1::2],
                               kin.measured_rate(rock.body_rate(t[:-1] + 0.025), delta_g),
                               rtol=0, atol=1e-15)


def test_first_interval_mean_row_has_the_stated_noise():
    """Interval-mean rows: the first row's noise (an interval before the run) has the per-sample
    sd q sqrt(rate) like the others. 2000 runs x 3 axes: the sample sd is within 4 x its
    relative sd 1/sqrt(2 x 6000) = 0.9 % of q sqrt(rate)."""
    rock = kin.Rocking(np.full(3, 5 * D), [0.25, 0.4, 0.32], [0.0, 1.0, 2.0])
    q = np.radians(0.05) / 60.0
    setup = sim.Setup(duration=0.2, rate=50.0, gyro_noise=q, gyro_sampling="interval-mean",
                      image_noise=0.0)
    delta_g = np.zeros((2000, 3))
    run = sim.simulate(rock, setup, delta_g, 0.0, rng=3)
    quiet = sim.simulate(rock, dataclasses.replace(setup, gyro_noise=0.0), delta_g, 0.0)
    noise = (run.gyro - quiet.gyro)[:, 0, :]
    sd = float(np.sqrt(np.mean(noise**2)))
    assert abs(sd / (q * np.sqrt(setup.rate)) - 1.0) < 4.0 / np.sqrt(2.0 * noise.size)


def test_inner_gimbal_encoder_azimuth_starts_at_the_aim_beyond_half_a_turn():
    """Aimed at 200 deg, a compensated inner-gimbal camera's encoder azimuth starts near
    200 deg (the installation angles are a fraction of a degree), not at its -160 deg alias."""
    rock = kin.Rocking(np.full(3, 5 * D), [0.25, 0.4, 0.32], [0.0, 1.0, 2.0])
    setup = sim.Setup(duration=0.5, rate=20.0, aim_azimuth=200 * D, aim_pitch=10 * D,
                      mount="inner-gimbal", image_noise=0.0)
    compensation = sim.Compensation([0.005, 0.01, -0.01, 0.0], delta_gz=0.005,
                                    mount="inner-gimbal")
    run = sim.simulate(rock, setup, [0.01, -0.01, 0.005], [0.005, 0.01, -0.01],
                       compensation=compensation)
    assert abs(run.eta[0] - 200 * D) < 2 * D
