"""The camera problem's parts by hand: residuals against pixels shifted by a known amount from
noise-free views, the report's radial/tangential split, the pixel error left after a diagnosis
(a diagnosis written by hand), and the ``[errors]`` table it becomes."""

import math
import tomllib
from dataclasses import replace
from types import SimpleNamespace

import numpy as np
import pytest
from scipy import stats

from montecarlo.camera_calibration.simulate import DEFAULT_CAMERA
from montecarlo.discrepancy import camera_effects as ce
from montecarlo.tools import camera_acceptance as ca

GRID = 3
SIGMA = 0.25


@pytest.fixture(scope="module")
def exact():
    """Noise-free views of a 3 x 3 target (5 views) and the true parameters."""
    data = ca.views_data(DEFAULT_CAMERA, 0.0, 0, GRID)
    _, r, t = ca.design(GRID)
    truth = dict(DEFAULT_CAMERA)
    for v in range(r.shape[0]):
        for j, a in enumerate("xyz"):
            truth[f"r{a}_{v + 1}"], truth[f"t{a}_{v + 1}"] = float(r[v, j]), float(t[v, j])
    return data, truth


def _shifted(data):
    """Pixels moved by (0.5 + 0.01 i, -0.25 i / n) at observation i: the residuals at the truth."""
    n = data.n
    shift = np.stack([0.5 + 0.01 * np.arange(n), -0.25 * np.arange(n) / n], axis=1)
    return replace(data, pixels=data.pixels + shift), shift


def test_units_of_the_parameters_in_reports():
    assert ce.display_unit("f") == ("px", 1.0) and ce.display_unit("gamma") == ("px", 1.0)
    assert ce.display_unit("k3") == ("1", 1.0) and ce.display_unit("a") == ("1", 1.0)
    assert ce.display_unit("rz_4") == ("rad", 1.0) and ce.display_unit("ty_2") == ("m", 1.0)


def test_base_effect_is_the_pinhole_and_every_pose():
    base = ce.base_effect(2)
    assert base.name == "pinhole"
    assert base.parameters == ("f", "cx", "cy", "rx_1", "ry_1", "rz_1", "tx_1", "ty_1",
                               "tz_1", "rx_2", "ry_2", "rz_2", "tx_2", "ty_2", "tz_2")
    assert base.steps == (1e-3,) * 3 + (1e-7,) * 12
    assert all(b == (-np.inf, np.inf) for b in base.bounds)
    assert base.description == "focal length, principal point [px], pose of each view [rad, m]"


def test_residuals_are_the_pixel_shifts_over_sigma_in_one_and_in_a_batch(exact):
    """At the true parameters the whitened residuals are the known shifts / sigma, u and v of
    each observation in turn; a batch of parameter vectors gives one row per vector (the
    truth twice and a 1 px larger focal length, which moves every point)."""
    data, truth = exact
    moved, shift = _shifted(data)
    problem = ce.camera_problem(moved, SIGMA)
    np.testing.assert_allclose(problem.residuals(truth), shift.ravel() / SIGMA, atol=1e-9)
    batch = {k: np.array([[v], [v], [v + (1.0 if k == "f" else 0.0)]]) for k, v in truth.items()}
    rows = problem.residuals(batch)
    assert rows.shape == (3, 2 * data.n)
    np.testing.assert_allclose(rows[0], shift.ravel() / SIGMA, atol=1e-9)
    np.testing.assert_allclose(rows[1], rows[0], atol=0)
    longer = problem.residuals({**truth, "f": truth["f"] + 1.0})
    np.testing.assert_allclose(rows[2], longer, atol=1e-12)
    assert np.abs(rows[2] - rows[0]).min() >= 0.0 and np.abs(rows[2] - rows[0]).max() > 0.1
    # the start is Zhang's closed form: on noise-free data, the truth, every base parameter
    start = ce.camera_problem(data, SIGMA).start
    assert set(start) == set(ce.base_effect(5).parameters)
    for name, value in truth.items():
        assert start[name] == pytest.approx(value, rel=1e-6, abs=1e-9), name
    assert problem.system == "camera" and problem.base.parameters[:3] == ("f", "cx", "cy")
    assert problem.candidates == ce.CANDIDATES and problem.unavailable == {}
    assert problem.separating_data == ce.SEPARATING_DATA
    assert problem.requires == {"radial_k2": "radial_k1", "radial_k3": "radial_k2"}


