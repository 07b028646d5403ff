"""Tests of ground_second.py against things it does not compute itself: scipy's Rotation, a plain
pinhole written here, hand-derived single-axis cases, the paper's inverse equations (3), (7),
(11)-(14) re-implemented here, the paper's Table 1, and statistics of the drawn noise."""
import csv
import itertools
import json

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from tests.independent import ground_second as gs  # (import path adapted to the repository)

# the author's json.load(open(...)) leaves files to the garbage collector (kept as written)
pytestmark = [pytest.mark.filterwarnings("ignore::ResourceWarning"),
              pytest.mark.filterwarnings("ignore::pytest.PytestUnraisableExceptionWarning")]

FOV, PIX = (90.0, 90.0), (512, 512)
F = 256.0                                        # (512/2)/tan(45 deg), by hand


def pinhole_scipy(points_b, psi, theta, gamma, fov=FOV, pix=PIX):
    """Independent pinhole: r^a = R^T r^b with R = from_euler('ZXY'); px = f x/y, pz = f z/y."""
    R = Rotation.from_euler("ZXY", [psi, theta, gamma], degrees=True).as_matrix()
    r_a = np.atleast_2d(points_b) @ R                     # rows: (R^T r)^T
    fx = pix[0] / 2 / np.tan(np.radians(fov[0]) / 2)
    fz = pix[1] / 2 / np.tan(np.radians(fov[1]) / 2)
    return fx * r_a[:, 0] / r_a[:, 1], fz * r_a[:, 2] / r_a[:, 1]


def read_csv(path):
    with open(path, encoding="utf-8") as fh:
        rows = list(csv.reader(fh))
    return rows[0], rows[1:]


def sim(tmp_path, **kw):
    kw.setdefault("pixel_sigma_px", 0.0)
    kw.setdefault("survey_sigma_m", 0.0)
    return gs.simulate_ground(str(tmp_path), "d", **kw)


# ---- paper's inverse equations, written here from the text ----
def eq3_angles(fmx, fmz, fov=FOV, pix=PIX):
    tx, tz = np.tan(np.radians(fov[0]) / 2), np.tan(np.radians(fov[1]) / 2)
    psi = np.arctan(-2 * fmx / pix[0] * tx)
    theta = np.arctan((2 * fmz / pix[1] * tz) / np.sqrt(4 * fmx ** 2 / pix[0] ** 2 * tx ** 2 + 1))
    return psi, theta


def eq7_row2(psi, theta):
    return np.array([-np.cos(theta) * np.sin(psi), np.cos(theta) * np.cos(psi), np.sin(theta)])


def paper_calibration(pA, pB, L, H, normalise=True):
    """Eqs. (11)-(14): mounting angles [rad] from pixel coordinates of A=[0,L,0], B=[0,L,H]."""
    A, B = eq7_row2(*eq3_angles(*pA)), eq7_row2(*eq3_angles(*pB))
    C12, C22, C32 = A
    C13, C23, C33 = (B * np.sqrt(L ** 2 + H ** 2) - A * L) / H
    if normalise:
        al = np.sqrt(C13 ** 2 + C23 ** 2 + C33 ** 2)
        be = np.sqrt((C12 * C33 - C13 * C32) ** 2 + C22 ** 2 + C23 ** 2)
        C13, C23, C33, C12, C32 = C13 / al, C23 / al, C33 / al, al * C12 / be, al * C32 / be
    theta = np.arcsin(C23)
    gamma = np.arctan(-C13 / C33)
    psi = np.arcsin((C12 * C33 - C13 * C32) / np.sqrt(1 - C23 ** 2))
    return psi, theta, gamma


# ---------------------------------------------------------------- frames and projection
def test_eq5_matches_scipy_zxy():
    rng = np.random.default_rng(1)
    for ang in rng.uniform(-89, 89, (50, 3)):
        C = gs.dcm_b_to_a(*np.radians(ang))
        R = Rotation.from_euler("ZXY", ang, degrees=True).as_matrix()
        assert np.allclose(C, R.T, atol=1e-14)
        assert np.allclose(C @ C.T, np.eye(3), atol=1e-14)
        assert np.isclose(np.linalg.det(C), 1.0)


