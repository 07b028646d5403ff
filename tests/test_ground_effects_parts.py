"""The ground problem's bookkeeping by hand: units, candidates and their availability,
observation names, the layout generator, the simulated noise, and the report's view. A
non-square camera (70 x 40 deg over 1600 x 900 px) throughout."""

import json
import math
from types import SimpleNamespace

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from montecarlo.discrepancy import ground_effects as ge
from montecarlo.errors import InputError
from montecarlo.geometry.camera import Camera
from montecarlo.io.ground_csv import GroundData
from montecarlo.units import MRAD, MRAD_PER_HOUR

WIDE = Camera.from_degrees(70.0, 40.0, 1600, 900)
MOUNT = {"psi": math.radians(-25.0), "theta": math.radians(8.0), "gamma": math.radians(-4.0)}


def test_units_at_the_edge_and_of_small_changes():
    assert ge.display_unit("psi") == ("deg", math.pi / 180.0)
    assert ge.display_unit("rho") == ("mrad", MRAD)
    assert ge.display_unit("w_theta") == ("mrad/h", MRAD_PER_HOUR)
    assert ge.display_unit("c_z") == ("px", 1.0) and ge.display_unit("l_y") == ("m", 1.0)
    assert ge.display_unit("dk") == ("1", 1.0)
    assert ge.display_unit("gamma_shift_S2") == ("mrad", MRAD)  # session shifts
    assert ge.shift_unit("psi") == ("mrad", MRAD) and ge.shift_unit("gamma") == ("mrad", MRAD)
    assert ge.shift_unit("b_x") == ("m", 1.0)


def test_fewest_targets_and_the_candidates_available():
    """3 angles + 3 of the largest candidate + 1 degree of freedom = 7 values, 2 per target:
    4 targets. Without times no drift, with one session no session shift; two sessions S1,
    S2 give the shifts of S2 only (S1 is the reference), bounded by 0.05 rad."""
    assert ge.min_targets() == 4
    one = GroundData(("A", "B"), np.ones((2, 3)), np.zeros((2, 2)))
    candidates, unavailable = ge.candidates_for(one)
    assert unavailable == {"drift": "no t_s column", "session_shift": "fewer than two sessions"}
    assert candidates[:-1] == ge._CANDIDATES
    assert candidates[-1].name == "session_shift" and candidates[-1].parameters == ()
    two = GroundData(("A", "B", "C"), np.ones((3, 3)), np.zeros((3, 2)), np.arange(3.0),
                     ("S1", "S2", "S1"))
    candidates, unavailable = ge.candidates_for(two)
    assert unavailable == {}
    shift = candidates[-1]
    assert shift.parameters == ("psi_shift_S2", "theta_shift_S2", "gamma_shift_S2")
    assert shift.bounds == ((-0.05, 0.05),) * 3 and shift.steps == (1e-6,) * 3
    assert shift.description == "mounting angles shifted in each session after the first [rad]"
    assert shift.direction == (1.0, 1.0, 1.0)
    assert ge.TRUTH_KEYS[:3] == ("k1", "p1", "p2") and "dk" in ge.TRUTH_KEYS


def test_observation_names_carry_the_session_and_the_row_where_a_name_repeats():
    data = GroundData(("A", "B", "A"), np.ones((3, 3)), np.zeros((3, 2)))
    assert ge.observations(data) == (("A (row 1)", 1, (0, 1)), ("B", 2, (2, 3)),
                                     ("A (row 3)", 3, (4, 5)))
    data = GroundData(("A", "B", "A"), np.ones((3, 3)), np.zeros((3, 2)), None,
                      ("S1", "S1", "S2"))
    assert ge.observations(data) == (("A@S1", 1, (0, 1)), ("B@S1", 2, (2, 3)),
                                     ("A@S2", 3, (4, 5)))