def test_each_corner_is_an_observation_named_view_slash_id(exact):
    data, _ = exact
    problem = ce.camera_problem(data, SIGMA)
    assert len(problem.observations) == data.n == 5 * GRID * GRID
    # the data row, 1-based, as every system's (the views file's line is one more)
    assert problem.observations[0] == ("1/1", 1, (0, 1))
    assert problem.observations[GRID * GRID + 1] == ("2/2", GRID * GRID + 2,
                                                     (2 * GRID * GRID + 2, 2 * GRID * GRID + 3))


def test_raw_residuals_and_the_radial_split_of_the_report(exact):
    """Raw residuals in pixels (not whitened); along the image radius from the principal
    point and across it (counter-clockwise positive in u, v): a residual (1, 0) at a point
    straight right of the principal point is (along 1, across 0), at a point straight below
    (larger v) it is (0, -1)."""
    data, truth = exact
    moved, shift = _shifted(data)
    np.testing.assert_allclose(ce.raw_residuals(moved, truth), shift, atol=1e-9)
    view = ce.report_view(data, SIGMA)
    assert view.system == "camera" and view.components == ("u", "v")
    np.testing.assert_allclose(view.raw_residuals(truth), 0.0, atol=1e-9)
    label, radius, (names, radial) = view.axes[0]
    assert label == "distance from the principal point [px]"
    assert names == ("radial", "tangential")
    centre = np.array([truth["cx"], truth["cy"]])
    np.testing.assert_allclose(radius, np.hypot(*(data.pixels - centre).T), atol=1e-6)
    assert [a[0] for a in view.axes[1:]] == ["image column u [px]", "image row v [px]"]
    np.testing.assert_array_equal(view.axes[1][1], data.pixels[:, 0])
    np.testing.assert_array_equal(view.axes[2][1], data.pixels[:, 1])
    off = radius > 1.0  # the target's centre images onto the principal point in every view
    assert (~off).sum() == 5
    outward = (data.pixels - centre)[off] / radius[off, None]
    res = np.zeros((data.n, 2))
    res[:, 0] = 1.0
    split = radial(res)[off]
    np.testing.assert_allclose(split[:, 0], outward[:, 0], atol=1e-6)
    np.testing.assert_allclose(split[:, 1], -outward[:, 1], atol=1e-6)
    res = np.stack([np.zeros(data.n), np.full(data.n, 2.0)], axis=1)
    np.testing.assert_allclose(radial(res)[off], 2.0 * np.stack([outward[:, 1], outward[:, 0]],
                                                                1), atol=1e-6)
    assert view.base_physics == {"pixel_sigma_px": SIGMA}
    assert view.rms_unit == "px" and view.rms_scale == 1.0 and view.study_params(None) == {}
    assert view.study_system == ""  # no study system simulates camera data sets


def _diagnosis(data, params, n_names, flagged=(), tests=()):
    observations = tuple((f"{data.views[data.view[i]]}/{data.point_id[i]}", i + 2,
                          (2 * i, 2 * i + 1)) for i in range(data.n))
    return SimpleNamespace(
        after=SimpleNamespace(params=params, names=tuple(f"p{i}" for i in range(n_names))),
        outliers=[SimpleNamespace(name=f"outlier:{observations[i][0]}") for i in flagged],
        problem=SimpleNamespace(observations=observations),
        steps=[SimpleNamespace(tests=list(tests))])


def _test(name, status, mdb, projected):
    return SimpleNamespace(name=name, status=status, mdb=mdb, projected=projected)


