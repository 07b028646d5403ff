"""Tests of stabilization_second.py against things it does not compute itself:
scipy's Rotation, finite differences, hand-derived closed forms and exact geometric identities.

Kept as its author wrote it but for two changes made when it joined the repository's tests: the
module is imported relatively (``from . import``), and the noise test, four runs of 100 s at
100 Hz through the ODE solver, is marked slow."""
import json
import numpy as np
import pytest
from scipy.spatial.transform import Rotation as R

from . import stabilization_second as S

DEG = np.pi / 180
QUIET = dict(gyro_noise_rad_s=0.0, encoder_noise_rad=0.0, image_noise_px=0.0)
SHORT = dict(duration_s=20.0, rate_hz=50.0, **QUIET)
DG = (0.3 * DEG, -0.4 * DEG, 0.5 * DEG)
DP = (0.6 * DEG, 0.2 * DEG, -0.35 * DEG)


def passive(axis, a):
    return R.from_rotvec(a * np.eye(3)["xyz".index(axis)]).as_matrix().T


def C_bn_scipy(psi, theta, phi):          # intrinsic z-x-y active rotation, transposed
    return R.from_euler("ZXY", [psi, theta, phi]).as_matrix().T


# ---------------------------------------------------------------- conventions ---------------
def test_rotations_match_scipy_and_patent_small_angle_matrices():
    for a in (0.1, -0.7, 2.0):
        assert np.allclose(S.rot_x(a), passive("x", a), atol=1e-15)
        assert np.allclose(S.rot_y(a), passive("y", a), atol=1e-15)
        assert np.allclose(S.rot_z(a), passive("z", a), atol=1e-15)
    d = 1e-4   # printed matrices of eq. (1), to first order
    assert np.allclose(S.rot_y(d), [[1, 0, -d], [0, 1, 0], [d, 0, 1]], atol=1e-8)
    assert np.allclose(S.rot_x(d), [[1, 0, 0], [0, 1, d], [0, -d, 1]], atol=1e-8)
    assert np.allclose(S.rot_z(d), [[1, d, 0], [-d, 1, 0], [0, 0, 1]], atol=1e-8)
    g = (0.2, -0.3, 0.4)
    assert np.allclose(S.imu_matrix(g), R.from_euler("ZXY", [g[2], g[0], g[1]]).as_matrix().T)


def test_brief_sign_conventions_for_gimbal_angles():
    los = lambda eta, eps: S.camera_matrix(eta, eps, (0, 0, 0)).T @ [0, 1, 0]
    assert np.allclose(los(0, 0), [0, 1, 0])            # forward at eta = eps = 0
    assert los(0.3, 0)[0] < 0                            # eta > 0: to the left
    assert los(0, 0.3)[2] > 0                            # eps > 0: up


def test_carrier_rate_against_finite_difference_of_attitude():
    amp, freq, ph = (0.3, 0.4, 0.5), (0.2, 0.35, 0.27), (0.1, -0.5, 1.0)
    h = 1e-5
    for t in (0.3, 1.7, 4.2):
        ang, rate = S.carrier_euler(t, amp, freq, ph)
        w = S.carrier_rate(ang, rate)[:, 0]
        Cp = C_bn_scipy(*S.carrier_euler(t + h, amp, freq, ph)[0][:, 0])
        Cm = C_bn_scipy(*S.carrier_euler(t - h, amp, freq, ph)[0][:, 0])
        C = C_bn_scipy(*ang[:, 0])
        Om = -(Cp - Cm) / (2 * h) @ C.T                 # dC_bn/dt = -[w x] C_bn
        assert np.allclose([Om[2, 1], Om[0, 2], Om[1, 0]], w, atol=1e-8)
        assert np.allclose(S.carrier_attitude(*ang[:, 0]), C, atol=1e-14)


def test_gimbal_law_hand_cases():
    w = np.array([0.1, -0.2, 0.3])
    assert np.allclose(S.gimbal_rates(0.0, 0.0, w), (-0.3, -0.1))     # eps' = -wx, eta' = -wz
    assert np.allclose(S.gimbal_rates(np.pi / 2, 0.0, w), (-0.3, 0.2))  # eps' = -wy
    # eps = 45 deg, eta = 0: eta' = sec(eps)(sin(eps) wy - cos(eps) wz) = wy - wz
    assert np.allclose(S.gimbal_rates(0.0, np.pi / 4, w), (-0.2 - 0.3, -0.1))


def test_perfect_mounting_cancels_los_pitch_and_yaw_rate():
    rng = np.random.default_rng(3)
    for _ in range(20):
        eta, eps = rng.uniform(-1.2, 1.2, 2)
        wc = S.camera_rate(eta, eps, rng.normal(size=3), (0, 0, 0), (0, 0, 0))
        assert abs(wc[0]) < 1e-14 and abs(wc[2]) < 1e-14


