"""``montecarlo.discrepancy.stabilization_effects`` against hand values and the injected noise.

References: the units' definitions (1 arcmin = pi/10800 rad, 1 deg/h = pi/648000 rad/s), the
scalar Kalman filter of a random walk worked by hand (F = I, walk variance q, image noise 1:
P = 0, q, q/(1+q) ... below), and the chi-square band of whitened residuals of a recording
simulated with known gyro and image noise.
"""

import dataclasses
import math

import numpy as np
import pytest

from montecarlo.discrepancy import stabilization_effects as ste
from montecarlo.seed001 import estimate as se
from montecarlo.seed001 import kinematics as kin
from montecarlo.seed001 import simulate as sim

D = np.pi / 180.0
ROCK = kin.Rocking(np.full(3, 5 * D), [0.25, 0.4, 0.32], [0.0, 1.0, 2.0])
DELTA_G = np.array([0.5, -0.3, 0.7]) * D
DELTA_P = np.array([0.4, 0.6, -0.6]) * D
BIAS = np.array([1.0, -2.0, 0.5]) * D / 3600.0
TRUTH = dict(zip(se.PARAMETER_NAMES, [DELTA_P[0], DELTA_G[0], DELTA_G[1],
                                      DELTA_P[2] - DELTA_G[2], DELTA_P[1], *BIAS], strict=True))


def test_display_units_by_hand():
    arcmin, deg_per_h = math.pi / 10800.0, math.pi / 648000.0
    for name in ("delta_px", "delta_gx", "delta_gy", "delta_z", "delta_py", "delta_gz",
                 "camera_yaw_on_pitch"):
        unit, size = ste.display_unit(name)
        assert unit == "arcmin" and size == pytest.approx(arcmin, rel=1e-15)
    for name in ("bias_x", "bias_y", "bias_z"):
        unit, size = ste.display_unit(name)
        assert unit == "deg/h" and size == pytest.approx(deg_per_h, rel=1e-15)
    assert ste.display_unit("aim_x") == ("px", 1.0) == ste.display_unit("aim_z")
    for name in ("gyro_scale_x", "gyro_scale_y", "gyro_scale_z"):
        assert ste.display_unit(name) == ("ppm", 1e-6)
    assert ste.display_unit("gyro_delay") == ("ms", 1e-3) == ste.display_unit("servo_lag")


@pytest.mark.parametrize("mount", kin.MOUNTS)
def test_base_effect_names_steps_and_bounds(mount):
    base = ste.base_effect(mount)
    assert base.name == "installation"
    assert base.parameters == (*se.parameter_names(mount), "aim_x", "aim_z")
    steps = dict(zip(base.parameters, base.steps, strict=True))
    assert steps["delta_px"] == 1e-6 and steps["delta_z"] == 1e-6
    assert steps["bias_x"] == 1e-9 and steps["bias_z"] == 1e-9
    assert steps["aim_x"] == 1e-3 and steps["aim_z"] == 1e-3
    if mount == "inner-gimbal":
        assert steps["delta_gz"] == 1e-6
    assert base.bounds == ((-np.inf, np.inf),) * len(base.parameters)
    assert base.description == (f"the estimator's model, {mount} mount: angles [rad], gyro "
                                "biases [rad/s], aim point [px]")


