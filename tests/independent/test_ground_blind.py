"""Tests of the blind ground-calibration simulator against closed forms derived by hand from
the paper (Ding Tao 2014, section 1) — see each docstring for the derivation.

Notation: F = (N/2)/tan(FOV/2) [px]; for the 90 deg x 90 deg, 512 x 512 camera of section 1.4,
F_x = F_z = 256 px. C_b^a is the paper's eq. (5); r^a = C_b^a r^b; px = F_x x_a/y_a,
pz = F_z z_a/y_a (eqs. (1), (4)).
"""

from __future__ import annotations

import csv
import importlib.util
import json
import math
from pathlib import Path

import numpy as np
import pytest

_spec = importlib.util.spec_from_file_location(
    "ground_blind", Path(__file__).with_name("ground_blind.py"))
gb = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(gb)

F = 256.0  # 90 deg field, 512 px: 256 / tan(45 deg)
NOISELESS = dict(pixel_sigma_px=0.0, survey_sigma_m=0.0)


def _read_csv(path):
    with open(path, newline="", encoding="utf-8") as fh:
        rows = list(csv.reader(fh))
    return rows[0], rows[1:]


def _sim(tmp_path, targets, angles=(0.0, 0.0, 0.0), name="d", **kw):
    kw = {**NOISELESS, **kw}
    truth = gb.simulate(tmp_path / name, psi_deg=angles[0], theta_deg=angles[1],
                        gamma_deg=angles[2], targets_m=np.asarray(targets, float), **kw)
    header, rows = _read_csv(tmp_path / f"{name}.csv")
    data = np.array([[float(v) for v in r[1:]] for r in rows]).reshape(-1, 6)
    return truth, header, rows, data


def _eq5(psi, theta, gamma):
    """Eq. (5) typed entry by entry from the paper."""
    cp, sp = math.cos(psi), math.sin(psi)
    ct, st = math.cos(theta), math.sin(theta)
    cg, sg = math.cos(gamma), math.sin(gamma)
    return np.array([
        [cg * cp - sg * st * sp, cg * sp + sg * st * cp, -sg * ct],
        [-ct * sp, ct * cp, st],
        [sg * cp + cg * st * sp, sg * sp - cg * st * cp, cg * ct],
    ])


def test_dcm_matches_eq5():
    """The scipy mapping Rotation.from_euler('ZXY', [psi, theta, gamma]).as_matrix().T must
    reproduce eq. (5) for arbitrary angles in (-90, 90) deg, including the paper's 30/20/10."""
    rng = np.random.default_rng(1)
    angs = [(30.0, 20.0, 10.0)] + [tuple(a) for a in rng.uniform(-89, 89, (20, 3))]
    for a in angs:
        c = gb.dcm_b_to_a(*a)
        np.testing.assert_allclose(c, _eq5(*np.radians(a)), atol=1e-14)


def test_optical_axis_target_lands_at_centre(tmp_path):
    """A target on the optical axis has r^a = (0, R, 0), i.e. r^b = (C_b^a)^T (0, R, 0) = R times
    the second row of eq. (5); eq. (P) gives px = pz = 0."""
    c = _eq5(*np.radians([30.0, 20.0, 10.0]))
    targets = [c[1] * 37.0, c[1] * 120.0]
    _, _, _, d = _sim(tmp_path, targets, (30.0, 20.0, 10.0))
    np.testing.assert_allclose(d[:, 3:5], 0.0, atol=1e-9)


def test_zero_angles_pinhole(tmp_path):
    """psi = theta = gamma = 0: C_b^a = I, so r^a = r^b and px = F x/y, pz = F z/y (positive x
    right -> positive px, positive z up -> positive pz, eq. (1)). Also the 16:9-like camera
    checks that NX/FOV_h go with px and NZ/FOV_v with pz (F_x = 320/tan 40, F_z = 240/tan 30)."""
    t = np.array([[10.0, 100.0, 5.0], [-20.0, 50.0, -7.0], [3.0, 30.0, 0.0]])
    _, _, _, d = _sim(tmp_path, t)
    np.testing.assert_allclose(d[:, 3], F * t[:, 0] / t[:, 1], atol=1e-9)
    np.testing.assert_allclose(d[:, 4], F * t[:, 2] / t[:, 1], atol=1e-9)
    _, _, _, d2 = _sim(tmp_path, t, name="w", fov_deg=(80.0, 60.0), pixels=(640, 480))
    fx, fz = 320 / math.tan(math.radians(40)), 240 / math.tan(math.radians(30))
    np.testing.assert_allclose(d2[:, 3], fx * t[:, 0] / t[:, 1], atol=1e-9)
    np.testing.assert_allclose(d2[:, 4], fz * t[:, 2] / t[:, 1], atol=1e-9)


