"""Self-checks of the independent seed 001 simulator (stabilization_recording.py), written by its
author with it."""
import json
import math

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from . import stabilization_recording as sb

QUIET = dict(delta_g=(0, 0, 0), delta_p=(0, 0, 0), gyro_bias=(0, 0, 0), gyro_noise_density=0.0, image_noise=0.0)


def rate_fd(dcm_of_t, t, h=1e-5):
    """Angular rate [rad/s] of a passive DCM C(t) in its own axes: C_dot = -[w x] C."""
    m = dcm_of_t(t + h) @ dcm_of_t(t - h).T
    return -Rotation.from_matrix(m).as_rotvec() / (2 * h)


def test_no_errors_target_stays_put():
    """Perfect IMU and camera: eq. (4) holds the LOS exactly, the target stays at the centre."""
    cols, truth = sb.simulate(duration=30.0, rng=np.random.default_rng(0), **QUIET)
    assert np.max(np.abs(cols["los_x_px"])) < 1e-8  # observed ~5e-11 px, i.e. ~5e-15 rad
    assert np.max(np.abs(cols["los_z_px"])) < 1e-8
    assert np.ptp(cols["eta_rad"]) > 0.05  # the gimbal really moved
    # gimbal angles equal the geometric pointing at the fixed target, computed in closed form
    l_b = sb.carrier_dcm(cols["t_s"], *[truth["rocking"][k] for k in ("amp_rad", "freq_hz", "phase_rad")]) \
        @ np.array(truth["camera"]["target_dir_enu"])
    eta_geo = np.arctan2(-l_b[:, 0], l_b[:, 1])
    eps_geo = np.arcsin(l_b[:, 2])
    assert np.max(np.abs(eta_geo - cols["eta_rad"])) < 1e-10
    assert np.max(np.abs(eps_geo - cols["eps_rad"])) < 1e-10


def test_rotations_against_scipy():
    a, b, c = 0.3, -0.7, 1.1
    for f, ax in ((sb.rot_x, "x"), (sb.rot_y, "y"), (sb.rot_z, "z")):
        assert np.allclose(f(a), Rotation.from_euler(ax, a).as_matrix().T, atol=1e-15)
    # small-angle forms printed in the patent
    d = 1e-6
    assert np.allclose(sb.rot_z(d), [[1, d, 0], [-d, 1, 0], [0, 0, 1]], atol=1e-12)
    assert np.allclose(sb.rot_x(d), [[1, 0, 0], [0, 1, d], [0, -d, 1]], atol=1e-12)
    assert np.allclose(sb.rot_y(d), [[1, 0, -d], [0, 1, 0], [d, 0, 1]], atol=1e-12)
    # eq. (1) order z, then x, then y (intrinsic)
    assert np.allclose(sb.imu_dcm((a, b, c)), Rotation.from_euler("ZXY", [c, a, b]).as_matrix().T)
    # carrier: yaw z, pitch x, roll y
    amp, fr, ph = (0.4, 0.3, 0.2), (0.25, 0.4, 0.32), (0.1, 0.2, 0.3)
    ang, _ = sb.carrier_euler(1.7, amp, fr, ph)
    assert np.allclose(sb.carrier_dcm(1.7, amp, fr, ph), Rotation.from_euler("ZXY", ang).as_matrix().T)
    # FORMAT.md signs: eta > 0 turns the LOS left (-x), eps > 0 up (+z)
    los_b = sb.camera_dcm(0.1, 0.0, (0, 0, 0)).T @ [0, 1, 0]
    assert los_b[0] < 0
    los_b = sb.camera_dcm(0.0, 0.1, (0, 0, 0)).T @ [0, 1, 0]
    assert los_b[2] > 0


def test_carrier_rate_vs_finite_difference():
    kin = ((0.3, 0.2, 0.25), (0.25, 0.4, 0.32), (0.1, 0.5, 0.9), (0.01, -0.02, 0.03))
    for t in (0.0, 0.77, 3.1, 11.4):
        w = sb.carrier_rate(t, *kin)
        assert np.allclose(w, rate_fd(lambda s: sb.carrier_dcm(s, *kin), t), atol=1e-8)