def test_focal_length_by_hand():
    assert np.allclose(gs.focal_lengths_px(FOV, PIX), (F, F))
    fx, fz = gs.focal_lengths_px((60.0, 40.0), (640, 480))
    assert np.isclose(fx, 320 / np.tan(np.radians(30)))
    assert np.isclose(fz, 240 / np.tan(np.radians(20)))


def test_hand_cases_single_axis():
    # identity mounting: target 10 m right, 5 m up at 100 m -> (0.1 F, 0.05 F)
    px, pz, _ = gs.paper_forward([[10, 100, 5]], 0, 0, 0, FOV, PIX)
    assert np.allclose([px[0], pz[0]], [25.6, 12.8], atol=1e-12)
    # azimuth only: target at bearing beta (left positive) -> px = -F tan(beta - psi), pz = 0
    for beta in (-10.0, 0.0, 30.0, 55.0):
        b = np.radians(beta)
        px, pz, _ = gs.paper_forward([[-80 * np.sin(b), 80 * np.cos(b), 0]], 30, 0, 0, FOV, PIX)
        assert np.isclose(px[0], -F * np.tan(b - np.radians(30)), atol=1e-10)
        assert abs(pz[0]) < 1e-10
    # target on the optical axis -> image centre
    px, pz, _ = gs.paper_forward([[-np.sin(np.radians(30)), np.cos(np.radians(30)), 0]],
                                 30, 0, 0, FOV, PIX)
    assert np.allclose([px[0], pz[0]], 0, atol=1e-12)
    # pitch only: target at elevation e -> pz = F tan(e - theta), px = 0
    for e in (0.0, 10.0, 20.0, 35.0):
        pt = [[0, 60 * np.cos(np.radians(e)), 60 * np.sin(np.radians(e))]]
        px, pz, _ = gs.paper_forward(pt, 0, 20, 0, FOV, PIX)
        assert np.isclose(pz[0], F * np.tan(np.radians(e - 20)), atol=1e-10)
        assert abs(px[0]) < 1e-10
    # roll only: target d to the right -> (F cos(g) d/L, F sin(g) d/L)
    g = np.radians(25)
    px, pz, _ = gs.paper_forward([[7, 100, 0]], 0, 0, 25, FOV, PIX)
    assert np.allclose([px[0], pz[0]], [F * np.cos(g) * 0.07, F * np.sin(g) * 0.07], atol=1e-10)


def test_forward_equals_independent_pinhole():
    rng = np.random.default_rng(2)
    for _ in range(30):
        ang = rng.uniform(-60, 60, 3)
        C = gs.dcm_b_to_a(*np.radians(ang))
        d_a = np.column_stack([rng.uniform(-0.9, 0.9, 20), np.ones(20), rng.uniform(-0.9, 0.9, 20)])
        pts = (d_a * rng.uniform(20, 300, (20, 1))) @ C          # r^b = C^T r^a, in front
        px, pz, _ = gs.paper_forward(pts, *ang, FOV, PIX)
        qx, qz = pinhole_scipy(pts, *ang)
        assert np.allclose(px, qx, atol=1e-9) and np.allclose(pz, qz, atol=1e-9)


def test_eq3_inverts_eq4_and_eq7_row_is_the_ray():
    rng = np.random.default_rng(3)
    pts = np.column_stack([rng.uniform(-40, 40, 50), rng.uniform(50, 120, 50),
                           rng.uniform(-10, 10, 50)])
    px, pz, r_a = gs.paper_forward(pts, 5, -3, 4, FOV, PIX)
    psi_m, th_m = eq3_angles(px, pz)
    psi10, th10 = gs.equivalent_angles(r_a)                     # eq. (10)
    assert np.allclose(psi_m, psi10, atol=1e-12) and np.allclose(th_m, th10, atol=1e-12)
    ray = eq7_row2(psi_m, th_m).T                                # eq. (8): r^a = A_2j |r|
    assert np.allclose(ray, r_a / np.linalg.norm(r_a, axis=1)[:, None], atol=1e-12)
    # eq. (2): x_N = -L tan(psi_m), z_N = L tan(theta_m)/cos(psi_m) on the plane y = L
    assert np.allclose(r_a[:, 0] / r_a[:, 1], -np.tan(psi_m), atol=1e-12)
    assert np.allclose(r_a[:, 2] / r_a[:, 1], np.tan(th_m) / np.cos(psi_m), atol=1e-12)


