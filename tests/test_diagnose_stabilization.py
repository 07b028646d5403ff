"""``diagnose stabilization``: seed 001's estimator model on the generic discrepancy engine.

References: the estimator's predictor (the base model must equal it), the inner-gimbal
simulator (the candidate at ``c = dpz`` must reproduce it), the explicit covariance of the LOS
walk (the whitening), and the engine's verdicts on simulated data with and without the effect.
"""

import dataclasses
import json
import subprocess
import sys

import numpy as np
import pytest

from montecarlo.discrepancy import stabilization_effects as ste
from montecarlo.discrepancy.candidate_tests import canonical_correlation
from montecarlo.discrepancy.engine import diagnose
from montecarlo.seed001 import estimate as se
from montecarlo.seed001 import kinematics as kin
from montecarlo.seed001 import linear_model as lin
from montecarlo.seed001 import simulate as sim

D = np.pi / 180.0
ROCK = kin.Rocking(np.full(3, 5 * D), [0.25, 0.4, 0.32], [0.0, 1.0, 2.0])
SETUP = sim.Setup(duration=8.0, rate=25.0, aim_azimuth=20 * D, aim_pitch=18 * D,
                  image_noise=0.1, gyro_noise=np.radians(0.01) / 60.0,
                  target_px=(200.0, -100.0))
QUIET = dataclasses.replace(SETUP, image_noise=0.0, gyro_noise=0.0)
DELTA_G = np.array([0.5, -0.3, 0.7]) * D
DELTA_P = np.array([0.4, 0.6, -0.6]) * D
BIAS = np.array([1.0, -2.0, 0.5]) * D / 3600.0
PATENT = dict(zip(se.PARAMETER_NAMES, [DELTA_P[0], DELTA_G[0], DELTA_G[1],
                                       DELTA_P[2] - DELTA_G[2], DELTA_P[1], *BIAS],
                  strict=True))


def _values(params, aim, **extra):
    return {**params, "aim_x": aim[0], "aim_z": aim[1], **extra}


@pytest.mark.parametrize("mount", kin.MOUNTS)
def test_base_model_is_the_estimators_predictor(mount):
    run = sim.simulate(ROCK, dataclasses.replace(QUIET, mount=mount), DELTA_G, DELTA_P, BIAS)
    params = {**PATENT, **({"delta_gz": DELTA_G[2]} if mount == "inner-gimbal" else {})}
    vector = [params[n] for n in se.parameter_names(mount)]
    ours = ste.predict_image(_values(params, QUIET.target_px), run, QUIET.camera, mount)
    theirs = se.predict_los(run.t, run.gyro, run.eta, run.eps, vector, QUIET.camera,
                            QUIET.target_px, mount=mount)
    np.testing.assert_allclose(ours, theirs, atol=1e-9)
    # batched parameter vectors, as the engine passes them: shape (k, 1)
    batch = {k: np.full((3, 1), v) for k, v in _values(params, QUIET.target_px).items()}
    np.testing.assert_allclose(ste.predict_image(batch, run, QUIET.camera, mount),
                               np.broadcast_to(ours, (3, *ours.shape)), atol=1e-9)


def test_inner_gimbal_candidate_at_dpz_is_the_inner_gimbal_camera():
    run = sim.simulate(ROCK, dataclasses.replace(QUIET, mount="inner-gimbal"), DELTA_G, DELTA_P,
                       BIAS)
    predicted = ste.predict_image(_values(PATENT, QUIET.target_px,
                                          camera_yaw_on_pitch=DELTA_P[2]), run, QUIET.camera)
    inner = se.predict_los(run.t, run.gyro, run.eta, run.eps, [*PATENT.values(), DELTA_G[2]],
                           QUIET.camera, QUIET.target_px, mount="inner-gimbal")
    np.testing.assert_allclose(predicted, inner, atol=1e-9)
    assert np.abs(predicted - run.los_px_true).max() < 1e-3  # the spline at 25 Hz


