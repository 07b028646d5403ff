"""Ground static-base calibration of seed 000 (eqs. 6-16): forward model, solver, invalid paths."""

import numpy as np
import pytest
from hypothesis import assume, given, settings
from hypothesis import strategies as st
from scipy.spatial.transform import Rotation

from montecarlo.geometry import camera as cam
from montecarlo.geometry.camera import Camera
from montecarlo.geometry.invalid import Invalid
from montecarlo.geometry.rotations import mounting_matrix
from montecarlo.seed000 import ground

CAMERA = Camera.from_degrees(90.0, 90.0, 512, 512)
TRUE = tuple(np.radians([30.0, 20.0, 10.0]))


def _independent_pixels(angles, r_b, camera):
    """Pixels through scipy's Rotation and the tangent-plane form: no code shared with ground."""
    C_ba = Rotation.from_euler("ZXY", np.stack(angles, -1)).inv().as_matrix()
    u = np.einsum("...ij,...j->...i", C_ba, r_b)
    return np.stack([camera.k_x * u[..., 0] / u[..., 1], camera.k_z * u[..., 2] / u[..., 1]], -1), u


def test_target_positions_follow_section_1_3():
    r_a, r_b = ground.target_positions(100.0, 2.0, dx=0.1, dy=-0.1, dh1=0.05, dh=0.001)
    np.testing.assert_allclose(r_a, [0.1, 99.9, 0.05])
    np.testing.assert_allclose(r_b, [0.1, 99.9, 2.051])


def test_forward_model_matches_independent_projection():
    """Eqs. (15)-(16) + (4) equal scipy's rotation followed by the pinhole tangent-plane map."""
    rng = np.random.default_rng(15)
    n = 5000
    angles = tuple(rng.uniform(-0.6, 0.6, (3, n)))
    r_b = np.stack([rng.uniform(-5, 5, n), rng.uniform(20, 500, n), rng.uniform(-5, 5, n)], -1)
    pix, flags = ground.observe_target(mounting_matrix(*angles), r_b, CAMERA)
    ref, _ = _independent_pixels(angles, r_b, CAMERA)
    seen = np.all(np.abs(ref) <= 256, axis=-1)
    assert np.array_equal(flags == 0, seen)
    assert np.array_equal(flags == Invalid.OUTSIDE_FOV, ~seen)
    np.testing.assert_allclose(pix, ref, rtol=1e-11, atol=1e-9)


def test_forward_model_flags_target_behind():
    pix, flags = ground.observe_target(mounting_matrix(np.pi, 0.0, 0.0), [0.0, 50.0, 0.0], CAMERA)
    assert flags == Invalid.BEHIND_SENSOR
    assert np.isnan(pix).all()


def test_zero_error_round_trip_100k_cases():
    """The literal solver: no error in, true angles out to <= 1e-9 rad, over >= 100,000 cases.

    Mounting angles within +-80 deg, L 10-1000 m, H 0.5-10 m, fields of view 10-170 deg and
    64-4096 pixels, all drawn per case. Cases whose targets fall outside the field of view or
    behind the sensor (checked independently with scipy's Rotation) must be flagged, never solved.
    """
    rng = np.random.default_rng(2)
    n = 400_000
    angles = tuple(rng.uniform(-np.radians(80), np.radians(80), (3, n)))
    L = rng.uniform(10, 1000, n)
    H = rng.uniform(0.5, 10, n)
    camera = Camera(*np.radians(rng.uniform(10, 170, (2, n))), *rng.integers(64, 4097, (2, n)))
    solutions = ground.simulate(camera, angles, L, H)

    r_a, r_b = ground.target_positions(L, H)
    pix_a, u_a = _independent_pixels(angles, r_a, camera)
    pix_b, u_b = _independent_pixels(angles, r_b, camera)
    visible = ((u_a[:, 1] > 0) & (u_b[:, 1] > 0)
               & cam.in_field_of_view(*pix_a.T, camera) & cam.in_field_of_view(*pix_b.T, camera))
    assert visible.sum() >= 100_000
    for name, sol in solutions.items():
        assert np.array_equal(sol.valid, visible), name
        assert np.all(sol.invalid[~visible] & (Invalid.BEHIND_SENSOR | Invalid.OUTSIDE_FOV))
        err = np.abs(np.stack([sol.psi, sol.theta, sol.gamma]) - np.stack(angles))[:, visible]
        assert err.max() <= 1e-9, (name, err.max())
        assert np.isnan(sol.psi[~visible]).all()