@pytest.mark.parametrize("ang,L,H", [((30, 20, 10), 50, 1), ((30, 20, 10), 100, 3),
                                     ((-25, 12, -30), 80, 2), ((5, -15, 40), 120, 1.5)])
def test_paper_two_point_calibration_recovers_angles(tmp_path, ang, L, H):
    out = sim(tmp_path, psi_deg=ang[0], theta_deg=ang[1], gamma_deg=ang[2],
              targets_b=[[0, L, 0], [0, L, H]], target_names=["A", "B"])
    for norm in (False, True):
        est = paper_calibration((out["px"][0], out["pz"][0]), (out["px"][1], out["pz"][1]),
                                L, H, norm)
        assert np.allclose(np.degrees(est), ang, atol=1e-9)


TABLE1 = [  # df [px], L [m], H [m], delta_b [m], Delta [mrad], Delta_bar [mrad]
    (1.0, 50, 1, 5e-3, 7.37, 6.77), (1.0, 50, 1, 1e-3, 5.92, 5.81),
    (0.5, 50, 1, 1e-3, 4.38, 4.23), (0.5, 100, 1, 1e-3, 3.13, 3.02),
    (0.5, 100, 2, 1e-3, 2.96, 2.91), (0.5, 100, 3, 1e-3, 2.91, 2.88)]


@pytest.mark.parametrize("df,L,H,db,D,Dbar", TABLE1)
def test_paper_table1_worst_case(tmp_path, df, L, H, db, D, Dbar):
    """Section 1.3/1.4: A' = [dx, L+dy, dh1], B' = [dx, L+dy, H+dh1+db] with |dx|,|dy|,|dh1| =
    0.1 m, a pixel error df on both coordinates; worst case over the 64 sign choices. The paper's
    Delta equals arccos((1 + trace D)/4) (i.e. eq. (18) without its square root, ~ angle/sqrt 2);
    its values are reproduced to 1 %. The pixel error df is injected through the simulator's
    principal-point offset (a common image shift)."""
    C_true = gs.dcm_b_to_a(*np.radians([30, 20, 10]))
    worst = [0.0, 0.0]
    for sx, sy, sh, sb, s1, s2 in itertools.product((-1, 1), repeat=6):
        dx, dy, dh1 = 0.1 * sx, 0.1 * sy, 0.1 * sh
        out = sim(tmp_path, targets_b=[[dx, L + dy, dh1], [dx, L + dy, H + dh1 + sb * db]],
                  target_names=["A'", "B'"], principal_point_px=(s1 * df, s2 * df))
        for k, norm in enumerate((False, True)):
            est = paper_calibration((out["px"][0], out["pz"][0]), (out["px"][1], out["pz"][1]),
                                    L, H, norm)
            Dm = gs.dcm_b_to_a(*est) @ C_true.T                  # C_a^c = C_b^c (C_b^a)^T
            worst[k] = max(worst[k], np.arccos(min(1.0, (1 + np.trace(Dm)) / 4)))
    assert np.isclose(worst[0] * 1e3, D, rtol=0.01)
    assert np.isclose(worst[1] * 1e3, Dbar, rtol=0.01)


