"""Ground forward model with candidate effects, checked against independent routes."""

import json
import math

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from montecarlo.discrepancy import ground_effects as ge
from montecarlo.discrepancy.candidate_tests import analyse_candidates, canonical_correlation
from montecarlo.discrepancy.design import TRIAL_METRICS
from montecarlo.discrepancy.engine import diagnose
from montecarlo.discrepancy.fit import fit_model
from montecarlo.errors import InputError
from montecarlo.geometry.camera import Camera
from montecarlo.io.ground_csv import GroundData, read_ground_csv, write_ground_csv
from montecarlo.seed000 import ground
from montecarlo.systems import discrepancy as sd

CAM = Camera.from_degrees(90.0, 90.0, 512, 512)
MOUNT = dict(ge.DEFAULT_MOUNTING)
LAYOUT = sd.default_layout(CAM, MOUNT)


def read_ground_checked(path):
    """Read a ground CSV as ``montecarlo diagnose ground`` does: format, then geometry."""
    data = read_ground_csv(path, CAM, ge.min_targets())
    ge.check_in_front(data, CAM, str(path))
    return data


def predict(params, layout=LAYOUT, camera=CAM, refraction=ge.STANDARD_REFRACTION):
    return ge.predict_pixels({**MOUNT, **params}, layout, camera, refraction)


def moved(layout, positions):
    return GroundData(layout.targets, positions, layout.pixels, layout.t, layout.session)


WIDE = Camera.from_degrees(70.0, 40.0, 1600, 900)
"""A non-square camera: 70 x 40 deg over 1600 x 900 px (k_x and k_z differ)."""
TILTED = {"psi": np.radians(-25.0), "theta": np.radians(8.0), "gamma": np.radians(-4.0)}


@pytest.mark.parametrize(("camera", "mount"), [(CAM, MOUNT), (WIDE, TILTED)])
def test_base_model_equals_seed000_trigonometric_route(camera, mount):
    """Base prediction = eq. (4) of the equivalent angles of eq. (10) (seed000.ground), for
    the square 90 deg camera and a non-square one on another mounting.

    Seed 000 has a flat earth and straight rays: k = 1 (a ray bent like the earth) cancels
    the curvature exactly."""
    C = Rotation.from_euler("ZXY", [mount["psi"], mount["theta"], mount["gamma"]]).as_matrix().T
    layout = sd.default_layout(camera, mount)
    expected, flags = ground.observe_target(C, layout.positions, camera)
    assert not flags.any()
    np.testing.assert_allclose(ge.predict_pixels(mount, layout, camera, 1.0), expected,
                               rtol=1e-12, atol=1e-9)
    # the layout spans most of each half-width (800 and 450 px for the non-square camera)
    half = np.array([camera.n_x, camera.n_z]) / 2.0
    assert np.all(np.abs(expected) <= half)
    assert np.all(np.abs(expected).max(axis=0) > 0.5 * half)


def test_layout_is_spread_over_the_field_at_two_ranges():
    pix = predict({})
    assert LAYOUT.n == 36
    assert np.all(np.abs(pix) <= 256) and np.ptp(pix[:, 0]) > 300 and np.ptp(pix[:, 1]) > 300
    np.testing.assert_allclose(sorted(set(np.round(np.linalg.norm(LAYOUT.positions, axis=1),
                                                   9))), [50.0, 100.0])


def tangent(pix, camera=CAM):
    return pix / np.array([camera.k_x, camera.k_z])


def test_radial_distortion_scales_the_tangent_radius():
    """r -> r (1 + k1 r^2) along the same image direction (docs/reference/discrepancy.md)."""
    t0, t1 = tangent(predict({})), tangent(predict({"k1": 0.03}))
    r0, r1 = np.linalg.norm(t0, axis=1), np.linalg.norm(t1, axis=1)
    np.testing.assert_allclose(r1, r0 * (1 + 0.03 * r0**2), rtol=1e-12)
    np.testing.assert_allclose(t1 / r1[:, None], t0 / r0[:, None], atol=1e-12)