def test_pure_azimuth_pitch_roll(tmp_path):
    """Single-axis mountings, target straight ahead (0, L, 0) or to the side (x, L, 0):
    psi only: r^a = (L sin psi, L cos psi, 0) -> px = F tan psi, pz = 0 (optical axis turned
      left, target appears right; same as eq. (10) psi_A = -psi and eq. (4)).
    theta only: r^a = (0, L cos theta, -L sin theta) -> px = 0, pz = -F tan theta.
    gamma only, target (x, L, 0): r^a = (x cos gamma, L, x sin gamma) ->
      px = F x cos(gamma)/L, pz = F x sin(gamma)/L (the image rotates about the centre)."""
    L, x = 100.0, 20.0
    for ang in (30.0, -12.0):
        a = math.radians(ang)
        _, _, _, d = _sim(tmp_path, [[0, L, 0]], (ang, 0, 0), name="p")
        np.testing.assert_allclose(d[0, 3:5], [F * math.tan(a), 0.0], atol=1e-9)
        _, _, _, d = _sim(tmp_path, [[0, L, 0]], (0, ang, 0), name="t")
        np.testing.assert_allclose(d[0, 3:5], [0.0, -F * math.tan(a)], atol=1e-9)
        _, _, _, d = _sim(tmp_path, [[x, L, 0]], (0, 0, ang), name="g")
        np.testing.assert_allclose(d[0, 3:5], [F * x * math.cos(a) / L, F * x * math.sin(a) / L],
                                   atol=1e-9)


def test_matches_paper_eq10_and_eq4(tmp_path):
    """Full chain through the paper's own equations: for the 30/20/10 mounting and arbitrary
    targets, eq. (10) gives theta_A = arcsin((C31 x + C32 y + C33 z)/|r|) and
    psi_A = arctan(-(C11 x + C12 y + C13 z)/(C21 x + C22 y + C23 z)); eq. (4) gives
    f_mx = -f_x tan(psi_A)/(2 tan(fov/2)), f_mz = f_z tan(theta_A)/(2 cos(psi_A) tan(fov/2)).
    Then eq. (3) must invert (px, pz) back to the same (psi_A, theta_A)."""
    ang = (30.0, 20.0, 10.0)
    c = _eq5(*np.radians(ang))
    t = gb.default_layout(*ang)
    _, _, _, d = _sim(tmp_path, t, ang)
    assert d.shape[0] == t.shape[0]
    num_x, num_y, num_z = (t @ c[0]), (t @ c[1]), (t @ c[2])
    theta_a = np.arcsin(num_z / np.linalg.norm(t, axis=1))
    psi_a = np.arctan(-num_x / num_y)
    tan_half = math.tan(math.radians(45.0))
    fmx = -512 * np.tan(psi_a) / (2 * tan_half)
    fmz = 512 * np.tan(theta_a) / (2 * np.cos(psi_a) * tan_half)
    np.testing.assert_allclose(d[:, 3], fmx, atol=1e-8)
    np.testing.assert_allclose(d[:, 4], fmz, atol=1e-8)
    # eq. (3)
    psi_m = np.arctan(-2 * d[:, 3] / 512 * tan_half)
    theta_m = np.arctan((2 * d[:, 4] / 512 * tan_half)
                        / np.sqrt(4 * d[:, 3] ** 2 / 512 ** 2 * tan_half ** 2 + 1))
    np.testing.assert_allclose(psi_m, psi_a, atol=1e-12)
    np.testing.assert_allclose(theta_m, theta_a, atol=1e-12)


def test_default_layout_spread_and_ranges(tmp_path):
    """Default layout: every target projects inside the image (none dropped), ranges lie in
    [30, 150] m with at least two distinct ranges, and the images cover most of the field
    (extent of |px|, |pz| above 70 % of the half-width 256 px)."""
    for ang in [(30.0, 20.0, 10.0), (0.0, 0.0, 0.0), (-40.0, 10.0, -25.0)]:
        t = gb.default_layout(*ang)
        r = np.linalg.norm(t, axis=1)
        assert r.min() >= 30.0 and r.max() <= 150.0
        assert len(np.unique(np.round(r, 6))) >= 2
        truth = gb.simulate(tmp_path / "L", psi_deg=ang[0], theta_deg=ang[1],
                            gamma_deg=ang[2], **NOISELESS)
        assert truth["n_written"] == len(t) and truth["n_dropped_outside"] == 0
        assert truth["n_dropped_behind"] == 0
        p = np.array([[e["px_true"], e["pz_true"]] for e in truth["targets"]])
        assert np.all(np.abs(p) <= 256.0)
        assert np.abs(p[:, 0]).max() > 0.7 * 256 and np.abs(p[:, 1]).max() > 0.7 * 256


