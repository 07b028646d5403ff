"""Camera model of seed 000, eqs. (1)-(4): trigonometric and vector forms, round trips, limits."""

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from montecarlo.geometry import camera as cam
from montecarlo.geometry.camera import Camera

fov_deg = st.floats(1.0, 179.0)
pixels = st.integers(2, 8192)


def _camera(fy, fp, nx, nz):
    return Camera.from_degrees(fy, fp, nx, nz)


@given(fov_deg, fov_deg, pixels, pixels, st.floats(-0.5, 0.5), st.floats(-0.5, 0.5))
def test_pixel_angle_round_trip(fy, fp, nx, nz, ux, uz):
    """Eq. (4) inverts eq. (3) anywhere on the detector."""
    c = _camera(fy, fp, nx, nz)
    f_mx, f_mz = ux * nx, uz * nz
    psi, theta = cam.equivalent_angles_from_pixels(f_mx, f_mz, c)
    assert abs(psi) < np.pi / 2 and abs(theta) < np.pi / 2
    back = cam.pixels_from_equivalent_angles(psi, theta, c)
    np.testing.assert_allclose(back, (f_mx, f_mz), rtol=1e-12, atol=1e-9)


@given(fov_deg, fov_deg, pixels, pixels, st.floats(-0.5, 0.5), st.floats(-0.5, 0.5))
def test_vector_form_equals_trigonometric_form(fy, fp, nx, nz, ux, uz):
    """Direction from pixels: the direct vector form equals eq. (3) followed by R_M'^a."""
    c = _camera(fy, fp, nx, nz)
    f_mx, f_mz = ux * nx, uz * nz
    via_angles = cam.direction_from_equivalent_angles(
        *cam.equivalent_angles_from_pixels(f_mx, f_mz, c))
    direct = cam.direction_from_pixels(f_mx, f_mz, c)
    np.testing.assert_allclose(direct, via_angles, atol=1e-14)
    np.testing.assert_allclose(cam.pixels_from_direction(direct, c), (f_mx, f_mz),
                               rtol=1e-12, atol=1e-9)


def test_focal_plane_point_matches_eq2():
    """Eq. (1) puts N on the ray of eq. (2): x_N = -L tan psi_m, z_N = L tan theta_m / cos psi_m."""
    c = Camera.from_degrees(60.0, 40.0, 640, 480)
    rng = np.random.default_rng(0)
    f_mx, f_mz = rng.uniform(-320, 320, 50), rng.uniform(-240, 240, 50)
    L = 3.7
    point = cam.focal_plane_point(f_mx, f_mz, c, L)
    psi, theta = cam.equivalent_angles_from_pixels(f_mx, f_mz, c)
    np.testing.assert_allclose(point[:, 0], -L * np.tan(psi), rtol=1e-12)
    np.testing.assert_allclose(point[:, 1], L)
    np.testing.assert_allclose(point[:, 2], L * np.tan(theta) / np.cos(psi), rtol=1e-12)


def test_detector_edge_maps_to_half_field_of_view():
    """A pixel on the detector edge along an axis sees half the field of view."""
    c = Camera.from_degrees(70.0, 50.0, 1000, 800)
    psi, _ = cam.equivalent_angles_from_pixels(-500.0, 0.0, c)
    _, theta = cam.equivalent_angles_from_pixels(0.0, 400.0, c)
    assert psi == pytest.approx(np.radians(35.0), rel=1e-13)
    assert theta == pytest.approx(np.radians(25.0), rel=1e-13)


@pytest.mark.parametrize("fov_deg", [4.0, 2.0, 1.0, 0.5])
def test_small_angle_limit_of_eq3(fov_deg):
    """The approximation after eq. (3) has a relative error of order fov**2 (Taylor series).

    For tan(fov/2) = fov/2 (1 + fov**2/12 + ...) and arctan(t) = t (1 - t**2/3 + ...), with
    |t| <= fov/2 on the detector, the relative error is below fov**2/12 + fov**2/12 + fov**2/8.
    """
    c = Camera.from_degrees(fov_deg, fov_deg, 512, 512)
    f = np.linspace(-256, 256, 101)
    fx, fz = np.meshgrid(f, f)
    exact = np.stack(cam.equivalent_angles_from_pixels(fx, fz, c))
    approx = np.stack(cam.small_angle_equivalent_angles(fx, fz, c))
    fov = np.radians(fov_deg)
    bound = fov**2 * (1 / 12 + 1 / 12 + 1 / 8)
    err = np.abs(approx - exact)
    assert np.all(err <= bound * np.abs(exact) + 1e-15)
    # and it is not much smaller than that: the limit is really quadratic
    assert err.max() > 0.1 * bound * np.abs(exact).max()