# ---------------------------------------------------------------- files
def test_clean_files_are_the_paper_model(tmp_path):
    out = sim(tmp_path)
    header, rows = read_csv(out["csv"])
    assert header == ["target", "x_m", "y_m", "z_m", "px", "pz", "t_s"]
    names = [r[0] for r in rows]
    assert len(set(names)) == len(names) >= 8
    data = np.array([[float(v) for v in r[1:]] for r in rows])
    assert np.all(np.diff(data[:, 5]) > 0)
    qx, qz = pinhole_scipy(data[:, :3], 30, 20, 10)              # surveyed == true here
    assert np.allclose(data[:, 3], qx, rtol=1e-12, atol=1e-9)
    assert np.allclose(data[:, 4], qz, rtol=1e-12, atol=1e-9)
    assert np.all(np.abs(data[:, 3]) <= 256) and np.all(np.abs(data[:, 4]) <= 256)
    truth = json.load(open(out["truth"], encoding="utf-8"))
    for key in ("fov_deg", "pixels", "pixel_sigma_px", "survey_sigma_m", "psi_deg", "theta_deg",
                "gamma_deg", "seed", "hidden_effects"):
        assert key in truth
    assert truth["fov_deg"] == [90.0, 90.0] and truth["pixels"] == [512, 512]
    assert (truth["psi_deg"], truth["theta_deg"], truth["gamma_deg"]) == (30.0, 20.0, 10.0)
    assert not any(e["enabled"] for e in truth["hidden_effects"].values())
    assert all(e["definition"] for e in truth["hidden_effects"].values())
    # the paper's forward-axis points A = [0, 50, 0] and B = [0, 50, 2] are in the default layout
    tb = np.array(list(truth["true_targets_b_m"].values()))
    assert np.any(np.all(np.isclose(tb, [0, 50, 0], atol=1e-12), axis=1))
    assert np.any(np.all(np.isclose(tb, [0, 50, 2], atol=1e-12), axis=1))


@pytest.mark.parametrize("ang", [(30, 20, 10), (-40, 5, -20), (0, -25, 35), (60, 10, 0)])
def test_default_layout_in_front_and_inside_fov(tmp_path, ang):
    out = gs.simulate_ground(str(tmp_path), "d", psi_deg=ang[0], theta_deg=ang[1],
                             gamma_deg=ang[2], seed=4)
    assert np.all(out["r_a"][:, 1] > 0)
    assert np.all(np.abs(out["px"]) <= 256) and np.all(np.abs(out["pz"]) <= 256)


def test_rejects_targets_behind_or_outside(tmp_path):
    with pytest.raises(ValueError):
        sim(tmp_path, psi_deg=0, theta_deg=0, gamma_deg=0, targets_b=[[0, -50, 0]])
    with pytest.raises(ValueError):
        sim(tmp_path, psi_deg=0, theta_deg=0, gamma_deg=0, targets_b=[[60, 50, 0]])


# ---------------------------------------------------------------- noise
def grid_targets(n=40):
    u = np.linspace(-0.7, 0.7, n)
    xa, za = np.meshgrid(u, u)
    return np.column_stack([xa.ravel() * 100, np.full(xa.size, 100.0), za.ravel() * 100])


def test_noise_statistics_and_seed(tmp_path):
    pts = grid_targets()
    clean = sim(tmp_path, psi_deg=0, theta_deg=0, gamma_deg=0, targets_b=pts)
    a = gs.simulate_ground(str(tmp_path), "a", psi_deg=0, theta_deg=0, gamma_deg=0,
                           targets_b=pts, pixel_sigma_px=0.7, survey_sigma_m=0.05, seed=11)
    b = gs.simulate_ground(str(tmp_path), "b", psi_deg=0, theta_deg=0, gamma_deg=0,
                           targets_b=pts, pixel_sigma_px=0.7, survey_sigma_m=0.05, seed=11)
    c = gs.simulate_ground(str(tmp_path), "c", psi_deg=0, theta_deg=0, gamma_deg=0,
                           targets_b=pts, pixel_sigma_px=0.7, survey_sigma_m=0.05, seed=12)
    assert open(a["csv"]).read() == open(b["csv"]).read()
    assert not np.allclose(a["px"], c["px"])
    e = np.concatenate([a["px"] - clean["px"], a["pz"] - clean["pz"]])
    assert abs(e.mean()) < 0.05 and abs(e.std() / 0.7 - 1) < 0.05           # n = 3200
    s = (a["surveyed_b"] - pts).ravel()
    assert abs(s.mean()) < 0.005 and abs(s.std() / 0.05 - 1) < 0.05         # n = 4800
    assert np.allclose(a["px_ideal"], clean["px"])        # noise does not touch the true image