# -------------------------------------------------------------------- whole runs ------------
def test_zero_angles_zero_noise_image_is_still_and_gyro_exact():
    d, tr = S.simulate(**SHORT)
    assert np.nanmax(np.abs(d["los_px"])) < 1e-5
    assert np.allclose(d["gyro"], d["omega_b"], atol=1e-15)
    assert tr["frames_out_of_view"] == 0


def test_gimbal_and_image_against_geometric_construction():
    """Eq. (4) driven by w_bm keeps the IMU-based 'virtual' LOS fixed in space, so the gimbal angles
    are the azimuth/elevation of that fixed vector seen in the IMU frame: no ODE needed."""
    kw = dict(SHORT, eta0_rad=-25 * DEG, eps0_rad=20 * DEG)
    d, tr = S.simulate(DG, DP, **kw)
    G = R.from_euler("ZXY", [DG[2], DG[0], DG[1]]).as_matrix().T
    ang = d["carrier_euler"]
    Vg0 = R.from_euler("ZX", [kw["eta0_rad"], kw["eps0_rad"]]).as_matrix()   # gimbal, active
    v_n = C_bn_scipy(*ang[0]).T @ G.T @ Vg0 @ [0, 1, 0]
    fpx = 0.5 * 1024 / np.tan(2.5 * DEG)
    cam = lambda eta, eps: (R.from_euler("ZXY", [eta + DP[2], eps + DP[0], DP[1]]).as_matrix().T)
    u_n = (cam(kw["eta0_rad"], kw["eps0_rad"]) @ C_bn_scipy(*ang[0])).T @ [0, 1, 0]
    for k in range(0, len(d["t_s"]), 37):
        vg = G @ C_bn_scipy(*ang[k]) @ v_n
        eps = np.arcsin(vg[2])
        eta = np.arctan2(-vg[0], vg[1])
        assert abs(eps - d["eps_rad"][k]) < 1e-9 and abs(eta - d["eta_rad"][k]) < 1e-9
        uc = cam(eta, eps) @ C_bn_scipy(*ang[k]) @ u_n
        assert np.allclose(fpx * uc[[0, 2]] / uc[1], d["los_px"][k], atol=1e-4)
    assert np.nanmax(np.abs(d["los_px"])) > 5.0         # the angles do make the image drift


def test_roll_only_closed_form_for_dpz():
    """Carrier rolls about y only, eta0 = eps0 = 0, perfect IMU: eq. (4) keeps eta = eps = 0 and the
    camera is fixed to the carrier. Hand derivation: with s, c = sin, cos(dpz),
    target in camera = (s c (1 - cos phi), s^2 cos phi + c^2, -s sin phi)."""
    dpz = 0.8 * DEG
    d, _ = S.simulate((0, 0, 0), (0, 0, dpz), eta0_rad=0, eps0_rad=0, duration_s=10, rate_hz=20,
                      rock_amp_rad=(0, 0, 10 * DEG), **QUIET)
    assert np.allclose(d["eta_rad"], 0, atol=1e-12) and np.allclose(d["eps_rad"], 0, atol=1e-12)
    phi = d["carrier_euler"][:, 2]
    s, c = np.sin(dpz), np.cos(dpz)
    X, Y, Z = s * c * (1 - np.cos(phi)), s * s * np.cos(phi) + c * c, -s * np.sin(phi)
    f = S.focal_px(5 * DEG, 1024)
    assert np.allclose(d["los_px"][:, 0], f * X / Y, atol=1e-8)
    assert np.allclose(d["los_px"][:, 1], f * Z / Y, atol=1e-8)
    assert d["los_px"][np.argmax(phi), 1] < 0            # sign: z drift = -f dpz phi


def test_equal_azimuth_angles_of_imu_and_camera_cancel_exactly():
    """dgz = dpz: the IMU and the gimbal base share one yaw, so the drift vanishes (patent: only
    dz = dpz - dgz matters); likewise a lone camera roll dpy leaves a centred target at the centre."""
    d, _ = S.simulate((0, 0, 0.7 * DEG), (0, 0, 0.7 * DEG), **SHORT)
    assert np.max(np.abs(d["los_px"])) < 1e-5
    d, _ = S.simulate((0, 0, 0), (0, 1.5 * DEG, 0), **SHORT)
    assert np.max(np.abs(d["los_px"])) < 1e-5


def test_camera_roll_rotates_the_drift():
    beta = 3 * DEG
    d0, _ = S.simulate(DG, (DP[0], 0.0, DP[2]), **SHORT)
    d1, _ = S.simulate(DG, (DP[0], beta, DP[2]), **SHORT)
    c, s = np.cos(beta), np.sin(beta)
    rot = d0["los_px"] @ np.array([[c, -s], [s, c]]).T
    assert np.allclose(d1["los_px"], rot, atol=1e-5)