def test_broadcasting_and_shapes():
    c = Camera.from_degrees(90.0, 90.0, 512, 512)
    f_mx = np.zeros((4, 1))
    f_mz = np.zeros((1, 3))
    psi, theta = cam.equivalent_angles_from_pixels(f_mx, f_mz, c)
    assert psi.shape == (4, 1) and theta.shape == (4, 3)
    assert cam.direction_from_pixels(f_mx, f_mz, c).shape == (4, 3, 3)
    per_trial = Camera.from_degrees([10.0, 170.0], 90.0, 512, [100, 200])
    assert cam.direction_from_pixels([1.0, 1.0], 0.0, per_trial).shape == (2, 3)


@pytest.mark.parametrize(
    "args",
    [(0.0, 90.0, 512, 512), (180.0, 90.0, 512, 512), (90.0, -1.0, 512, 512),
     (90.0, 90.0, 0, 512), (90.0, 90.0, 512, np.nan)],
)
def test_camera_rejects_impossible_parameters(args):
    with pytest.raises(ValueError, match=r"fov|pixel"):
        Camera.from_degrees(*args)


def test_field_of_view_and_front_checks():
    c = Camera.from_degrees(90.0, 90.0, 512, 256)
    assert cam.in_field_of_view(256.0, 128.0, c)
    assert not cam.in_field_of_view(256.01, 0.0, c)
    assert not cam.in_field_of_view(0.0, -128.5, c)
    assert not cam.in_field_of_view(np.nan, 0.0, c)
    assert list(cam.in_front([[0, 1, 0], [0, -1, 0], [1, 0, 0]])) == [True, False, False]


def test_focal_plane_point_by_hand_on_a_grid_and_at_the_default_distance():
    """Eq. (1) by hand for a 90 x 60 deg, 800 x 600 px camera: tan(45°) = 1 and
    tan(30°) = 0.57735, so pixel (400, 300) (the corner) is at (1, L, 0.57735) L; pixel
    (-200, 150) at (-0.5, 1, 0.288675) L. The default L is 1 (the focal distance's unit).
    A grid of pixels (2, 3) gives points of shape (2, 3, 3)."""
    c = Camera.from_degrees(90.0, 60.0, 800, 600)
    f_mx = np.array([[400.0, -200.0, 0.0], [0.0, 400.0, -400.0]])
    f_mz = np.array([[300.0, 150.0, 0.0], [-300.0, 0.0, 300.0]])
    point = cam.focal_plane_point(f_mx, f_mz, c)
    assert point.shape == (2, 3, 3)
    t = np.tan(np.radians(30.0))
    expected = np.array([[[1.0, 1.0, t], [-0.5, 1.0, t / 2], [0.0, 1.0, 0.0]],
                         [[0.0, 1.0, -t], [1.0, 1.0, 0.0], [-1.0, 1.0, t]]])
    np.testing.assert_allclose(point, expected, rtol=1e-12, atol=1e-15)


def test_direction_of_equivalent_angles_by_hand_for_a_batch():
    """R_M'^a = [-sin ψ cos θ, cos ψ cos θ, sin θ]: ψ = 90° points along -x (left), θ = 90°
    along +z, ψ = θ = 0 along y; a batch of n angles gives (n, 3)."""
    psi = np.radians([0.0, 90.0, 0.0, 30.0])
    theta = np.radians([0.0, 0.0, 90.0, 60.0])
    u = cam.direction_from_equivalent_angles(psi, theta)
    assert u.shape == (4, 3)
    expected = [[0.0, 1.0, 0.0], [-1.0, 0.0, 0.0], [0.0, 0.0, 1.0],
                [-0.25, np.sqrt(3.0) / 4.0, np.sqrt(3.0) / 2.0]]
    np.testing.assert_allclose(u, expected, atol=1e-15)


def test_camera_values_are_stored_as_floats_and_one_pixel_is_a_camera():
    """Integer pixel counts and fields of view are stored as Python floats (float arrays for
    one camera per trial); a single pixel
    across an axis is a (poor) camera, a count of zero is refused."""
    c = Camera(1, 1, 1, 640)
    assert all(type(getattr(c, n)) is float for n in ("fov_yaw", "fov_pitch", "n_x", "n_z"))
    assert c.k_x == pytest.approx(1.0 / (2.0 * np.tan(0.5)), rel=1e-15)
    per_trial = Camera(np.array([1, 2]), 1, np.array([512, 640]), 480)
    assert per_trial.fov_yaw.dtype == per_trial.n_x.dtype == np.float64
    with pytest.raises(ValueError, match="n_x"):
        Camera(1, 1, 0, 640)