def test_field_layout_by_hand():
    """A 3 x 2 grid over 80 % of the field: tangents 0.8 tan(35°) (-1, 0, 1) across and
    0.8 tan(20°) (-1, 1) up; ranges alternate like a checkerboard (i + j even: the first);
    every target at its range along its line of sight; names T01...; times a permutation of
    (k + 0.5) 600 s over 3600 s, the second session 3600 s later with the same positions."""
    layout = ge.field_layout(WIDE, MOUNT, (40.0, 90.0), (3, 2), 0.8, 3600.0, sessions=2, rng=7)
    assert layout.targets == tuple(f"T{i:02d}" for i in range(1, 7)) * 2
    assert layout.session == ("S1",) * 6 + ("S2",) * 6
    C = Rotation.from_euler("ZXY", [MOUNT["psi"], MOUNT["theta"], MOUNT["gamma"]]).as_matrix()
    r_a = layout.positions[:6] @ C  # frame a = C^T r_b in scipy's active convention
    tx, tz = r_a[:, 0] / r_a[:, 1], r_a[:, 2] / r_a[:, 1]
    ax, az = 0.8 * math.tan(math.radians(35.0)), 0.8 * math.tan(math.radians(20.0))
    np.testing.assert_allclose(tx, [-ax, -ax, 0.0, 0.0, ax, ax], atol=1e-12)
    np.testing.assert_allclose(tz, [-az, az] * 3, atol=1e-12)
    np.testing.assert_allclose(np.linalg.norm(layout.positions[:6], axis=1),
                               [40.0, 90.0, 90.0, 40.0, 40.0, 90.0], rtol=1e-12)
    np.testing.assert_array_equal(layout.positions[6:], layout.positions[:6])
    np.testing.assert_allclose(np.sort(layout.t[:6]), (np.arange(6) + 0.5) * 600.0)
    np.testing.assert_allclose(np.sort(layout.t[6:]), (np.arange(6) + 0.5) * 600.0 + 3600.0)
    assert not np.array_equal(layout.t[6:] - 3600.0, layout.t[:6])  # a new order per session
    assert layout.pixels.shape == (12, 2)
    np.testing.assert_array_equal(layout.pixels, 0.0)
    single = ge.field_layout(WIDE, MOUNT, (40.0,), (2, 2), rng=1)
    assert single.session is None and single.n == 4 and single.t.max() < 3600.0


def test_field_layout_defaults():
    """6 x 6 targets over 80 % of the field at 50 and 100 m, one hour, one session, seed 0."""
    layout = ge.field_layout(WIDE, MOUNT)
    explicit = ge.field_layout(WIDE, MOUNT, (50.0, 100.0), (6, 6), 0.8, 3600.0, 1, rng=0)
    np.testing.assert_array_equal(layout.positions, explicit.positions)
    np.testing.assert_array_equal(layout.t, explicit.t)
    assert layout.session is None and layout.n == 36
    np.testing.assert_allclose(np.sort(layout.t), (np.arange(36) + 0.5) * 100.0)
    r = np.linalg.norm(layout.positions, axis=1)
    assert set(np.round(r, 9)) == {50.0, 100.0}
    C = Rotation.from_euler("ZXY", [MOUNT["psi"], MOUNT["theta"], MOUNT["gamma"]]).as_matrix()
    r_a = layout.positions @ C
    assert np.max(r_a[:, 0] / r_a[:, 1]) == pytest.approx(0.8 * math.tan(math.radians(35.0)))


def test_simulated_noise_has_the_stated_sigmas():
    """Pixels: predict_pixels of the true positions + N(0, 0.4^2); surveyed positions: true +
    N(0, 0.03^2). 2 x 36 pixel and 3 x 36 position values per set, 20 sets: the variances are
    known to sqrt(2/1440) = 3.7 % and sqrt(2/2160) = 3.0 %; 15 % is 4 of those."""
    layout = ge.field_layout(WIDE, MOUNT, rng=2)
    exact = ge.predict_pixels(MOUNT, layout, WIDE)
    rng = np.random.default_rng(9)
    dp, dr = [], []
    for _ in range(20):
        data = ge.simulate(layout, WIDE, MOUNT, 0.4, 0.03, rng)
        dp.append(data.pixels - exact)
        dr.append(data.positions - layout.positions)
        assert data.targets == layout.targets and data.t is layout.t
    assert np.mean([np.mean(x ** 2) for x in dp]) == pytest.approx(0.16, rel=0.15)
    assert np.mean([np.mean(x ** 2) for x in dr]) == pytest.approx(9e-4, rel=0.15)
    # independent per coordinate: within one set the spread is the stated one too
    assert np.var(dr[0]) == pytest.approx(9e-4, rel=0.5)
    assert np.var(dp[0]) == pytest.approx(0.16, rel=0.5)
    same = ge.simulate(layout, WIDE, MOUNT, 0.4, 0.03, 5)
    np.testing.assert_array_equal(same.pixels, ge.simulate(layout, WIDE, MOUNT, 0.4, 0.03,
                                                           5).pixels)