def test_tangential_distortion_formula():
    t0, t1 = tangent(predict({})), tangent(predict({"p1": 0.002, "p2": -0.001}))
    x, z = t0.T
    r2 = x**2 + z**2
    np.testing.assert_allclose(t1[:, 0], x + 2 * 0.002 * x * z - 0.001 * (r2 + 2 * x**2),
                               rtol=1e-12)
    np.testing.assert_allclose(t1[:, 1], z + 0.002 * (r2 + 2 * z**2) - 2 * 0.001 * x * z,
                               rtol=1e-12)


def test_image_plane_effects():
    p0 = predict({})
    np.testing.assert_allclose(predict({"s": 0.01}), 1.01 * p0, rtol=1e-12)
    np.testing.assert_allclose(predict({"a": 0.02}), p0 * [1.01, 0.99], rtol=1e-12)
    np.testing.assert_allclose(predict({"c_x": 1.5, "c_z": -2.0}), p0 + np.array([1.5, -2.0]),
                               rtol=1e-12)
    rho = 0.01
    rot = np.array([[math.cos(rho), math.sin(rho)], [-math.sin(rho), math.cos(rho)]])
    np.testing.assert_allclose(predict({"rho": rho}), p0 @ rot, rtol=1e-12)


def test_detector_rotation_equals_roll_for_square_pixels():
    """With k_x = k_z an image rotation is a roll of frame a: detector_rotation is absorbed."""
    np.testing.assert_allclose(predict({"rho": 0.01}),
                               ge.predict_pixels({**MOUNT, "gamma": MOUNT["gamma"] + 0.01},
                                                 LAYOUT, CAM), atol=1e-9)


def test_target_effects_move_the_targets():
    r = LAYOUT.positions
    np.testing.assert_allclose(predict({"s_h": 0.02}),
                               predict({}, moved(LAYOUT, r * [1, 1, 1.02])), rtol=1e-12)
    for key, axis in (("b_x", 0), ("b_y", 1), ("b_z", 2)):
        shift = np.zeros(3)
        shift[axis] = 0.3
        np.testing.assert_allclose(predict({key: 0.3}), predict({}, moved(LAYOUT, r + shift)),
                                   rtol=1e-12)
    # the projection centre at l sees r - l: a lever arm is minus a common target bias
    np.testing.assert_allclose(predict({"l_x": 0.1, "l_y": -0.2, "l_z": 0.3}),
                               predict({"b_x": -0.1, "b_y": 0.2, "b_z": -0.3}), rtol=1e-12)


def test_curvature_and_standard_refraction_are_in_the_base_model():
    """Apparent height - (1 - k) d^2 / (2R); at 100 m that is 0.68 mm, ~0.002 px here."""
    d2 = np.sum(LAYOUT.positions[:, :2] ** 2, axis=1)
    drop = (1 - 0.13) * d2 / (2 * 6_371_000.0)
    flat = moved(LAYOUT, LAYOUT.positions - np.outer(drop, [0, 0, 1]))
    got = predict({})
    np.testing.assert_allclose(got, predict({}, flat, refraction=1.0), rtol=1e-12)
    assert 1e-4 < np.max(np.abs(got - predict({}, refraction=1.0))) < 0.01
    # the candidate dk adds to the standard coefficient
    np.testing.assert_allclose(predict({"dk": 0.4}), predict({}, refraction=0.53), rtol=1e-12)