def test_drops_behind_and_outside(tmp_path):
    """With zero angles: (0, -50, 0) is behind (y_a < 0); (60, 50, 0) maps to px = 307 > 256
    (outside); (0, 50, 0) and (10, 50, 10) are kept (px = pz = 51.2 for the latter)."""
    t = [[0, 50, 0], [0, -50, 0], [60, 50, 0], [10, 50, 10]]
    truth, _, rows, d = _sim(tmp_path, t)
    assert truth["n_dropped_behind"] == 1 and truth["n_dropped_outside"] == 1
    assert [r[0] for r in rows] == ["T000", "T003"]
    np.testing.assert_allclose(d[1, 3:5], [51.2, 51.2], atol=1e-9)


def test_noise_statistics(tmp_path):
    """Centroid and survey errors are N(0, sigma^2), independent. With n samples the sample
    standard deviation has relative s.d. ~ 1/sqrt(2(n-1)) and the mean has s.d. sigma/sqrt(n);
    the fraction within +-sigma (0.6827 for a normal; 0.577 for a uniform of equal s.d.) has
    s.d. sqrt(p(1-p)/n). Tolerances are 5 such standard deviations. px and pz errors must be
    uncorrelated (|rho| < 5/sqrt(n))."""
    g = np.linspace(-50.0, 50.0, 45)
    xx, zz = np.meshgrid(g, g)
    t = np.column_stack([xx.ravel(), np.full(xx.size, 100.0), zz.ravel()])
    sp, ss = 0.3, 0.01
    _, _, _, d = _sim(tmp_path, t, pixel_sigma_px=sp, survey_sigma_m=ss, seed=7)
    true_img = np.column_stack([F * t[:, 0] / t[:, 1], F * t[:, 2] / t[:, 1]])
    for err, sigma in ((d[:, 3:5] - true_img, sp), (d[:, 0:3] - t, ss)):
        e = err.ravel()
        n = e.size
        assert abs(e.std(ddof=1) / sigma - 1) < 5 / math.sqrt(2 * (n - 1))
        assert abs(e.mean()) < 5 * sigma / math.sqrt(n)
        p = 0.682689492
        assert abs(np.mean(np.abs(e) <= sigma) - p) < 5 * math.sqrt(p * (1 - p) / n)
    e = d[:, 3:5] - true_img
    assert abs(np.corrcoef(e[:, 0], e[:, 1])[0, 1]) < 5 / math.sqrt(len(e))


def test_deterministic_and_seed_dependent(tmp_path):
    """Same seed -> byte-identical files; another seed -> different noise."""
    t = gb.default_layout()
    gb.simulate(tmp_path / "a", psi_deg=30, theta_deg=20, gamma_deg=10, targets_m=t, seed=3)
    gb.simulate(tmp_path / "b", psi_deg=30, theta_deg=20, gamma_deg=10, targets_m=t, seed=3)
    gb.simulate(tmp_path / "c", psi_deg=30, theta_deg=20, gamma_deg=10, targets_m=t, seed=4)
    a, b, c = ((tmp_path / f"{k}.csv").read_bytes() for k in "abc")
    assert a == b and a != c


def test_radial_k1(tmp_path):
    """x_d = x_u (1 + k1 r^2) with r^2 = u^2 + w^2, u = x/y, w = z/y (zero angles): the centre
    target stays at (0, 0); target (30, 100, 40) has r^2 = 0.25, so its image (76.8, 102.4)
    becomes (76.8, 102.4) (1 + 0.25 k1)."""
    k1 = -0.08
    t = [[0, 80, 0], [30, 100, 40]]
    truth, _, _, d = _sim(tmp_path, t, effects={"radial_k1": k1})
    np.testing.assert_allclose(d[0, 3:5], 0.0, atol=1e-12)
    np.testing.assert_allclose(d[1, 3:5], np.array([76.8, 102.4]) * (1 + 0.25 * k1), atol=1e-9)
    assert truth["effects"]["radial_k1"]["value"] == k1
    assert "distortion" in truth["effects"]["radial_k1"]["definition"]


def test_principal_point(tmp_path):
    """Every measured coordinate is offset by (dx, dz), whatever the mounting and target."""
    ang = (30.0, 20.0, 10.0)
    t = gb.default_layout(*ang)
    _, _, _, d0 = _sim(tmp_path, t, ang, name="n")
    _, _, _, d1 = _sim(tmp_path, t, ang, name="e", effects={"principal_point_px": (1.5, -2.0)})
    np.testing.assert_allclose(d1[:, 3:5] - d0[:, 3:5], np.tile([1.5, -2.0], (len(t), 1)),
                               atol=1e-9)