@pytest.mark.slow  # 20 000 samples through the pure-Python loop (about 4 s)
def test_gyro_noise_sigma():
    """Carrier at rest: gyro = bias + noise with per-sample sigma = density*sqrt(rate)."""
    dens, rate = 1e-4, 200.0
    cols, truth = sb.simulate(duration=100.0, rate=rate, delta_g=(0.01, 0.02, 0.03), gyro_bias=(1e-3, 0, -1e-3),
                              gyro_noise_density=dens, rock_amp=(0, 0, 0), rng=np.random.default_rng(3))
    g = np.column_stack([cols["gyro_x"], cols["gyro_y"], cols["gyro_z"]]) - [1e-3, 0, -1e-3]
    n = len(g)
    s_expect = dens * math.sqrt(rate)
    assert math.isclose(truth["gyro_noise_sigma_per_sample_rad_s"], s_expect)
    s = g.std(axis=0)
    assert np.all(np.abs(s / s_expect - 1) < 5 / math.sqrt(2 * n))  # 5 sigma of the std estimate
    assert np.all(np.abs(g.mean(axis=0)) < 5 * s_expect / math.sqrt(n))


def test_bias_exact_azimuth_walk():
    """Carrier at rest, z-bias b: eq. (4) gives eta_dot = -b exactly, so x = -k tan(b t), z = 0."""
    b = 2e-4
    cols, truth = sb.simulate(duration=10.0, delta_g=(0, 0, 0), delta_p=(0, 0, 0), gyro_bias=(0, 0, b),
                              gyro_noise_density=0.0, image_noise=0.0, rock_amp=(0, 0, 0), eps0=0.0,
                              rng=np.random.default_rng(1))
    k = truth["camera"]["k_px_per_rad"]
    t = cols["t_s"]
    assert np.allclose(cols["eta_rad"], math.radians(20) - b * t, atol=1e-12)
    assert np.allclose(cols["los_x_px"], -k * np.tan(b * t), atol=1e-8)
    assert np.allclose(cols["los_z_px"], 0, atol=1e-8)


def test_first_order_yaw_with_imu_tilt():
    """Hand-derived first-order case.

    Carrier yaws at a constant rate W [rad/s] (w_b = [0,0,W]); the IMU is tilted by dgx = d about x,
    so it measures w_bm = [0, sin(d) W, cos(d) W]: the loop believes in a roll d*W about the carrier's
    y axis.  Because the gimbal cancels the *measured* rate, the camera's true inertial rate is, to first
    order, C_pb (w_b - w_bm) = C_pb [0, -d W, 0], whose pitch component is -sin(eta) d W (patent
    H_1,2 = -sin(eta) w_bz) and whose azimuth component is sin(eps) cos(eta) d W (H_2,2), i.e. 0 at eps = 0.
    With eps0 = 0 and eta = eta0 - W t the camera pitches by theta_e(T) = int -sin(eta0 - W t) d W dt
    = -d (cos(eta0 - W T) - cos(eta0)), and a pitch theta_e moves the target image by z = -k tan(theta_e).
    For eta0 = 90 deg: z(T) = k d sin(W T)  (initial drift rate k d W, upward for d, W > 0), x(T) = 0.
    The neglected terms are O(k d^2) ~ 0.01 px here.
    """
    d, w = 1e-3, 0.5
    cols, truth = sb.simulate(duration=4.0, delta_g=(d, 0, 0), delta_p=(0, 0, 0), gyro_bias=(0, 0, 0),
                              gyro_noise_density=0.0, image_noise=0.0, rock_amp=(0, 0, 0),
                              rock_drift=(w, 0, 0), eta0=math.pi / 2, eps0=0.0, rng=np.random.default_rng(2))
    k, t = truth["camera"]["k_px_per_rad"], cols["t_s"]
    z_hand = k * d * np.sin(w * t)
    assert np.max(np.abs(z_hand)) > 10.0
    assert np.max(np.abs(cols["los_z_px"] - z_hand)) < 0.05
    assert np.max(np.abs(cols["los_x_px"])) < 0.05