def test_walk_filter_by_hand():
    """F = I, image noise 1, walk variances q = (1, 4) per axis.

    Axis x: k = 0: P = 0, S = 1, K = 0, W = 1; k = 1: P = 1, S = 2, K = 1/2, W = 1/sqrt(2),
    P = 1/2; k = 2: P = 3/2, S = 5/2, K = 3/5, W = sqrt(2/5). Axis z: k = 1: P = 4, S = 5,
    K = 4/5, W = 1/sqrt(5), P = 4/5; k = 2: P = 24/5, S = 29/5, K = 24/29, W = sqrt(5/29).
    Innovations of residuals r: e_0 = r_0, w = K_0 e_0 = 0; e_1 = r_1, w = K_1 e_1;
    e_2 = r_2 - w; each whitened by W_k.
    """
    F = np.broadcast_to(np.eye(2), (3, 2, 2))
    q = np.array([[9.0, 9.0], [1.0, 4.0], [1.0, 4.0]])  # row 0 is never used (w_0 = 0)
    gain, whiten = ste.walk_whitening(F, q, 1.0)
    np.testing.assert_allclose(np.diagonal(gain, axis1=1, axis2=2),
                               [[0, 0], [1 / 2, 4 / 5], [3 / 5, 24 / 29]], rtol=1e-14)
    np.testing.assert_allclose(np.diagonal(whiten, axis1=1, axis2=2),
                               [[1, 1], [1 / np.sqrt(2), 1 / np.sqrt(5)],
                                [np.sqrt(2 / 5), np.sqrt(5 / 29)]], rtol=1e-14)
    assert np.abs(gain[:, 0, 1]).max() == 0 and np.abs(whiten[:, 1, 0]).max() == 0
    r = np.array([[2.0, -1.0], [4.0, 10.0], [1.0, 3.0]])
    e2 = r[2] - np.array([1 / 2 * 4.0, 4 / 5 * 10.0])
    expected = [r[0], r[1] * [1 / np.sqrt(2), 1 / np.sqrt(5)],
                e2 * [np.sqrt(2 / 5), np.sqrt(5 / 29)]]
    np.testing.assert_allclose(ste.whitened_innovations(r, F, gain, whiten), expected,
                               rtol=1e-14)
    # a batch of residual sets: each filtered alone
    batch = np.stack([r, 2 * r])
    np.testing.assert_allclose(ste.whitened_innovations(batch, F, gain, whiten)[1],
                               2 * np.asarray(expected), rtol=1e-14)
    # without a walk: no gain, every residual divided by the image noise
    gain, whiten = ste.walk_whitening(F, None, 0.5)
    assert np.abs(gain).max() == 0
    np.testing.assert_allclose(whiten, np.broadcast_to(2 * np.eye(2), (3, 2, 2)), rtol=1e-15)


def test_flipped_columns_change_one_sign_each():
    t = np.arange(3.0)
    data = sim.Record(t=t, gyro=np.ones((3, 3)), eta=np.full(3, 0.1), eps=np.full(3, 0.2),
                      los_px=np.tile([3.0, 4.0], (3, 1)))
    f = ste.flipped(data, "eta_rad")
    assert f.eta.tolist() == [-0.1] * 3 and f.eps.tolist() == [0.2] * 3
    assert f.los_px.tolist() == data.los_px.tolist() and f.gyro is data.gyro
    f = ste.flipped(data, "eps_rad")
    assert f.eps.tolist() == [-0.2] * 3 and f.eta.tolist() == [0.1] * 3
    assert f.los_px.tolist() == data.los_px.tolist()
    f = ste.flipped(data, "los_x_px")
    assert f.los_px.tolist() == [[-3.0, 4.0]] * 3 and f.eta.tolist() == [0.1] * 3
    f = ste.flipped(data, "los_z_px")
    assert f.los_px.tolist() == [[3.0, -4.0]] * 3 and f.eps.tolist() == [0.2] * 3
    for column in ste.CONVENTIONS:
        f = ste.flipped(data, column)
        assert f.t is data.t and f.gyro is data.gyro
    assert set(ste.CONVENTIONS) == {"eta_rad", "eps_rad", "los_x_px", "los_z_px"}


def test_large_angles_at_the_limit_and_every_angle_name():
    """30 deg itself is small (the limit is exclusive); 30.01 deg is large in every angle."""
    at = {n: 30.0 * D for n in ste.ANGLES}
    assert ste.large_angles(at) == {}
    beyond = {n: -30.01 * D for n in ste.ANGLES}
    large = ste.large_angles(beyond)
    assert sorted(large) == sorted(ste.ANGLES)
    assert all(v == pytest.approx(-30.01 * D, abs=1e-12) for v in large.values())