@settings(max_examples=200, deadline=None)
@given(
    st.tuples(*[st.floats(-0.7, 0.7)] * 3),
    st.floats(10, 1000), st.floats(0.5, 10),
)
def test_eq11_recovers_columns_exactly(angles, L, H):
    """With exact pixels, eq. (11) gives columns 2 and 3 of C_b^a and eq. (12) gives alpha = 1."""
    C = mounting_matrix(*angles)
    wide = Camera.from_degrees(170, 170, 512, 512)
    r_a, r_b = ground.target_positions(L, H)
    pa, fa = ground.observe_target(C, r_a, wide)
    pb, fb = ground.observe_target(C, r_b, wide)
    assume(fa == 0 and fb == 0)
    for normalise in (False, True):
        sol = ground.solve_mounting(pa, pb, L, H, wide, normalise)
        np.testing.assert_allclose(sol.matrix(), C, atol=1e-10)


def test_normalisation_helps_on_average_with_common_pixel_error():
    """Seed 000, section 1.4: 'normalisation clearly improves accuracy' (Table 1, every row)."""
    rng = np.random.default_rng(13)
    n = 20000
    e = rng.uniform(-1, 1, (n, 2))
    sols = ground.simulate(CAMERA, TRUE, 50.0, 1.0, dx=rng.uniform(-.1, .1, n),
                           dy=rng.uniform(-.1, .1, n), dh1=rng.uniform(-.1, .1, n),
                           dh=rng.uniform(-.005, .005, n), pixel_error_a=e, pixel_error_b=e)
    raw = ground.solution_metrics(sols["raw"], TRUE)["rotation_angle"]
    norm = ground.solution_metrics(sols["normalised"], TRUE)["rotation_angle"]
    assert np.mean(norm) < np.mean(raw)


@pytest.mark.parametrize(
    ("pix_a", "pix_b", "L", "H", "normalise", "reason"),
    [
        ([np.nan, 0.0], [0.0, 5.0], 50.0, 1.0, True, Invalid.NAN_INPUT),
        ([0.0, 0.0], [0.0, 5.0], np.inf, 1.0, True, Invalid.NAN_INPUT),
        ([0.0, 0.0], [0.0, 5.0], 50.0, 0.0, True, Invalid.ZERO_HEIGHT),
        ([0.0, 0.0], [0.0, 5.0], 0.0, 1.0, True, Invalid.RANGE_NOT_POSITIVE),
        ([0.0, 0.0], [0.0, 300.0], 50.0, 1.0, True, Invalid.OUTSIDE_FOV),
        ([0.0, 0.0], [0.0, 100.0], 50.0, 1.0, False, Invalid.PITCH_OUT_OF_RANGE),
        ([0.0, 0.0], [0.0, -100.0], 50.0, 1.0, True, Invalid.ROLL_OUT_OF_RANGE),
        ([-250.0, 0.0], [-250.0, 60.0], 50.0, 1.0, False, Invalid.YAW_OUT_OF_RANGE),
    ],
)
def test_invalid_geometry_is_flagged_not_solved(pix_a, pix_b, L, H, normalise, reason):
    sol = ground.solve_mounting(pix_a, pix_b, L, H, CAMERA, normalise)
    assert sol.invalid == reason
    assert np.isnan([sol.psi, sol.theta, sol.gamma]).all()


def test_flags_are_per_trial():
    pix_b = np.array([[0.0, 5.0], [np.nan, 5.0], [0.0, 5.0]])
    sol = ground.solve_mounting([0.0, 0.0], pix_b, 50.0, [1.0, 1.0, 0.0], CAMERA)
    assert list(sol.invalid) == [0, Invalid.NAN_INPUT, Invalid.ZERO_HEIGHT]
    assert np.isfinite(sol.psi[0]) and np.isnan(sol.psi[1:]).all()