def test_initial_image_rate_equals_camera_rate():
    """At t = 0 the target is at the centre; its image moves at f (w_cz, -w_cx)."""
    kw = dict(duration_s=0.02, rate_hz=2000.0, **QUIET)
    d, tr = S.simulate(DG, DP, **kw)
    wc = S.camera_rate(d["eta_rad"][0], d["eps_rad"][0], d["omega_b"][0], DG, DP)
    f = tr["camera"]["focal_px"]
    t = d["t_s"]
    for j, expect in ((0, f * wc[2]), (1, -f * wc[0])):
        slope = np.polyfit(t, d["los_px"][:, j], 4)[-2]
        assert slope == pytest.approx(expect, rel=1e-6, abs=1e-8)


def test_small_angles_agree_with_printed_eq5_rows_except_dpx_column():
    """First order in the angles: camera pitch/yaw rates vs printed A (rows 1, 3), and the dpx column
    of row 3 vs my derivation  -dpx(-sin(eta) wx + cos(eta) wy)/cos(eps)."""
    rng = np.random.default_rng(5)
    k = 1e-7
    for _ in range(10):
        eta, eps = rng.uniform(-1, 1, 2)
        w = rng.normal(size=3)
        gx, gy, gz, px, pz = rng.normal(size=5) * k
        se, ce, sn, cn = np.sin(eps), np.cos(eps), np.sin(eta), np.cos(eta)
        A1 = [(gz - pz) * sn, -(gz - pz) * cn, gy * cn - gx * sn]
        A3 = [(pz - gz) * se * cn - gy * ce, (pz - gz) * se * sn + gx * ce, gy * se * sn + gx * se * cn]
        wc = S.camera_rate(eta, eps, w, (gx, gy, gz), (px, 0.0, pz))
        assert wc[0] == pytest.approx(np.dot(A1, w), abs=1e-12)
        assert wc[2] == pytest.approx(np.dot(A3, w) - px * (-sn * w[0] + cn * w[1]) / ce, abs=1e-12)


def test_drift_is_linear_in_small_angles():
    d1, _ = S.simulate(DG, DP, **SHORT)
    d2, _ = S.simulate(tuple(np.array(DG) / 2), tuple(np.array(DP) / 2), **SHORT)
    err = np.max(np.abs(d1["los_px"] - 2 * d2["los_px"]))
    assert err < 0.02 * np.max(np.abs(d1["los_px"]))


def test_zoh_loop_converges_to_continuous():
    kw = dict(duration_s=5.0, **QUIET)
    e = []
    for rate in (100.0, 1000.0):
        dc, _ = S.simulate(DG, DP, rate_hz=rate, **kw)
        dz, _ = S.simulate(DG, DP, rate_hz=rate, loop="zoh", **kw)
        e.append(np.max(np.abs(dz["los_px"] - dc["los_px"])))
    assert e[1] < e[0] / 8                                 # first-order in the sample interval


# ------------------------------------------------------------------ noise and files ---------
@pytest.mark.slow
def test_noise_seeded_and_with_requested_sigma():
    kw = dict(duration_s=100.0, rate_hz=100.0, gyro_noise_rad_s=1e-3, encoder_noise_rad=2e-4,
              image_noise_px=0.5)
    a, _ = S.simulate(DG, DP, seed=7, **kw)
    b, _ = S.simulate(DG, DP, seed=7, **kw)
    c, _ = S.simulate(DG, DP, seed=8, **kw)
    assert np.array_equal(a["los_px"], b["los_px"]) and not np.array_equal(a["gyro"], c["gyro"])
    assert np.std(a["gyro"] - a["true_gyro"]) == pytest.approx(1e-3, rel=0.03)
    assert np.std(a["eta_rad"] - a["true_eta"]) == pytest.approx(2e-4, rel=0.05)
    assert np.std(a["los_px"] - a["true_los_px"]) == pytest.approx(0.5, rel=0.03)
    assert np.allclose(a["true_los_px"], S.simulate(DG, DP, **kw, seed=9)[0]["true_los_px"])


def test_csv_and_truth_files(tmp_path):
    csv, js = tmp_path / "r.csv", tmp_path / "r.json"
    d, tr = S.simulate_recording(csv, js, DG, DP, duration_s=2.0, rate_hz=50.0, seed=4)
    lines = csv.read_text().splitlines()
    assert lines[0] == "t_s,gyro_x,gyro_y,gyro_z,eta_rad,eps_rad,los_x_px,los_z_px"
    arr = np.loadtxt(csv, delimiter=",", skiprows=1)
    assert arr.shape == (101, 8)
    assert np.allclose(np.diff(arr[:, 0]), 0.02) and np.all(np.diff(arr[:, 0]) > 0)
    assert np.allclose(arr[:, 1:4], d["gyro"]) and np.allclose(arr[:, 6:8], d["los_px"])
    t = json.loads(js.read_text())
    assert t["delta_g_rad"]["gy"] == pytest.approx(DG[1])
    assert t["delta_p_rad"]["pz"] == pytest.approx(DP[2])
    assert t["camera"]["pixels"] == 1024