def _recording(mount="patent", gyro_noise=0.0, rng=11):
    setup = sim.Setup(duration=8.0, rate=25.0, aim_azimuth=20 * D, aim_pitch=18 * D,
                      image_noise=0.1, gyro_noise=gyro_noise, target_px=(200.0, -100.0),
                      mount=mount)
    return setup, sim.simulate(ROCK, setup, DELTA_G, DELTA_P, BIAS, rng=rng)


@pytest.mark.parametrize("gyro_noise", [0.0, np.radians(0.05) / 60.0])
def test_whitened_residuals_at_the_truth_are_unit_white_noise(gyro_noise):
    """At the true parameters the residuals are the injected noise: image noise 0.1 px per axis
    and, with gyro noise of density q, an LOS walk of density q k per axis (k = k_x, k_z
    [px/rad]). Whitened with these stated levels, the 2N = 402 values of 8 s at 25 Hz have a
    sum of squares chi2(402): mean 402, sd sqrt(804) = 28.4; the band is +-4 sd. The walk here
    (0.05 deg/sqrt(h): 1.7 px after 8 s) is much larger than the image noise, so a walk left
    out or mis-scaled leaves the sum far outside the band."""
    setup, run = _recording(gyro_noise=gyro_noise)
    problem = ste.stabilization_problem(run, setup.camera, setup.image_noise, gyro_noise)
    values = {**TRUTH, "aim_x": setup.target_px[0], "aim_z": setup.target_px[1]}
    r = problem.residuals(values)
    assert r.shape == (2 * run.t.size,)
    n = r.size
    assert abs(float(r @ r) - n) < 4.0 * math.sqrt(2.0 * n)
    assert abs(r.mean()) < 4.0 / math.sqrt(n)
    # the unwhitened residuals are the raw image errors
    raw = ste.raw_residuals(run, setup.camera, values, "patent", "point")
    np.testing.assert_allclose(raw, run.los_px - ste.predict_image(values, run, setup.camera),
                               rtol=0, atol=0)
    if gyro_noise == 0.0:  # whitening is then a division by the image noise
        np.testing.assert_allclose(r, (raw / setup.image_noise).ravel(), rtol=1e-12)


def test_problem_start_candidates_and_view():
    setup, run = _recording(mount="inner-gimbal", gyro_noise=0.0)
    est = se.estimate(run.t, run.gyro, run.eta, run.eps, run.los_px, setup.camera, 0.1, 0.0,
                      mount="inner-gimbal")
    problem = ste.stabilization_problem(run, setup.camera, 0.1, 0.0, "inner-gimbal", "point",
                                        est)
    assert problem.system == "stabilization"
    assert problem.base.parameters == ste.base_effect("inner-gimbal").parameters
    assert list(problem.start.values()) == [*est.values.tolist(), *est.aim_px.tolist()]
    assert [c.name for c in problem.candidates] == ["gyro_scale_factor", "gyro_time_delay",
                                                    "servo_lag"]
    assert problem.unavailable == {
        "inner_gimbal_mount": "the base model already has the inner-gimbal mount"}
    setup_p, run_p = _recording()
    patent = ste.stabilization_problem(run_p, setup_p.camera, 0.1)
    assert [c.name for c in patent.candidates] == [c.name for c in ste.CANDIDATES]
    assert patent.unavailable == {}
    # by default no gyro noise: the whitening divides by the image noise
    raw = ste.raw_residuals(run_p, setup_p.camera, patent.start, "patent", "point")
    np.testing.assert_allclose(patent.residuals(patent.start), (raw / 0.1).ravel(), rtol=1e-12)
    view = ste.report_view(run, setup.camera, "inner-gimbal", "point")
    assert (view.system, view.rms_unit, view.rms_scale, view.components) == (
        "stabilization", "px", 1.0, ("x", "z"))
    assert view.study_system == "stabilization" and view.display_unit is ste.display_unit
    (label, values, components), = view.axes
    assert label == "time [s]" and values is run.t and components is None
    np.testing.assert_array_equal(view.raw_residuals(problem.start), ste.raw_residuals(
        run, setup.camera, problem.start, "inner-gimbal", "point"))
    with pytest.raises(NotImplementedError) as info:
        view.study_params(None)
    assert str(info.value) == "no Monte Carlo of stabilisation diagnoses"
    # the raw residuals use the recording's mount and sampling
    for sampling in ("point", "interval-mean"):
        np.testing.assert_array_equal(
            ste.raw_residuals(run, setup.camera, problem.start, "inner-gimbal", sampling),
            run.los_px - ste.predict_image(problem.start, run, setup.camera, "inner-gimbal",
                                           sampling))