def test_apparent_elevation_change_is_one_minus_k_range_over_2R():
    """Independent route: a target at range L on the level surface, seen along a ray of
    curvature k / R, is depressed by the angle (1 - k) L / (2R) to first order; exact circles
    (earth of radius R, ray of radius R / k) give that angle to 1e-6 relative at 3 km."""
    R, k, L = 6_371_000.0, 0.13, 3000.0
    phi = L / R  # geocentric angle to a target on the level surface
    target = np.array([R * np.sin(phi), R * np.cos(phi) - R])  # sensor at the origin
    geometric = np.arctan2(target[1], target[0])  # below the horizontal
    refraction = k * L / (2.0 * R)  # the ray's chord-to-tangent angle, raising the target
    apparent = geometric + refraction
    shift = ge.apparent_height_shift(L, k)
    assert apparent == pytest.approx(shift / L, rel=1e-6)
    assert shift == pytest.approx(-(1 - k) * L**2 / (2 * R), rel=1e-15)


def test_drift_is_linear_in_time_about_the_mean_epoch():
    w = np.array([2e-7, -1e-7, 3e-7])
    got = predict(dict(zip(("w_psi", "w_theta", "w_gamma"), w, strict=True)))
    dt = LAYOUT.t - LAYOUT.t.mean()
    for i in (0, 7, 20):
        angles = {k: MOUNT[k] + w[j] * dt[i] for j, k in enumerate(("psi", "theta", "gamma"))}
        one = GroundData(LAYOUT.targets[i:i + 1], LAYOUT.positions[i:i + 1],
                            LAYOUT.pixels[i:i + 1])
        np.testing.assert_allclose(got[i], ge.predict_pixels(angles, one, CAM)[0], rtol=1e-12)


def test_batched_parameters_equal_single_evaluations():
    values = [0.0, 0.01, -0.02]
    batch = ge.predict_pixels({**MOUNT, "k1": np.array(values)[:, None],
                               "b_z": np.array([0.0, 0.1, 0.2])[:, None]}, LAYOUT, CAM)
    for i, v in enumerate(values):
        np.testing.assert_allclose(batch[i], predict({"k1": v, "b_z": 0.1 * i}), rtol=1e-12)


def test_initial_mounting_recovers_the_truth_from_exact_data():
    data = GroundData(LAYOUT.targets, LAYOUT.positions, predict({}), LAYOUT.t)
    start = ge.initial_mounting(data, CAM)
    for k in ("psi", "theta", "gamma"):
        assert start[k] == pytest.approx(MOUNT[k], abs=1e-9)


def test_pixel_covariance_propagates_the_survey_error():
    """J J' from central differences of the pinhole (straight rays: k = 1) against the
    target position."""
    cov = ge.pixel_covariance(LAYOUT, CAM, MOUNT, 0.3, 0.02)
    h = 1e-4
    J = np.stack([(predict({}, moved(LAYOUT, LAYOUT.positions + h * e), refraction=1.0)
                   - predict({}, moved(LAYOUT, LAYOUT.positions - h * e), refraction=1.0))
                  / (2 * h)
                  for e in np.eye(3)], axis=-1)
    expected = 0.09 * np.eye(2) + 0.0004 * J @ np.swapaxes(J, 1, 2)
    np.testing.assert_allclose(cov, expected, rtol=1e-6)


def analyse(layout, camera, truth=MOUNT, sigma=0.3):
    problem = ge.exact_problem(layout, camera, truth, sigma, 0.0)
    fit = fit_model(problem, ())
    return {t.name: t for t in analyse_candidates(problem, fit)}


def test_what_the_default_layout_can_and_cannot_tell():
    tests = analyse(LAYOUT, CAM)
    assert tests["detector_rotation"].status == "absorbed"
    assert tests["detector_rotation"].absorbed_by == {"rho": ["gamma"]}
    assert tests["refraction"].status == "undetectable"
    assert "earth_curvature" not in tests  # known physics: in the base model
    assert tests["session_shift"].status == "unavailable"
    for name in ("radial_distortion", "focal_scale", "principal_point", "drift", "lever_arm"):
        assert tests[name].status == "testable"
    assert canonical_correlation(tests["target_height_bias"], tests["lever_arm"]) == \
        pytest.approx(1.0, abs=1e-9)