def test_pixel_error_by_hand(exact):
    """45 corners, residual u = 0.5 + 0.01 i and v = -0.25 i / 45 (i = 0..44) at the truth;
    corners 3 and 7 flagged and left out. N = 2 * 43 coordinates, 33 parameters, 2 flagged:
    scale sqrt(86 / (86 - 33 + 4)) = sqrt(86 / 57). A distortion candidate's largest image
    displacement at its MDB: projected column (3, 4) at one corner, times sigma 0.25 and MDB 2:
    5 * 0.25 * 2 = 2.5 px; a larger one of a candidate that is not distortion (skew) or is
    not testable does not count."""
    data, truth = exact
    moved, shift = _shifted(data)
    n = data.n
    keep = [i for i in range(n) if i not in (3, 7)]
    su = math.sqrt(sum(shift[i, 0] ** 2 for i in keep) / len(keep))
    sv = math.sqrt(sum(shift[i, 1] ** 2 for i in keep) / len(keep))
    scale = math.sqrt(86 / 57)

    def column(at, u, v):
        col = np.zeros((2 * n, 1))
        col[2 * at], col[2 * at + 1] = u, v
        return col

    tests = [
        _test("radial_k1", "testable", {"k1": 2.0}, column(5, 3.0, 4.0)),
        _test("radial_k2", "undetectable", {"k2": 1.0}, column(6, 1.0, 1.0)),
        _test("skew", "testable", {"gamma": 100.0}, column(5, 3.0, 4.0)),
        _test("radial_k3", "absorbed", {"k3": 100.0}, column(5, 3.0, 4.0)),
        _test("tangential", "unavailable", {"p1": 100.0, "p2": 1.0},
              np.hstack([column(5, 3.0, 4.0)] * 2)),
    ]
    d = _diagnosis(moved, truth, 33, flagged=(3, 7), tests=tests)
    out = ce.pixel_error(d, moved, SIGMA)
    assert out["sigma_u"] == pytest.approx(su * scale, rel=1e-9)
    assert out["sigma_v"] == pytest.approx(sv * scale, rel=1e-9)
    assert out["distortion_bound"] == pytest.approx(2.5, rel=1e-12)
    assert out["distortion_source"] == "radial_k1"
    # the second parameter of a two-parameter candidate, and the larger of two candidates
    tests.append(_test("tangential", "testable", {"p1": 1.0, "p2": 4.0},
                       np.hstack([column(1, 1.0, 0.0), column(2, 0.0, 3.0)])))
    tests.pop(4)
    out = ce.pixel_error(_diagnosis(moved, truth, 33, tests=tests), moved, SIGMA)
    assert out["distortion_bound"] == pytest.approx(3.0 * 0.25 * 4.0, rel=1e-12)
    assert out["distortion_source"] == "tangential"
    scale0 = math.sqrt(2 * n / (2 * n - 33))
    assert out["sigma_u"] == pytest.approx(
        math.sqrt(np.mean(shift[:, 0] ** 2)) * scale0, rel=1e-9)
    # an undetectable candidate counts as well: 2 px at corner 9 (0, 8) * 0.25 * 1 beats 1.5
    tests = [_test("radial_k1", "testable", {"k1": 1.0}, column(5, 3.0, 4.0) * 1.2),
             _test("radial_k3", "undetectable", {"k3": 1.0}, column(9, 0.0, 8.0))]
    out = ce.pixel_error(_diagnosis(moved, truth, 33, tests=tests), moved, SIGMA)
    assert out["distortion_bound"] == pytest.approx(2.0, rel=1e-12)
    assert out["distortion_source"] == "radial_k3"
    # nothing testable: no bound, no source; an MDB of no parameters or no column is skipped
    none = [_test("radial_k1", "testable", {}, column(5, 3.0, 4.0)),
            _test("radial_k2", "testable", {"k2": 1.0}, None)]
    out = ce.pixel_error(_diagnosis(moved, truth, 33, tests=none), moved, SIGMA)
    assert out["distortion_bound"] == 0.0 and out["distortion_source"] is None


def test_pixel_error_scale_never_divides_by_zero(exact):
    data, truth = exact
    moved, shift = _shifted(data)
    out = ce.pixel_error(_diagnosis(moved, truth, 10 * data.n), moved, SIGMA)
    assert out["sigma_u"] == pytest.approx(math.sqrt(np.mean(shift[:, 0] ** 2))
                                           * math.sqrt(2 * data.n), rel=1e-9)