def test_first_order_model():
    """Exact camera rate (finite difference of the simulator's DCMs) vs my linearisation of eq. (2),(4).

    Delta w_x = H_1 . [dpx, dgx, dgy, dz] as printed; Delta w_z as printed except
    H_2,1 = sec(eps)(sin(eta) w_bx - cos(eta) w_by) (printed: cos eps sin eta w_bx - cos eps cos eta w_by
    - sin eps w_bz = my H_2,1 + sin(eps)*eta_dot: it drops eta_dot's share of the roll rate)."""
    rng = np.random.default_rng(7)
    kin = ((0.3, 0.2, 0.25), (0.25, 0.4, 0.32), (0.1, 0.5, 0.9))
    for _ in range(5):
        dg, dp = rng.normal(0, 1e-4, 3), rng.normal(0, 1e-4, 3)
        eta, eps, t = rng.uniform(-1, 1), rng.uniform(-0.8, 0.8), rng.uniform(0, 10)
        wb = sb.carrier_rate(t, *kin)
        eta_dot, eps_dot = sb.gimbal_rates(eta, eps, sb.imu_dcm(dg) @ wb)

        def c_cn(s):
            return sb.camera_dcm(eta + (s - t) * eta_dot, eps + (s - t) * eps_dot, dp) @ sb.carrier_dcm(s, *kin)
        wc = rate_fd(c_cn, t, h=1e-4)
        se, ce, sh, ch = math.sin(eps), math.cos(eps), math.sin(eta), math.cos(eta)
        wx, wy, wz = wb
        X = np.array([dp[0], dg[0], dg[1], dp[2] - dg[2]])
        h1 = np.array([0, -sh * wz, ch * wz, ch * wy - sh * wx])
        h2 = np.array([(sh * wx - ch * wy) / ce, se * ch * wz + ce * wy, -ce * wx + se * sh * wz,
                       se * ch * wx + se * sh * wy])
        assert abs(wc[0] - h1 @ X) < 1e-7
        assert abs(wc[2] - h2 @ X) < 1e-7
        h21_printed = ce * sh * wx - ce * ch * wy - se * wz
        assert math.isclose(h21_printed - h2[0], se * sb.gimbal_rates(eta, eps, wb)[0], rel_tol=1e-9)


def test_linear_model_recovers_truth():
    """Whole chain: from the simulated image drift, least squares on eq. (6) (with my H_2,1) recovers X.

    Image rate of a target at (x, z)/k [rad] from the centre: x' = w_z - w_y z, z' = -w_x + w_y x, with the
    camera's roll rate w_y = sec(eps)(-sin(eta) w_bx + cos(eta) w_by); so Delta w_x = -z' + w_y x and
    Delta w_z = x' + w_y z.  Small angles (a few arc-min) keep second-order terms negligible."""
    a = sb.ARCMIN
    cols, truth = sb.simulate(duration=30.0, delta_g=(3 * a, -1.8 * a, 4.8 * a), delta_p=(-2.4 * a, 1.2 * a, 3.6 * a),
                              eps0=math.radians(40), gyro_bias=(0, 0, 0), gyro_noise_density=0.0, image_noise=0.0,
                              rng=np.random.default_rng(4))
    k, dt = truth["camera"]["k_px_per_rad"], cols["t_s"][1]
    x, z = cols["los_x_px"] / k, cols["los_z_px"] / k
    se, ce = np.sin(cols["eps_rad"]), np.cos(cols["eps_rad"])
    sh, ch = np.sin(cols["eta_rad"]), np.cos(cols["eta_rad"])
    wx, wy, wz = cols["gyro_x"], cols["gyro_y"], cols["gyro_z"]
    roll = (-sh * wx + ch * wy) / ce
    y = np.concatenate([-np.gradient(z, dt) + roll * x, np.gradient(x, dt) + roll * z])
    h1 = np.column_stack([0 * wx, -sh * wz, ch * wz, ch * wy - sh * wx])
    h2 = np.column_stack([-roll, se * ch * wz + ce * wy, -ce * wx + se * sh * wz, se * ch * wx + se * sh * wy])
    X = np.linalg.lstsq(np.vstack([h1, h2]), y, rcond=None)[0]
    assert np.allclose(X, list(truth["patent_X_rad"].values()), atol=0.02 * a)


def test_csv_and_cli(tmp_path):
    out = tmp_path / "run.csv"
    sb.main([str(out), "--seed", "5", "--duration", "2"])
    lines = out.read_text().splitlines()
    assert lines[0] == "t_s,gyro_x,gyro_y,gyro_z,eta_rad,eps_rad,los_x_px,los_z_px"
    data = np.loadtxt(out, delimiter=",", skiprows=1)
    assert data.shape == (201, 8) and np.all(np.diff(data[:, 0]) > 0)
    truth = json.loads((tmp_path / "run.truth.json").read_text())
    assert truth["seed"] == 5 and math.isclose(truth["delta_g_rad"]["x"], 30 * sb.ARCMIN)