def test_principal_point_is_absorbed_by_yaw_and_pitch_in_a_narrow_field():
    """A 2-degree field: a shift of the image centre is a yaw/pitch rotation to < 5 %."""
    narrow = Camera.from_degrees(2.0, 2.0, 1000, 1000)
    mount = {"psi": 0.01, "theta": -0.02, "gamma": 0.005}
    layout = ge.field_layout(narrow, mount, (500.0, 1000.0), (6, 6), 0.8, 3600.0, rng=1)
    tests = analyse(layout, narrow, mount)
    assert tests["principal_point"].status == "absorbed"
    assert set(tests["principal_point"].absorbed_by) == {"c_x", "c_z"}
    wide = analyse(LAYOUT, CAM)["principal_point"]
    assert wide.status == "testable" and min(wide.retained.values()) > 0.2


def test_session_shift_with_two_sessions():
    layout = ge.field_layout(CAM, MOUNT, (50.0, 100.0), (4, 4), 0.8, 1800.0, sessions=2, rng=3)
    truth = {**MOUNT, "theta_shift_S2": 2e-3}
    data = ge.simulate(layout, CAM, truth, 0.3, 0.0, 4)
    d = diagnose(ge.ground_problem(data, CAM, 0.3))
    assert d.named == ["session_shift"]
    est, se = d.after.params, d.after.stderr
    assert abs(est["theta_shift_S2"] - 2e-3) < 3 * se["theta_shift_S2"]


def test_simulation_noise_matches_the_stated_sigma():
    """chi2 of the true parameters over many simulated sets averages 2n (unit variance)."""
    rng = np.random.default_rng(2)
    chi2 = []
    for _ in range(40):
        data = ge.simulate(LAYOUT, CAM, MOUNT, 0.3, 0.02, rng)
        r = ge.ground_problem(data, CAM, 0.3, 0.02).residuals(MOUNT)
        chi2.append(r @ r)
    n = 2 * LAYOUT.n
    assert np.mean(chi2) == pytest.approx(n, abs=4 * math.sqrt(2 * n / 40))


def write(tmp_path, text):
    p = tmp_path / "data.csv"
    p.write_text(text)
    return p


def test_csv_round_trip(tmp_path):
    data = ge.simulate(LAYOUT, CAM, MOUNT, 0.3, 0.01, 1)
    path = tmp_path / "g.csv"
    write_ground_csv(path, data)
    back = read_ground_checked(path)
    np.testing.assert_allclose(back.positions, data.positions, atol=5e-5)
    np.testing.assert_allclose(back.pixels, data.pixels, atol=5e-7)
    np.testing.assert_allclose(back.t, data.t, atol=0.05)
    assert back.targets == data.targets and back.session is None


@pytest.mark.parametrize(("body", "message"), [
    ("target,x_m,y_m,z_m,px\nA,1,50,0,0\n", r"missing column 'pz'"),
    ("target,x_m,y_m,z_m,px,pz\n" + "A,1,50,0,0,0\n" * 3, r"3 data rows, at least 4"),
    ("target,x_m,y_m,z_m,px,pz\n" + "A,1,50,0,0,0\n" * 4 + "B,1,x,0,0,0\n",
     r"row 6, column 'y_m': 'x' is not a finite number"),
    ("target,x_m,y_m,z_m,px,pz,t_s\n" + "A,1,50,0,0,0,1\n" * 4 + "B,1,5,0,0,0,nan\n",
     r"row 6, column 't_s'"),
    ("target,x_m,y_m,z_m,px,pz\n" + "A,1,50,0,0,0\n" * 4 + "B,1,5,0,300,0\n",
     r"row 6, column 'px': 300.0 is outside the detector"),
    ("target,x_m,y_m,z_m,px,pz,session\n" + "A,1,50,0,0,0,s\n" * 4 + "B,1,5,0,0,0,\n",
     r"row 6, column 'session': empty value"),
])
def test_malformed_csv_is_one_line(tmp_path, body, message):
    path = write(tmp_path, body)
    with pytest.raises(InputError, match=message) as info:
        read_ground_checked(path)
    assert "\n" not in str(info.value) and str(path) in str(info.value)