def test_errors_toml_folds_the_bound_in_by_variance():
    """sigma = sqrt(max(0.3, 0.4)^2 + 0.6^2 / 3) = sqrt(0.16 + 0.12) = 0.52915 px."""
    text = ce.errors_toml({"sigma_u": 0.3, "sigma_v": 0.4, "distortion_bound": 0.6,
                           "distortion_source": "radial_k2"}, "views.csv", 0.25,
                          ["radial_k1", "skew"])
    assert tomllib.loads(text) == {"errors": {"pixel_px": {"dist": "normal",
                                                           "sigma": 0.52915}}}
    assert math.sqrt(0.28) == pytest.approx(0.52915, abs=5e-6)
    assert text.splitlines() == [
        "# Pixel error left by the camera calibration of views.csv",
        "# (montecarlo diagnose camera, stated pixel sigma 0.25 px; final model: radial_k1, "
        "skew)",
        "# residual sigma per axis: u 0.3000 px, v 0.4000 px",
        "# remaining distortion, largest image displacement undetected at its MDB: +-0.6000 px "
        "(radial_k2), a bounded source",
        "# one pixel source per axis in a ground study: the bound folded in by variance, "
        "sigma = sqrt(max(su, sv)^2 + B^2/3)",
        "[errors]",
        'pixel_px = { dist = "normal", sigma = 0.52915 }',
        "# pixel_distortion_bound_px = 0.6"]
    assert text.endswith("\n")
    other = ce.errors_toml({"sigma_u": 0.5, "sigma_v": 0.1, "distortion_bound": 0.0,
                            "distortion_source": None}, "x", 0.2, [])
    assert tomllib.loads(other)["errors"]["pixel_px"]["sigma"] == 0.5
    assert "+-0.0000 px (none tested)" in other


def test_what_a_view_offset_leaves_against_opencvs_jacobian():
    """A view's corners all shifted alike: the noncentrality the refitted pinhole leaves,
    against the same projection computed from OpenCV's own Jacobian of ``projectPoints``
    (focal length as fx + fy, principal point, each view's rotation vector and translation),
    and the Neyman-Pearson bound of any test of it (closed form: Phi(sqrt(lam) - z)). The
    first view faces the target (no tilt): there a shift is exactly a translation, lambda 0."""
    cv2 = pytest.importorskip("cv2")
    sigma, grid = 0.2, 16
    points, r, t = ca.design(grid)
    K = np.array([[DEFAULT_CAMERA["f"], 0, DEFAULT_CAMERA["cx"]],
                  [0, DEFAULT_CAMERA["f"], DEFAULT_CAMERA["cy"]], [0, 0, 1.0]])
    obj = np.column_stack([points, np.zeros(len(points))])
    n, v = len(points), r.shape[0]
    A = np.zeros((2 * n * v, 3 + 6 * v))
    for k in range(v):
        _, jac = cv2.projectPoints(obj, r[k], t[k], K, np.zeros(5))
        rows = slice(2 * n * k, 2 * n * (k + 1))
        A[rows, 0] = jac[:, 6] + jac[:, 7]
        A[rows, 1:3] = jac[:, 8:10]
        A[rows, 3 + 6 * k:9 + 6 * k] = jac[:, 0:6]
    q = np.linalg.qr(A / sigma)[0]
    for view in range(v):
        shift = np.repeat(np.arange(n * v) // n == view, 2) / sigma
        left = shift - q @ (q.T @ shift)
        assert ca.offset_noncentrality(sigma, grid, view, 1.0) == pytest.approx(
            float(left @ left), rel=1e-6, abs=1e-9)
    assert ca.offset_noncentrality(sigma, grid, 0, 1.0) < 1e-9
    # the clustering's shift test: what the pinhole leaves of a shift of each view's u and of
    # its v (rank from OpenCV's Jacobian); its F test at alpha / 2 has power 0.8 at the MDB
    cells = np.zeros((2 * n * v, 2 * v))
    for k in range(2 * v):
        cells[2 * n * (k // 2) + k % 2:2 * n * (k // 2 + 1):2, k] = 1.0
    rank = int(np.sum(np.linalg.svd(cells - q @ (q.T @ cells), compute_uv=False)
                      > 1e-3 * math.sqrt(n)))
    dof = 2 * n * v - A.shape[1] - rank
    left = np.repeat(np.arange(n * v) // n == ca.VIEW, 2) / sigma
    left -= q @ (q.T @ left)
    power = stats.ncf.sf(stats.f.isf(0.005, rank, dof), rank, dof,
                         float(left @ left) * ca.offset_mdb(sigma, grid) ** 2)
    assert (rank, power) == (5, pytest.approx(0.8, abs=1e-6))
    lam = ca.offset_noncentrality(sigma, grid)
    assert 3.0 < lam < 4.5  # a 1 px shift is 5 sigma a coordinate; the pose takes up 98 %
    assert ca.most_powerful_rate(lam, 0.01) == pytest.approx(
        0.5 * math.erfc((2.3263478740408408 - math.sqrt(lam)) / math.sqrt(2)), rel=1e-9)
    assert ca.most_powerful_rate(0.0, 0.01) == pytest.approx(0.01)