# ---------------------------------------------------------------- hidden effects
def test_focal_drift_linear_in_time(tmp_path):
    pts = grid_targets(8)
    d = 3e-3
    out = sim(tmp_path, targets_b=pts, psi_deg=0, theta_deg=0, gamma_deg=0,
              focal_drift_per_hour=d, session_s=7200.0, t0_s=100.0)
    scale = 1 + d * (out["t_s"] - 100.0) / 3600
    assert np.isclose(scale[-1], 1.006)
    qx, qz = pinhole_scipy(pts, 0, 0, 0)
    assert np.allclose(out["px"], qx * scale, atol=1e-9)
    assert np.allclose(out["pz"], qz * scale, atol=1e-9)
    eff = json.load(open(out["truth"]))["hidden_effects"]["focal_drift_per_hour"]
    assert eff["value"] == d and eff["enabled"] and eff["units"] == "1/h"


def test_fifth_order_radial_distortion_only(tmp_path):
    pts = grid_targets(15)
    k2 = -0.03
    out = sim(tmp_path, targets_b=pts, psi_deg=0, theta_deg=0, gamma_deg=0, radial_k2=k2)
    xn, zn = pinhole_scipy(pts, 0, 0, 0)
    xn, zn = xn / F, zn / F
    dx, dz = out["px"] / F, out["pz"] / F
    r, rd = np.hypot(xn, zn), np.hypot(dx, dz)
    m = r > 0.05
    assert np.allclose(rd[m] / r[m], 1 + k2 * r[m] ** 4, atol=1e-12)
    assert np.allclose(np.arctan2(dz[m], dx[m]), np.arctan2(zn[m], xn[m]), atol=1e-12)
    # a least-squares fit of (r'/r - 1) on (r^2, r^4) finds no r^2 term
    coef = np.linalg.lstsq(np.column_stack([r[m] ** 2, r[m] ** 4]), rd[m] / r[m] - 1,
                           rcond=None)[0]
    assert abs(coef[0]) < 1e-10 and np.isclose(coef[1], k2)


def test_range_dependent_centroid_bias(tmp_path):
    b, ref = 0.8, 50.0
    pts = np.array([[20, 100, 10], [10, 50, 5], [40, 200, 20], [-30, 100, -15]], float)
    out = sim(tmp_path, targets_b=pts, psi_deg=0, theta_deg=0, gamma_deg=0,
              centroid_bias_px=b, centroid_bias_ref_range_m=ref)
    qx, qz = pinhole_scipy(pts, 0, 0, 0)
    shift = np.hypot(qx, qz) - np.hypot(out["px"], out["pz"])          # toward the centre
    assert np.allclose(shift, b * ref / np.linalg.norm(pts, axis=1), atol=1e-10)
    assert np.allclose(np.arctan2(out["pz"], out["px"]), np.arctan2(qz, qx), atol=1e-12)
    assert np.isclose(shift[1], 2 * shift[0]) and np.isclose(shift[0], 2 * shift[2])


def test_principal_point_and_height_datum(tmp_path):
    pts = grid_targets(5)
    out = sim(tmp_path, targets_b=pts, principal_point_px=(1.5, -2.0), height_datum_m=0.07,
              psi_deg=0, theta_deg=0, gamma_deg=0)
    qx, qz = pinhole_scipy(pts, 0, 0, 0)
    assert np.allclose(out["px"] - qx, 1.5) and np.allclose(out["pz"] - qz, -2.0)
    assert np.allclose(out["surveyed_b"] - pts, [0, 0, 0.07])


def test_effects_off_is_bit_exact_forward_model(tmp_path):
    out = sim(tmp_path, seed=5)
    px, pz, _ = gs.paper_forward(out["true_b"], 30, 20, 10, FOV, PIX)
    assert np.array_equal(out["px"], px) and np.array_equal(out["pz"], pz)
    _, rows = read_csv(out["csv"])
    assert np.array_equal(np.array([float(r[4]) for r in rows]), px)    # repr round-trips