def test_gyro_candidates_against_edited_recordings():
    """A scale factor s is the gyro divided by 1 + s; a delay d is the rate read d later."""
    run = sim.simulate(ROCK, QUIET, DELTA_G, DELTA_P, BIAS)
    s = np.array([1e-3, -2e-3, 5e-4])
    scaled = dataclasses.replace(run, gyro=run.gyro * (1.0 + s))
    base = ste.predict_image(_values(PATENT, QUIET.target_px), run, QUIET.camera)
    np.testing.assert_allclose(ste.predict_image(_values(PATENT, QUIET.target_px, **dict(zip(
        ("gyro_scale_x", "gyro_scale_y", "gyro_scale_z"), s, strict=True))), scaled,
        QUIET.camera), base, atol=1e-9)
    # rows one interval late (the first repeated): the delay of one interval undoes it
    shifted = dataclasses.replace(run, gyro=np.concatenate([run.gyro[:1], run.gyro[:-1]]))
    delayed = ste.predict_image(_values(PATENT, QUIET.target_px, gyro_delay=1.0 / QUIET.rate),
                                shifted, QUIET.camera)
    undelayed = ste.predict_image(_values(PATENT, QUIET.target_px), shifted, QUIET.camera)
    assert np.abs(delayed - base).max() < 1e-3 * np.abs(undelayed - base).max()


def test_los_lag_candidate_against_an_edited_recording():
    """An LOS lag L reads gimbal and gyro L before the image's time stamp: on a recording whose
    gyro and encoder rows are one interval late (the first repeated), a lag of minus one
    interval restores the prediction of the unedited recording."""
    run = sim.simulate(ROCK, QUIET, DELTA_G, DELTA_P, BIAS)
    late = dataclasses.replace(run, **{k: np.concatenate([getattr(run, k)[:1],
                                                          getattr(run, k)[:-1]])
                                       for k in ("gyro", "eta", "eps")})
    base = ste.predict_image(_values(PATENT, QUIET.target_px), run, QUIET.camera)
    lagged = ste.predict_image(_values(PATENT, QUIET.target_px, servo_lag=-1.0 / QUIET.rate),
                               late, QUIET.camera)
    unlagged = ste.predict_image(_values(PATENT, QUIET.target_px), late, QUIET.camera)
    assert np.abs(lagged - base).max() < 1e-3 * np.abs(unlagged - base).max()


@pytest.mark.slow
def test_interval_mean_rows_read_as_points_name_the_gyro_delay():
    """Interval-mean gyro rows analysed as point samples are rows half an interval late, and
    a little attenuated (the mean of a sinusoid over h is its value times 1 - (w h)^2 / 24, here
    -4e-4 at 25 Hz): the diagnosis names gyro_time_delay first, at h/2, never servo_lag, and the
    LOS lag is not its confounded partner (a gimbal-only lag was, and was named instead)."""
    setup = dataclasses.replace(SETUP, gyro_sampling="interval-mean", target_px=(0.0, 0.0))
    run = sim.simulate(ROCK, setup, DELTA_G, DELTA_P, BIAS, rng=4)
    d = diagnose(ste.stabilization_problem(run, setup.camera, setup.image_noise,
                                           setup.gyro_noise, gyro_sampling="point"))
    assert d.named[0] == "gyro_time_delay" and "servo_lag" not in d.named
    assert not d.unexplained
    assert d.after.params["gyro_delay"] == pytest.approx(
        0.5 / setup.rate, abs=4 * d.after.stderr["gyro_delay"])
    first = {t.name: t for t in d.steps[0].tests}
    assert canonical_correlation(first["gyro_time_delay"], first["servo_lag"]) < 0.9


def test_whitening_is_the_inverse_cholesky_factor_of_the_walk_covariance():
    g = np.random.default_rng(6)
    n = 30
    F = lin.plane_rotation(g.uniform(-0.1, 0.1, n))
    q = g.uniform(0.01, 0.05, (n, 2))
    r = g.normal(size=(n, 2))
    gain, whiten = ste.walk_whitening(F, q, 0.2)
    ours = ste.whitened_innovations(r, F, gain, whiten).ravel()
    cov = 0.04 * np.eye(2 * n)
    for j in range(1, n):
        carry = np.eye(2)
        B = np.zeros((2 * n, 2))
        for k in range(j, n):
            carry = F[k] @ carry if k > j else carry
            B[2 * k:2 * k + 2] = carry
        cov += B @ np.diag(q[j]) @ B.T
    L = np.linalg.cholesky(cov)
    np.testing.assert_allclose(ours, np.linalg.solve(L, r.ravel()), atol=1e-10)