def test_predict_image_of_a_scale_factor_and_a_lag_by_hand():
    """Without a carrier motion (gyro reads zero) and without gimbal motion the image stays
    where the aim point puts it, whatever the scale factor or lag; a constant gyro rate w
    about the azimuth axis read with scale 1 + s is the rate w / (1 + s)."""
    setup, run = _recording(gyro_noise=0.0)
    still = dataclasses.replace(run, gyro=np.zeros_like(run.gyro),
                                eta=np.full_like(run.eta, run.eta[0]),
                                eps=np.full_like(run.eps, run.eps[0]))
    aim = {"aim_x": 200.0, "aim_z": -100.0}
    for extra in ({}, {"gyro_scale_z": 0.01}, {"servo_lag": 0.02}, {"gyro_delay": -0.03}):
        image = ste.predict_image({**aim, **extra}, still, setup.camera)
        np.testing.assert_allclose(image, np.tile([200.0, -100.0], (run.t.size, 1)), atol=1e-9)
    w = 1e-3
    turning = dataclasses.replace(still, gyro=np.tile([0.0, 0.0, w], (run.t.size, 1)))
    scaled = dataclasses.replace(still, gyro=np.tile([0.0, 0.0, w * 1.01], (run.t.size, 1)))
    np.testing.assert_allclose(ste.predict_image({**aim, "gyro_scale_z": 0.01}, scaled,
                                                 setup.camera),
                               ste.predict_image(aim, turning, setup.camera), atol=1e-9)


def test_convention_check_refits_with_the_recordings_mount_sampling_and_noise():
    """An inner-gimbal recording with interval-mean gyro rows and gyro noise, image z the
    other way round: the refit with z negated passes the global test with small angles only if
    it uses the recording's mount, sampling and noise levels (the patent model misfits
    inner-gimbal data, point samples misread interval means by half an interval)."""
    from montecarlo.discrepancy.fit import fit_model

    gyro_noise = np.radians(0.01) / 60.0
    setup = sim.Setup(duration=8.0, rate=25.0, aim_azimuth=20 * D, aim_pitch=18 * D,
                      image_noise=0.1, gyro_noise=gyro_noise, mount="inner-gimbal",
                      gyro_sampling="interval-mean")
    run = sim.simulate(ROCK, setup, DELTA_G, DELTA_P, BIAS, rng=12)
    other = ste.flipped(run, "los_z_px")
    args = (setup.camera, 0.1, gyro_noise, "inner-gimbal", "interval-mean")
    base = fit_model(ste.stabilization_problem(other, *args), ())
    check = ste.convention_check(other, *args, base, 0.01)
    assert check["checked"]
    assert "los_z_px" in check["named"]
    fit = check["fits"]["los_z_px"]
    assert fit["p_value"] >= 0.01 and fit["large_angles"] == {}
    assert sorted(fit) == ["chi2_red", "large_angles", "p_value"] and fit["chi2_red"] < 2.0
    for column in check["named"]:  # named: the refit passes the test AND has small angles
        assert check["fits"][column]["p_value"] >= 0.01
        assert not check["fits"][column]["large_angles"]