def test_simulate_reports_forward_reasons_first():
    """A target out of view is reported as OUTSIDE_FOV, not as whatever the solver then meets."""
    sols = ground.simulate(CAMERA, (np.radians(60.0), 0.0, 0.0), 50.0, 1.0)
    assert all(s.invalid == Invalid.OUTSIDE_FOV for s in sols.values())


def test_simulate_rejects_unknown_solver():
    with pytest.raises(ValueError, match="unknown solver"):
        ground.simulate(CAMERA, TRUE, 50.0, 1.0, solvers=("raw", "fancy"))


def test_equivalent_angles_by_hand_and_nan_behind_the_focal_plane():
    """Identity mounting, by hand: (-1, 1, 0) is seen at psi = arctan(1) = pi/4, theta = 0;
    (0, 3, 4) at psi = 0, theta = arcsin(4/5) = 0.92729522. A target in the focal plane
    (y = 0), behind it, or at the focus itself has float NaN angles and is not in front,
    silently (the test run turns warnings into errors)."""
    r_b = np.array([[-1.0, 1.0, 0.0], [0.0, 3.0, 4.0], [1.0, 0.0, 0.0], [0.0, -5.0, 1.0],
                    [0.0, 0.0, 0.0]])
    psi, theta, front = ground.equivalent_angles_of_target(np.eye(3), r_b)
    assert psi.dtype == theta.dtype == np.float64
    np.testing.assert_array_equal(front, [True, True, False, False, False])
    np.testing.assert_allclose(psi[:2], [np.pi / 4, 0.0], atol=1e-15)
    np.testing.assert_allclose(theta[:2], [0.0, 0.92729522], atol=1e-8)
    assert np.isnan(psi[2:]).all() and np.isnan(theta[2:]).all()


def test_solver_broadcasts_every_input_and_normalises_by_default():
    """Exact pixels of four geometries (L 0.9, 50, 100 and 400 m; H 0.2, 2, 3 and 5 m): solving
    them as one batch whichever single input carries the batch axis, the others scalar, gives
    each geometry's own solution, which is the true mounting (a range below 1 m is a valid
    geometry). The default solver is the normalised one (eqs. (12)-(13))."""
    C = mounting_matrix(*np.radians([30.0, 20.0, 10.0]))
    L, H = np.array([0.9, 50.0, 100.0, 400.0]), np.array([0.2, 2.0, 3.0, 5.0])
    pix_a, pix_b = [], []
    for l_m, h_m in zip(L, H, strict=True):
        (a, b), _ = ground.observe_target(C, np.array([[0.0, l_m, 0.0], [0.0, l_m, h_m]]),
                                          CAMERA)
        pix_a.append(a)
        pix_b.append(b)
    pix_a, pix_b = np.array(pix_a), np.array(pix_b)
    for i in range(4):
        one = ground.solve_mounting(pix_a[i], pix_b[i], L[i], H[i], CAMERA)
        np.testing.assert_allclose(one.matrix(), C, atol=1e-9)
        for batch in ((pix_a, pix_b[i], L[i], H[i]), (pix_a[i], pix_b, L[i], H[i]),
                      (pix_a[i], pix_b[i], np.full(4, L[i]), H[i]),
                      (pix_a[i], pix_b[i], L[i], np.full(4, H[i]))):
            sol = ground.solve_mounting(*batch, CAMERA)
            assert sol.psi.shape == sol.invalid.shape == (4,)
            assert sol.invalid.dtype == np.uint16  # the flags are counted with bincount
            np.testing.assert_allclose(sol.psi[i], one.psi, atol=1e-12)
    raw = ground.solve_mounting(pix_a + 0.3, pix_b + 0.3, L, H, CAMERA, normalise=False)
    norm = ground.solve_mounting(pix_a + 0.3, pix_b + 0.3, L, H, CAMERA, normalise=True)
    default = ground.solve_mounting(pix_a + 0.3, pix_b + 0.3, L, H, CAMERA)
    np.testing.assert_array_equal(default.psi, norm.psi)
    assert np.all(default.valid) and not np.array_equal(raw.psi, norm.psi)
