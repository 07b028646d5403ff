"""Camera calibration from a planar target (montecarlo.camera_calibration, io.camera_csv).

References: Zhang (1998), MSR-TR-98-71, and the data set and results he published with it
(tests/data/camera/README.md).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from scipy import stats
from scipy.spatial.transform import Rotation

from montecarlo.camera_calibration.calibrate import (
    CalibrationError,
    calibrate,
    closed_form,
    homography,
)
from montecarlo.camera_calibration.model import distort, project, rotate, rotation_matrix
from montecarlo.camera_calibration.simulate import (
    DEFAULT_CAMERA,
    simulate,
    standard_poses,
    target_grid,
)
from montecarlo.errors import InputError
from montecarlo.io.camera_csv import read_camera_csv

DATA = Path(__file__).parent / "data" / "camera"
MODEL, VIEWS = DATA / "zhang_model.csv", DATA / "zhang_views.csv"


def test_rotate_matches_scipy_rotvec_including_tiny_angles():
    rng = np.random.default_rng(0)
    w = rng.normal(size=(50, 3)) * np.logspace(-9, 0.5, 50)[:, None]
    p = rng.normal(size=(50, 3))
    np.testing.assert_allclose(rotate(w, p), Rotation.from_rotvec(w).apply(p), rtol=0,
                               atol=1e-14)


def test_rotation_matrix_matches_scipy_including_tiny_angles():
    rng = np.random.default_rng(1)
    w = rng.normal(size=(50, 3)) * np.logspace(-9, 0.5, 50)[:, None]
    np.testing.assert_allclose(rotation_matrix(w), Rotation.from_rotvec(w).as_matrix(), rtol=0,
                               atol=1e-14)
    np.testing.assert_array_equal(rotation_matrix(np.zeros(3)), np.eye(3))


def test_projection_equals_the_point_by_point_rodrigues_reference():
    """``project`` (a matrix per view) against the literal formula: every point rotated by
    :func:`rotate`, then eq. (11) and eq. (1), for 7 parameter vectors at once."""
    rng = np.random.default_rng(2)
    k, V, n = 7, 4, 60
    rvec = rng.normal(scale=0.4, size=(k, V, 3))
    tvec = rng.normal(scale=0.1, size=(k, V, 3)) + np.array([0.0, 0.0, 1.0])
    pts = rng.uniform(-0.2, 0.2, size=(n, 2))
    view = rng.integers(0, V, size=n)
    params = {"f": rng.uniform(700, 900, (k, 1)), "a": 0.002, "gamma": 0.3, "cx": 320.0,
              "cy": 240.0, "k1": -0.2, "k2": 0.1, "p1": 0.001, "p2": -0.0005}
    cam = rotate(rvec[:, view], np.column_stack([pts, np.zeros(n)])) + tvec[:, view]
    xd, yd = distort(cam[..., 0] / cam[..., 2], cam[..., 1] / cam[..., 2], params)
    u = params["f"] * xd + 0.3 * yd + 320.0
    v = params["f"] * 1.002 * yd + 240.0
    np.testing.assert_allclose(project(params, rvec, tvec, pts, view),
                               np.stack([u, v], axis=-1), rtol=0, atol=1e-10)


def test_distortion_by_hand():
    """x = 0.1, y = 0.2: r^2 = 0.05. k1 = 0.1, k2 = 1, k3 = 10: radial factor
    1 + 0.005 + 0.0025 + 0.00125 = 1.00875. p1 = 0.01, p2 = 0.02: dx = 2 p1 x y + p2 (r^2 +
    2 x^2) = 0.0004 + 0.0014 = 0.0018; dy = p1 (r^2 + 2 y^2) + 2 p2 x y = 0.0013 + 0.0008."""
    xd, yd = distort(0.1, 0.2, {"k1": 0.1, "k2": 1.0, "k3": 10.0, "p1": 0.01, "p2": 0.02})
    assert xd == pytest.approx(0.1 * 1.00875 + 0.0018, abs=1e-15)
    assert yd == pytest.approx(0.2 * 1.00875 + 0.0021, abs=1e-15)


def test_projection_by_hand():
    """Identity pose, t = (0, 0, 2) m: the point (1, 0.5) m is at x = 0.5, y = 0.25.
    f = 800, a = 0.01, gamma = 2, c = (320, 240): u = 400 + 0.5 + 320, v = 808 * 0.25 + 240."""
    uv = project({"f": 800.0, "a": 0.01, "gamma": 2.0, "cx": 320.0, "cy": 240.0},
                 np.zeros((1, 3)), np.array([[0.0, 0.0, 2.0]]), np.array([[1.0, 0.5]]), [0])
    np.testing.assert_allclose(uv, [[720.5, 442.0]], rtol=0, atol=1e-12)


def test_homography_recovers_a_known_one():
    H = np.array([[700.0, 20.0, 300.0], [-10.0, 650.0, 200.0], [0.1, -0.2, 1.0]])
    M = target_grid(5, 0.1)
    m = np.column_stack([M, np.ones(len(M))]) @ H.T
    np.testing.assert_allclose(homography(M, m[:, :2] / m[:, 2:]), H, rtol=1e-9)


def test_closed_form_is_exact_on_noise_free_pinhole_views():
    truth = {**DEFAULT_CAMERA, "a": 0.002, "gamma": 0.5}
    r, t = standard_poses()
    pts, pix, view = simulate(target_grid(), truth, r, t, 0.0)
    K = closed_form(pts, pix, view, 5)["K"]
    np.testing.assert_allclose(K, [[830.0, 0.5, 320.0], [0.0, 830.0 * 1.002, 240.0],
                                   [0, 0, 1]], rtol=0, atol=1e-6)


def test_least_squares_recovers_distortion_and_its_sigma_is_honest():
    """Noise 0.1 px: every estimate within 4.5 sigma of the truth (36 parameters; a
    normal beyond 4.5 sigma has probability 7e-6 each), and exact without noise."""
    truth = {**DEFAULT_CAMERA, "a": 0.001, "gamma": 0.3, "k1": -0.2, "k2": 0.15,
             "p1": 1e-3, "p2": -5e-4}
    r, t = standard_poses()
    pts, pix, view = simulate(target_grid(), truth, r, t, 0.0)
    exact = calibrate(pts, pix, view, 5, ("k1", "k2", "p1", "p2"), sigma=0.1)
    for k, v in truth.items():
        assert exact.params[k] == pytest.approx(v, abs=1e-8)
    pts, pix, view = simulate(target_grid(), truth, r, t, 0.1, rng=3)
    noisy = calibrate(pts, pix, view, 5, ("k1", "k2", "p1", "p2"), sigma=0.1)
    z = {k: (noisy.params[k] - v) / noisy.stderr[k] for k, v in truth.items()}
    assert max(abs(v) for v in z.values()) < 4.5, z
    # from both sides: with the covariance as reported, e' C^-1 e over the 9 compared parameters
    # is chi-square with 9 dof; inside its central 99.9 % (a covariance 4 times too large
    # puts a typical 9 at 2.25, in the band; one 10 times too large, at 0.9, below it)
    idx = [noisy.names.index(k) for k in truth]
    e = np.array([noisy.params[k] - v for k, v in truth.items()])
    m2 = float(e @ np.linalg.solve(noisy.covariance[np.ix_(idx, idx)], e))
    assert stats.chi2.ppf(0.0005, 9) < m2 < stats.chi2.ppf(0.9995, 9), m2
    assert noisy.rms == pytest.approx(0.1, rel=0.1)  # 640 coordinates: rel. sd 2.8 %
    # 640 coordinates - 39 parameters (5 intrinsics, 4 distortion, 6 per view) = 601 dof, and
    # chi2_red of the stated noise within its central 99.9 % band (sd sqrt(2/601) = 5.8 %)
    assert noisy.dof == 601
    assert noisy.chi2 == pytest.approx(np.sum(noisy.residual**2) / 0.01, rel=1e-12)
    lo, hi = stats.chi2.ppf([0.0005, 0.9995], 601) / 601
    assert lo < noisy.chi2_red < hi


def test_two_views_are_refused():
    r, t = standard_poses(2)
    pts, pix, view = simulate(target_grid(), DEFAULT_CAMERA, r, t, 0.0)
    with pytest.raises(CalibrationError, match="at least 3"):
        closed_form(pts, pix, view, 2)


def test_reader_on_zhangs_files():
    data = read_camera_csv(MODEL, VIEWS)
    assert data.views == ("1", "2", "3", "4", "5")
    assert data.n == 1280 and data.unit == "in"
    # the pattern spans 6.72222 in (0 .. 6.72222 in X and -6.72222 .. 0 in Y) = 17.07 cm
    assert np.ptp(data.points, axis=0) == pytest.approx([6.72222 * 0.0254] * 2, rel=1e-6)


def test_reader_refuses_an_unknown_id(tmp_path):
    views = tmp_path / "v.csv"
    views.write_text(VIEWS.read_text().replace("\n1,7,", "\n1,999,", 1))
    with pytest.raises(InputError, match=r"row 8, column 'id': '999' is not a point"):
        read_camera_csv(MODEL, views)


def _zhang(distortion):
    data = read_camera_csv(MODEL, VIEWS)
    inch = 0.0254
    return calibrate(data.points / inch, data.pixels, data.view, 5, distortion)


def test_zhangs_published_calibration_with_radial_distortion():
    """Zhang's published result for his five views with two radial terms (the file
    calibration-result-zhang-withdistortion.txt beside his data, tests/data/camera/README.md):
    alpha 832.5, gamma 0.204494, beta 832.53, u0 303.959, v0 206.585, k1 -0.228601,
    k2 0.190353; agreement to the printed digits."""
    c = _zhang(("k1", "k2"))
    p = c.params
    assert p["f"] == pytest.approx(832.5, abs=0.05)
    assert p["f"] * (1 + p["a"]) == pytest.approx(832.53, abs=0.005)
    assert p["gamma"] == pytest.approx(0.204494, abs=5e-6)
    assert p["cx"] == pytest.approx(303.959, abs=5e-4)
    assert p["cy"] == pytest.approx(206.585, abs=5e-4)
    assert p["k1"] == pytest.approx(-0.228601, abs=5e-6)
    assert p["k2"] == pytest.approx(0.190353, abs=5e-6)


def test_zhangs_published_calibration_without_distortion():
    """Zhang's result without distortion for the same data (all-calibration-results.txt):
    867.307 0.05411 867.194 299.159 218.676 (alpha gamma beta u0 v0). gamma, u0, v0 agree to
    the printed digits; alpha and beta come out 0.0014 and 0.0012 px larger (867.3084,
    867.1952), 3e-4 of their sigma (5.0 px): along the focal length the pinhole's cost is flat
    (it trades against the views' distances), and an optimiser stopped that close to the
    minimum prints these digits. Tolerance 0.002 px for those two."""
    p = _zhang(()).params
    assert p["f"] == pytest.approx(867.307, abs=2e-3)
    assert p["gamma"] == pytest.approx(0.05411, abs=5e-5)
    assert p["f"] * (1 + p["a"]) == pytest.approx(867.194, abs=2e-3)
    assert p["cx"] == pytest.approx(299.159, abs=5e-4)
    assert p["cy"] == pytest.approx(218.676, abs=5e-4)