def test_simulation_uses_the_stated_refraction():
    """At 1 km with k = 1 refraction cancels curvature: the pixels are those of the positions
    with no height shift at all; the standard k = 0.13 lowers them by 0.87 L^2 / (2 R)."""
    far = ge.field_layout(WIDE, MOUNT, (1000.0,), (2, 2), rng=1)
    data = ge.simulate(far, WIDE, MOUNT, 0.0, 0.0, 1, refraction=1.0)
    no_shift = ge.predict_pixels({**MOUNT, "dk": 1.0 - ge.STANDARD_REFRACTION}, far, WIDE)
    np.testing.assert_allclose(data.pixels, no_shift, atol=1e-9)
    np.testing.assert_allclose(ge.raw_residuals(data, WIDE, MOUNT, refraction=1.0), 0.0,
                               atol=1e-9)
    truth = {**MOUNT, "k1": 0.01}
    problem = ge.exact_problem(far, WIDE, truth, 0.5, 0.0, refraction=1.0)
    np.testing.assert_allclose(problem.residuals(truth), 0.0, atol=1e-9)
    # whitened by the pixel sigma alone (no survey error): (truth - pinhole) / 0.5
    k1 = ge.predict_pixels({**MOUNT, "k1": 0.01, "dk": 0.87}, far, WIDE)
    pinhole = ge.predict_pixels({**MOUNT, "dk": 0.87}, far, WIDE)
    np.testing.assert_allclose(problem.residuals(MOUNT), ((k1 - pinhole) / 0.5).ravel(),
                               atol=1e-8)
    assert np.abs(problem.residuals(MOUNT)).max() > 0.1
    two = ge.field_layout(WIDE, MOUNT, (1000.0,), (2, 2), sessions=2, rng=1)
    problem = ge.exact_problem(two, WIDE, MOUNT, 0.5, 0.0)
    assert problem.unavailable == {}
    assert problem.candidates[-1].parameters == ("psi_shift_S2", "theta_shift_S2",
                                                 "gamma_shift_S2")


def test_raw_residuals_are_measured_minus_predicted_pixels():
    layout = ge.field_layout(WIDE, MOUNT, rng=3)
    exact = ge.predict_pixels(MOUNT, layout, WIDE)
    shift = np.tile([0.5, -0.25], (layout.n, 1))
    data = GroundData(layout.targets, layout.positions, exact + shift, layout.t)
    np.testing.assert_allclose(ge.raw_residuals(data, WIDE, MOUNT), shift, atol=1e-9)
    # and whitened by sigma 0.5 px (no survey error): twice that over one
    problem = ge.ground_problem(data, WIDE, 0.5)
    np.testing.assert_allclose(problem.residuals(MOUNT), (shift / 0.5).ravel(), atol=1e-8)
    assert problem.observations == ge.observations(data)
    assert problem.system == "ground" and problem.separating_data == ge.SEPARATING_DATA
    assert problem.base == ge.BASE
    assert problem.unavailable == {"session_shift": "fewer than two sessions"}


def test_a_target_just_in_front_is_accepted_one_behind_refused_naming_its_row():
    layout = ge.field_layout(WIDE, MOUNT, (40.0,), (3, 3), rng=4)
    data = ge.simulate(layout, WIDE, MOUNT, 0.0, 0.0, 1)
    ge.check_in_front(data, WIDE, "g.csv")  # nothing raised
    near = data.positions.copy()
    near[0] *= 0.5 / np.linalg.norm(near[0])  # half a metre in front
    ge.check_in_front(GroundData(data.targets, near, data.pixels, data.t), WIDE, "g.csv")
    positions = data.positions.copy()
    positions[2] *= -1.0
    behind = GroundData(data.targets, positions, data.pixels, data.t)
    with pytest.raises(InputError, match=r"^g\.csv: row 4, columns 'x_m', 'y_m', 'z_m': the "
                                         r"target is behind the sensor for the mounting that best "
                                         r"fits the measured directions \(check the frame: x "
                                         r"right, y forward, z up\)$"):
        ge.check_in_front(behind, WIDE, "g.csv")