def test_focal_scale(tmp_path):
    """True focal = nominal (1 + s): px, pz scale by (1 + s) about the centre; survey unchanged
    and the truth still describes the nominal 90 deg / 512 px camera."""
    ang = (30.0, 20.0, 10.0)
    t = gb.default_layout(*ang)
    _, _, _, d0 = _sim(tmp_path, t, ang, name="n")
    truth, _, _, d1 = _sim(tmp_path, t, ang, name="e", effects={"focal_scale": 0.01})
    np.testing.assert_allclose(d1[:, 3:5], 1.01 * d0[:, 3:5], atol=1e-9)
    np.testing.assert_allclose(d1[:, 0:3], d0[:, 0:3], atol=0)
    assert truth["fov_deg"] == [90.0, 90.0] and truth["pixels"] == [512, 512]


def test_lever_arm(tmp_path):
    """Projection centre at a (frame b): a target at a + v images exactly where v images without
    lever arm, while the file records a + v (survey relative to the origin). Zero angles:
    target (a + (10, 100, 5)) -> (25.6, 12.8)."""
    a = np.array([0.3, -0.5, 0.2])
    v = np.array([[10.0, 100.0, 5.0], [-20.0, 40.0, 8.0]])
    _, _, _, d = _sim(tmp_path, v + a, effects={"lever_arm_m": a})
    np.testing.assert_allclose(d[0, 3:5], [25.6, 12.8], atol=1e-9)
    np.testing.assert_allclose(d[:, 3], F * v[:, 0] / v[:, 1], atol=1e-9)
    np.testing.assert_allclose(d[:, 0:3], v + a, atol=1e-12)
    ang = (30.0, 20.0, 10.0)
    t = gb.default_layout(*ang)
    _, _, _, d0 = _sim(tmp_path, t, ang, name="n")
    _, _, _, d1 = _sim(tmp_path, t + a, ang, name="e", effects={"lever_arm_m": a})
    np.testing.assert_allclose(d1[:, 3:5], d0[:, 3:5], atol=1e-9)


def test_unknown_effect_and_bad_values(tmp_path):
    with pytest.raises(ValueError, match="tangential_p1"):
        gb.simulate(tmp_path / "x", psi_deg=0, theta_deg=0, gamma_deg=0,
                    effects={"tangential_p1": 1e-3})
    with pytest.raises(ValueError, match="lever_arm_m"):
        gb.simulate(tmp_path / "x", psi_deg=0, theta_deg=0, gamma_deg=0,
                    effects={"lever_arm_m": [1.0, 2.0]})
    with pytest.raises(ValueError, match="bogus"):
        gb.main([str(tmp_path), "--effect", "bogus=1"])


def test_file_format_and_truth(tmp_path):
    """CSV header and columns per the format; names unique; t_s increasing; truth JSON holds
    camera, noise, angles, seed and effects with value and definition."""
    truth = gb.simulate(tmp_path / "f", psi_deg=30, theta_deg=20, gamma_deg=10, seed=5,
                        effects={"radial_k1": 0.01, "principal_point_px": [0.5, 0.0]})
    header, rows = _read_csv(tmp_path / "f.csv")
    assert header == ["target", "x_m", "y_m", "z_m", "px", "pz", "t_s"]
    names = [r[0] for r in rows]
    assert len(set(names)) == len(names) == truth["n_written"] > 0
    ts = [float(r[6]) for r in rows]
    assert np.all(np.diff(ts) > 0)
    on_disk = json.loads((tmp_path / "f.truth.json").read_text(encoding="utf-8"))
    assert on_disk == json.loads(json.dumps(truth))
    for k in ("fov_deg", "pixels", "pixel_sigma_px", "survey_sigma_m", "psi_deg", "theta_deg",
              "gamma_deg", "seed", "effects"):
        assert k in on_disk
    assert on_disk["seed"] == 5 and on_disk["psi_deg"] == 30.0
    assert set(on_disk["effects"]) == {"radial_k1", "principal_point_px"}
    assert on_disk["effects"]["principal_point_px"]["value"] == [0.5, 0.0]


def test_cli(tmp_path):
    """CLI writes N data sets with consecutive seeds and the parsed effects."""
    assert gb.main([str(tmp_path), "--n", "2", "--seed", "11",
                    "--effect", "lever_arm_m=0.1,0,-0.2", "--effect", "focal_scale=0.002"]) == 0
    for i in range(2):
        tr = json.loads((tmp_path / f"ground_{i:03d}.truth.json").read_text(encoding="utf-8"))
        assert tr["seed"] == 11 + i
        assert tr["effects"]["lever_arm_m"]["value"] == [0.1, 0.0, -0.2]
        assert tr["effects"]["focal_scale"]["value"] == 0.002
        assert (tmp_path / f"ground_{i:03d}.csv").exists()