def test_inner_gimbal_data_with_the_patent_model_names_the_mount():
    run = sim.simulate(ROCK, dataclasses.replace(SETUP, mount="inner-gimbal"), DELTA_G, DELTA_P,
                       BIAS, rng=3)
    d = diagnose(ste.stabilization_problem(run, SETUP.camera, SETUP.image_noise,
                                           SETUP.gyro_noise))
    assert d.detected and d.named == ["inner_gimbal_mount"] and not d.unexplained
    assert d.after.params["camera_yaw_on_pitch"] == pytest.approx(
        DELTA_P[2], abs=4 * d.after.stderr["camera_yaw_on_pitch"])
    right = diagnose(ste.stabilization_problem(run, SETUP.camera, SETUP.image_noise,
                                               SETUP.gyro_noise, mount="inner-gimbal"))
    assert right.named == [] and "inner_gimbal_mount" in right.problem.unavailable


@pytest.mark.slow
def test_cli_json_names_the_mount_and_has_the_shared_shape(tmp_path):
    path = tmp_path / "run.csv"
    args = [sys.executable, "-m", "montecarlo"]
    out = subprocess.run([*args, "stabilization", "simulate", str(path), "--duration-s", "8",
                          "--rate-hz", "25", "--aim-deg", "20", "18", "--mount", "inner-gimbal",
                          "--target-px", "300", "0"], capture_output=True, text=True,
                         timeout=600)
    assert out.returncode == 0, out.stderr
    out = subprocess.run([*args, "diagnose", "stabilization", str(path), "--json"],
                         capture_output=True, text=True, timeout=600)
    assert out.returncode == 0, out.stderr
    report = json.loads(out.stdout)
    assert report["system"] == "stabilization"
    assert [e["name"] for e in report["named_effects"]] == ["inner_gimbal_mount"]
    assert report["gap"]["before"]["chi2_red"] > 10 * report["gap"]["after"]["chi2_red"]
    assert report["named_effects"][0]["units"] == {"camera_yaw_on_pitch": "arcmin"}


def test_cli_refuses_an_unknown_mount(tmp_path):
    bad = subprocess.run([sys.executable, "-m", "montecarlo", "diagnose", "stabilization",
                          str(tmp_path / "run.csv"), "--mount", "outer"],
                         capture_output=True, text=True, timeout=600)
    assert bad.returncode == 2 and "Traceback" not in bad.stderr and "--mount" in bad.stderr


@pytest.mark.slow
def test_null_recordings_name_nothing():
    """200 recordings without any candidate effect (20 s at 50 Hz; the mount, the gyro sampling
    and a 0 or 300 px target in turn, each analysed with its own mount): an effect is named in
    at most 2 % (the engine's family error is alpha = 1 %)."""
    g = np.random.default_rng(20110429)
    base = sim.Setup(duration=20.0, rate=50.0, aim_azimuth=20 * D, aim_pitch=10 * D,
                     image_noise=0.1, gyro_noise=np.radians(0.01) / 60.0)
    variants = [(m, s, o) for m in kin.MOUNTS for s in sim.GYRO_SAMPLINGS for o in (0.0, 300.0)]
    named = 0
    for i in range(200):
        mount, sampling, offset = variants[i % 8]
        angles = g.uniform(0.2, 1.0, 6) * g.choice([-1, 1], 6) * D
        rock = kin.Rocking(np.full(3, 5 * D), [0.25, 0.4, 0.32], g.uniform(0, 2 * np.pi, 3))
        a = g.uniform(0, 2 * np.pi)
        setup = dataclasses.replace(base, mount=mount, gyro_sampling=sampling,
                                    target_px=(offset * np.cos(a), offset * np.sin(a)))
        run = sim.simulate(rock, setup, angles[:3], angles[3:], g.normal(size=3) * D / 3600,
                           rng=g)
        d = diagnose(ste.stabilization_problem(run, setup.camera, 0.1, setup.gyro_noise, mount,
                                               sampling))
        named += bool(d.named)
    assert named <= 4


def test_large_angles_are_wrapped_before_the_30_degree_limit():
    """By hand: -720° and 360° + 5° wrap to 0° and 5° (small); 179.6° and -150° stay large;
    biases and the aim point are not angles."""
    d = np.pi / 180.0
    params = {"delta_px": 179.6 * d, "delta_gx": -720.0 * d, "delta_gy": 365.0 * d,
              "delta_z": -150.0 * d, "delta_py": 29.0 * d, "bias_x": 100.0, "aim_x": 300.0}
    large = ste.large_angles(params)
    assert set(large) == {"delta_px", "delta_z"}
    assert large["delta_px"] == pytest.approx(179.6 * d, abs=1e-12)
    assert large["delta_z"] == pytest.approx(-150.0 * d, abs=1e-12)