def test_report_view_axes_and_the_study_parameters_of_a_fit():
    """Axes: the tangent-plane radius hypot(px / k_x, pz / k_z), the range |r|, the height z
    and the time; residuals (1, 0) at a target on the +px axis are (along 1, across 0). The
    study parameters carry the camera, the noise, the layout, the fit's values (0 for effects
    not fitted), session shifts and the named effects without flagged observations."""
    layout = ge.field_layout(WIDE, MOUNT, (50.0, 100.0), (3, 3), sessions=2, rng=5)
    data = ge.simulate(layout, WIDE, MOUNT, 0.2, 0.0, 6)
    view = ge.report_view(data, WIDE, 0.2, 0.01, refraction=0.2)
    assert view.system == "ground" and view.study_system == "discrepancy_ground"
    assert view.components == ("px", "pz") and view.rms_unit == "px" and view.rms_scale == 1.0
    labels = [a[0] for a in view.axes]
    assert labels == ["image radius (tangent plane) [1]", "range [m]", "target height z [m]",
                      "time t_s [s]"]
    tangent = data.pixels / [WIDE.k_x, WIDE.k_z]
    np.testing.assert_allclose(view.axes[0][1], np.hypot(*tangent.T), rtol=1e-12)
    np.testing.assert_allclose(view.axes[1][1], np.linalg.norm(data.positions, axis=1))
    np.testing.assert_array_equal(view.axes[2][1], data.positions[:, 2])
    np.testing.assert_array_equal(view.axes[3][1], data.t)
    names, radial = view.axes[0][2]
    assert names == ("radial", "tangential")
    out = tangent / np.hypot(*tangent.T)[:, None]
    split = radial(np.tile([1.0, 0.0], (data.n, 1)))
    np.testing.assert_allclose(split, np.stack([out[:, 0], -out[:, 1]], 1), atol=1e-12)
    split = radial(np.tile([0.0, 1.0], (data.n, 1)))
    np.testing.assert_allclose(split, np.stack([out[:, 1], out[:, 0]], 1), atol=1e-12)
    np.testing.assert_allclose(view.raw_residuals(MOUNT), ge.raw_residuals(
        data, WIDE, MOUNT, 0.2), atol=0)
    assert view.shift_unit("psi") == ("mrad", MRAD)
    assert view.display_unit("psi") == ("deg", math.pi / 180.0)
    assert view.base_physics == {"earth_curvature": True, "refraction_k": 0.2}
    fit = SimpleNamespace(params={**MOUNT, "s": 1e-3, "theta_shift_S2": 2e-4},
                          effects=("mounting", "focal_scale", "outlier:T03@S1",
                                   "session_shift"))
    params = view.study_params(fit)
    assert params["fov_yaw"] == WIDE.fov_yaw and params["fov_pitch"] == WIDE.fov_pitch
    assert (params["n_x"], params["n_z"]) == (1600, 900)
    assert (params["pixel_sigma"], params["survey_sigma"], params["refraction_k"]) == (
        0.2, 0.01, 0.2)
    assert json.loads(params["layout"]) == data.layout()
    assert params["psi"] == MOUNT["psi"] and params["s"] == 1e-3 and params["k1"] == 0.0
    assert json.loads(params["extra_truth"]) == {"theta_shift_S2": 2e-4}
    assert params["fit_effects"] == "focal_scale,session_shift"
    assert params["diagnose"] == 0
    assert set(params) == {"fov_yaw", "fov_pitch", "n_x", "n_z", "pixel_sigma",
                           "survey_sigma", "layout", "refraction_k", "psi", "theta", "gamma",
                           *ge.TRUTH_KEYS, "extra_truth", "fit_effects", "diagnose"}
    untimed = GroundData(data.targets, data.positions, data.pixels)
    assert len(ge.report_view(untimed, WIDE, 0.2, 0.0).axes) == 3


def test_a_session_shift_turns_the_mounting_of_its_session_only():
    """Shifts (1, -2, 0.5) mrad of (psi, theta, gamma) in session S2: its observations are
    imaged as with the angles themselves shifted, those of S1 as without."""
    layout = ge.field_layout(WIDE, MOUNT, (50.0, 100.0), (3, 3), sessions=2, rng=8)
    shift = {"psi": 1e-3, "theta": -2e-3, "gamma": 5e-4}
    got = ge.predict_pixels({**MOUNT, **{f"{a}_shift_S2": v for a, v in shift.items()}},
                            layout, WIDE)
    turned = ge.predict_pixels({a: MOUNT[a] + shift[a] for a in MOUNT}, layout, WIDE)
    plain = ge.predict_pixels(MOUNT, layout, WIDE)
    s2 = np.array(layout.session) == "S2"
    np.testing.assert_allclose(got[s2], turned[s2], atol=1e-9)
    np.testing.assert_allclose(got[~s2], plain[~s2], atol=1e-12)
    assert np.abs(turned[s2] - plain[s2]).min() > 0.01