def test_run_trials_contract():
    rng = np.random.default_rng(0)
    out = sd.run_ground_trials({"diagnose": 1}, rng, 3)
    assert set(out) == set(TRIAL_METRICS)
    assert all(v.shape == (3,) and v.dtype == np.float64 for v in out.values())
    again = sd.run_ground_trials({"diagnose": 1}, np.random.default_rng(0), 3)
    for k in out:
        np.testing.assert_array_equal(out[k], again[k])
    with pytest.raises(ValueError, match="unknown"):
        sd.run_ground_trials({"nope": 1.0}, rng, 1)


def test_study_system_and_report_use_the_stated_refraction():
    """The Monte Carlo gap simulates with the diagnosis's coefficient: data made with k = 2 at
    0.5-3 km and refitted with k = 2 give chi2_red near 1; with the standard 0.13 they do not."""
    camera = Camera.from_degrees(30.0, 22.5, 1920, 1440)
    far = ge.field_layout(camera, MOUNT, (500.0, 1000.0, 2000.0, 3000.0), rng=1)
    params = {"fov_yaw": camera.fov_yaw, "fov_pitch": camera.fov_pitch, "n_x": 1920,
              "n_z": 1440, "pixel_sigma": 0.2, "layout": json.dumps(far.layout())}
    stated = sd.run_ground_trials({**params, "refraction_k": 2.0}, np.random.default_rng(1), 8)
    assert 0.6 < np.mean(stated["chi2_red"]) < 1.4  # 8 x 69 dof: sd of the mean 0.06
    standard = sd.run_ground_trials({**params, "dk": 1.87}, np.random.default_rng(1), 8)
    assert np.mean(standard["chi2_red"]) > 2.0
    data = ge.simulate(far, camera, MOUNT, 0.2, 0.0, 1, refraction=2.0)
    view = ge.report_view(data, camera, 0.2, 0.0, refraction=2.0)
    fit = fit_model(ge.ground_problem(data, camera, 0.2, 0.0, refraction=2.0), ())
    assert view.study_params(fit)["refraction_k"] == 2.0
    assert view.base_physics == {"earth_curvature": True, "refraction_k": 2.0}


def test_study_file_with_units_at_the_edge(tmp_path):
    """A TOML study of the registered system: keys carry units, run_trials gets SI."""
    from montecarlo.engine.runner import RunOptions, run_study
    from montecarlo.systems import load_study

    path = tmp_path / "d.toml"
    path.write_text('[study]\nsystem = "discrepancy_ground"\ntrials = 6\nseed = 1\n'
                    '[params]\npsi_deg = 30.0\npixel_sigma_px = 0.3\ndiagnose = 1\n'
                    'expected = "focal_scale"\ninject_mdb = 3.0\n')
    study = load_study(path)
    assert study.points[0].prepared.params["psi"] == pytest.approx(math.radians(30.0))
    result = run_study(study, RunOptions(n_jobs=1, progress=False, checkpoint_dir=tmp_path))
    row = result.to_frame().query("metric == 'named_expected'").iloc[0]
    assert row["count"] == 6 and row["mean"] == 1.0


def test_target_behind_the_sensor_is_one_line(tmp_path):
    data = ge.simulate(LAYOUT, CAM, MOUNT, 0.3, 0.0, 1)
    flipped = data.positions.copy()
    flipped[4] *= -1.0
    path = tmp_path / "g.csv"
    write_ground_csv(path, GroundData(data.targets, flipped, data.pixels, data.t))
    with pytest.raises(InputError, match=r"row 6, columns 'x_m', 'y_m', 'z_m': the target is "
                                         r"behind the sensor"):
        read_ground_checked(path)
