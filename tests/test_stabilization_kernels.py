"""Seed 001: each compiled kernel against the literal numpy function it replaces, same inputs.

Tolerances are rounding bounds: the kernels add and multiply in another order (a sequential
prefix product instead of a scan, a 2 x 2 inverse by formula instead of LAPACK, the camera's
angles by the sum formulas), so results differ by a few ulps per operation, accumulated over
the steps of a run. Forward differences divide such differences by their step; their bound is
derived from the two predictions they difference.
"""

import dataclasses

import numpy as np
import pytest
from scipy.interpolate import CubicSpline

from montecarlo.geometry.rotations import mounting_matrix
from montecarlo.seed001 import estimate as se
from montecarlo.seed001 import estimate_kernels, simulate_kernels
from montecarlo.seed001 import kinematics as kin
from montecarlo.seed001 import linear_model as lin
from montecarlo.seed001 import simulate as sim
from montecarlo.systems import stabilization as ss

D = np.pi / 180.0
EPS = np.finfo(float).eps
RNG = np.random.default_rng(20260)
N_RUNS = 3
ROCK = kin.Rocking(np.full(3, 5 * D), [0.25, 0.4, 0.32], RNG.uniform(0, 2 * np.pi, (N_RUNS, 3)))
SETUP = sim.Setup(duration=10.0, rate=100.0, aim_azimuth=20 * D, aim_pitch=10 * D,
                  image_noise=0.1, gyro_noise=np.radians(0.01) / 60.0)
DELTA_G = RNG.uniform(-1, 1, (N_RUNS, 3)) * D
DELTA_P = RNG.uniform(-1, 1, (N_RUNS, 3)) * D
BIAS = RNG.normal(0, 1, (N_RUNS, 3)) * D / 3600.0
PARAMS = np.concatenate([DELTA_P[:, :1], DELTA_G[:, :2], DELTA_P[:, 2:] - DELTA_G[:, 2:],
                         DELTA_P[:, 1:2], BIAS], axis=1)
INNER_PARAMS = np.concatenate([PARAMS, DELTA_G[:, 2:]], axis=1)
AIM = np.array([[250.0, -120.0], [-180.0, 90.0], [40.0, 260.0]])
"""Off-centre aim points [px], up to 290 px from the centre."""
CONFIGS = {  # mount, gyro sampling, target at t = 0
    "patent-point-centre": ("patent", "point", (0.0, 0.0)),
    "patent-mean-off": ("patent", "interval-mean", AIM),
    "inner-point-off": ("inner-gimbal", "point", AIM),
    "inner-mean-centre": ("inner-gimbal", "interval-mean", (0.0, 0.0)),
}


def _setup(name):
    mount, sampling, target = CONFIGS[name]
    return dataclasses.replace(SETUP, mount=mount, gyro_sampling=sampling, target_px=target)


def _params(setup):
    return INNER_PARAMS if setup.mount == "inner-gimbal" else PARAMS


@pytest.fixture(scope="module", params=list(CONFIGS))
def case(request):
    setup = _setup(request.param)
    return setup, sim.simulate(ROCK, setup, DELTA_G, DELTA_P, BIAS, rng=5, reference=True)


def _model(setup, run):
    return se.LosModel(run.t, run.gyro, run.eta, run.eps, SETUP.camera, mount=setup.mount,
                       gyro_sampling=setup.gyro_sampling)


def _predict(setup, run, params, aim):
    return se.predict_los(run.t, run.gyro, run.eta, run.eps, params, SETUP.camera, aim,
                          mount=setup.mount, gyro_sampling=setup.gyro_sampling)


@pytest.mark.parametrize("name", list(CONFIGS))
def test_simulator_kernels_equal_the_literal_simulator(name):
    """rocking_gyro, rk4_gimbal and target_directions (or the numpy camera chain the compiled
    path falls back to) against the numpy simulator, with and without compensation (the loop
    rate turned and biased; with the inner-gimbal mount the LOS integrated and turned back to
    encoder angles)."""
    setup = _setup(name)
    run = sim.simulate(ROCK, setup, DELTA_G, DELTA_P, BIAS, rng=5, reference=True)
    fast = sim.simulate(ROCK, setup, DELTA_G, DELTA_P, BIAS, rng=5)
    dgz = DELTA_G[:, 2] * 1.1 if setup.mount == "inner-gimbal" else 0.0
    compensation = sim.Compensation(PARAMS[:, :4] * 0.9, BIAS * 1.1, delta_gz=dgz,
                                    mount=setup.mount)
    ref_c = sim.simulate(ROCK, setup, DELTA_G, DELTA_P, BIAS, rng=6, compensation=compensation,
                         reference=True)
    fast_c = sim.simulate(ROCK, setup, DELTA_G, DELTA_P, BIAS, rng=6, compensation=compensation)
    n = setup.times.size
    for a, b in ((run, fast), (ref_c, fast_c)):
        np.testing.assert_allclose(b.gyro, a.gyro, rtol=0, atol=4 * EPS * np.abs(a.gyro).max())
        for angle in ("eta", "eps"):  # a few ulps per Runge-Kutta step
            np.testing.assert_allclose(getattr(b, angle), getattr(a, angle), rtol=0,
                                       atol=n * EPS)
        np.testing.assert_allclose(b.los_error, a.los_error, rtol=0, atol=n * EPS)
        np.testing.assert_allclose(b.los_px, a.los_px, rtol=0,
                                   atol=n * EPS * float(SETUP.camera.k_x))
    assert np.abs(fast_c.los_error).max() < 0.2 * np.abs(fast.los_error).max()  # compensated


def test_rk4_gimbal_equals_integrate_gimbal():
    t = np.linspace(0.0, 2.0, 201)
    t_half = np.sort(np.concatenate([t, t[:-1] + 0.5 * np.diff(t)]))
    rate = RNG.normal(0, 0.3, (N_RUNS, t_half.size, 3))
    noise = RNG.normal(0, 0.01, (N_RUNS, t.size, 3))
    C = mounting_matrix(0.0, *RNG.normal(0, 0.02, (2, N_RUNS))).swapaxes(-1, -2)
    bias = RNG.normal(0, 1e-3, (N_RUNS, 3))
    start = RNG.normal(0, 0.3, (4, N_RUNS))
    loop = kin.matvec(C[:, None], rate - bias[:, None])
    stages = np.stack([loop[:, 0:-1:2], loop[:, 1::2], loop[:, 2::2]], axis=-2)
    stages = stages + kin.matvec(C[:, None], noise)[:, :-1, None, :]
    expected = sim.integrate_gimbal(t, stages, *start)
    got = simulate_kernels.rk4_gimbal(np.diff(t), rate, noise, C, bias, *start)
    for a, b in zip(expected, got, strict=True):
        np.testing.assert_allclose(b, a, rtol=0, atol=t.size * EPS)


def test_spline_at_equals_scipy_cubic_spline():
    """Not-a-knot spline, also on uneven knots (where a swapped coefficient would show)."""
    for t in (np.arange(301) / 100.0, np.sort(RNG.uniform(0.0, 5.0, 40))):
        y = RNG.normal(0, 0.1, (2, t.size, 3)).cumsum(axis=1)
        g1, g2 = se.gauss_points(t)
        spline = CubicSpline(t, y, axis=1)
        for got, g in zip(estimate_kernels.spline_at(t, y, g1, g2), (g1, g2), strict=True):
            np.testing.assert_allclose(got, np.moveaxis(spline(g), 0, -1), rtol=0,
                                       atol=1e-12 * np.abs(y).max())


def test_predicted_pixels_equal_predict_los(case):
    """The fused attitude and camera kernel against predict_los (spline, Magnus steps,
    Hillis-Steele scan, camera_matrix, target_direction) at parameters away from zero, for
    each mount and sampling, with the aim point at the centre and off it."""
    setup, run = case
    model = _model(setup, run)
    bound = run.t.size * EPS * float(SETUP.camera.k_x)  # an ulp per step of angle, in pixels
    for params in (np.zeros_like(_params(setup)), _params(setup), _params(setup) * -1.7):
        for aim in (np.zeros((N_RUNS, 2)), AIM):
            expected = _predict(setup, run, params, aim)
            np.testing.assert_allclose(model.predict(params, aim), expected, rtol=0, atol=bound)


def test_predicted_pixels_with_long_steps_equal_predict_los():
    """At 2 Hz, runs rocking by 20 deg turn by more than the series covers in a step (up to
    0.6 rad, where the series alone would be off) and a run rocking by 1 deg by less: the runs
    that take sine and cosine, and the one that does not, both match."""
    setup = dataclasses.replace(SETUP, rate=2.0, duration=30.0)
    rock = kin.Rocking(np.array([[20.0], [1.0], [20.0]]) * D * np.ones(3), [0.25, 0.4, 0.32],
                       ROCK.phase)
    run = sim.simulate(rock, setup, DELTA_G, DELTA_P, BIAS, rng=5, reference=True)
    g1, g2 = se.gauss_points(run.t)
    spline = CubicSpline(run.t, run.gyro, axis=1)
    h = np.diff(run.t)[:, None]
    w1, w2 = spline(g1), spline(g2)
    angle = np.linalg.norm(0.5 * h * (w1 + w2) + np.sqrt(3.0) / 12.0 * h**2 * np.cross(w1, w2),
                           axis=-1)
    long_step = angle**2 >= estimate_kernels.SERIES_ANGLE_SQ
    assert np.mean(np.any(long_step, axis=0) & ~np.all(long_step, axis=0)) > 0.5  # mixed
    model = _model(setup, run)
    bound = run.t.size * EPS * float(SETUP.camera.k_x)
    for params in (PARAMS, PARAMS * -1.7):
        np.testing.assert_allclose(model.predict(params, AIM), _predict(setup, run, params, AIM),
                                   rtol=0, atol=bound)


def test_shared_motion_gives_the_same_runs():
    """A calibration run and its compensated rerun given the motion computed once equal the
    runs that compute it themselves, bit for bit, on both paths."""
    for reference in (False, True):
        for name in ("patent-point-centre", "inner-mean-centre"):
            setup = _setup(name)
            motion = sim.imu_motion(ROCK, setup, DELTA_G, BIAS, reference)
            compensation = sim.Compensation(PARAMS[:, :4] * 0.9, BIAS, mount=setup.mount)
            for comp in (None, compensation):
                kw = {"rng": 3, "compensation": comp, "reference": reference}
                alone = sim.simulate(ROCK, setup, DELTA_G, DELTA_P, BIAS, **kw)
                shared = sim.simulate(ROCK, setup, DELTA_G, DELTA_P, BIAS, motion=motion, **kw)
                for field in ("gyro", "eta", "eps", "los_px", "los_error"):
                    np.testing.assert_array_equal(getattr(shared, field), getattr(alone, field))


@pytest.mark.parametrize("columns", ["all", "aim"])
def test_jacobian_columns_equal_los_jacobian(case, columns):
    """Each forward-difference column (the parameters, dgz with the inner-gimbal mount, the aim
    point) equals the literal one within the difference of the two predictions it is made of,
    divided by its step (a column in the wrong place or with the wrong step is off by its whole
    size)."""
    setup, run = case
    model = _model(setup, run)
    params = _params(setup)
    predicted, J = model.predict_and_jacobian(params, AIM, columns)
    base = _predict(setup, run, params, AIM)
    expected = se.los_jacobian(run.t, run.gyro, run.eta, run.eps, params, SETUP.camera, base,
                               AIM, mount=setup.mount, gyro_sampling=setup.gyro_sampling,
                               columns=columns)
    assert J.shape == expected.shape
    np.testing.assert_array_equal(predicted, model.predict(params, AIM))
    moves = []
    if columns == "all":
        steps = np.append(se.JACOBIAN_STEP, [1e-6] * (params.shape[-1] - se.JACOBIAN_STEP.size))
        for j, h in enumerate(steps):
            moved = params.copy()
            moved[:, j] += h
            moves.append((moved, AIM, h))
    for j in range(2):
        moved = AIM.copy()
        moved[:, j] += se.AIM_STEP
        moves.append((params, moved, se.AIM_STEP))
    for j, (q, aim, h) in enumerate(moves):
        lit = _predict(setup, run, q, aim)
        bound = (np.abs(model.predict(q, aim) - lit) + np.abs(predicted - base)) / h
        error = np.abs(J[..., j] - expected[..., j])
        assert np.all(error <= 1.01 * bound + 1e-12 * np.abs(expected[..., j]).max()), j
        assert np.abs(expected[..., j]).max() > 100 * bound.max(), j  # the bound is tight


def test_drift_rows_equal_the_numpy_drift_matrix(case):
    setup, run = case
    kw = {"mount": setup.mount}
    expected = lin.drift_matrix(run.t, run.gyro, run.eta, run.eps, SETUP.camera,
                                reference=True, **kw)
    got = lin.drift_matrix(run.t, run.gyro, run.eta, run.eps, SETUP.camera, **kw)
    column_size = np.abs(expected).max(axis=(-4, -3))
    assert np.all(np.abs(got - expected) <= run.t.size * EPS * column_size)


@pytest.mark.parametrize("forgetting", [1.0, 0.999])
def test_rls_pass_equals_recursive_least_squares(forgetting):
    """Random rows, a turning and growing random walk: same mean and covariance."""
    n, p = 400, 5
    rows = RNG.normal(0, 1, (N_RUNS, n, 2, p))
    obs = RNG.normal(0, 1, (N_RUNS, n, 2))
    mean0 = RNG.normal(0, 1, (N_RUNS, p + 2))
    A = RNG.normal(0, 1, (p + 2, p + 2))
    cov0 = A @ A.T + np.eye(p + 2)
    turn = RNG.normal(0, 0.01, (N_RUNS, n))
    F = 1.001 * np.stack([np.stack([np.cos(turn), -np.sin(turn)], -1),
                          np.stack([np.sin(turn), np.cos(turn)], -1)], -2)
    Q = RNG.uniform(0, 1e-3, (N_RUNS, n, 2))
    x, P = se.recursive_least_squares(rows, obs, mean0, cov0, 0.01, forgetting=forgetting,
                                      walk_transition=F, walk_var=Q)
    xk, Pk = estimate_kernels.rls_pass(rows, obs, mean0,
                                       np.broadcast_to(cov0, (N_RUNS, p + 2, p + 2)),
                                       0.01, forgetting, F, Q)
    scale = np.sqrt(np.diagonal(P, axis1=-2, axis2=-1))
    np.testing.assert_allclose(xk / scale, x / scale, rtol=0, atol=1e-10)
    np.testing.assert_allclose(Pk / (scale[..., :, None] * scale[..., None, :]),
                               P / (scale[..., :, None] * scale[..., None, :]), rtol=0,
                               atol=1e-10)


def test_walk_transition_equals_the_numpy_turn():
    """F_k = J_k J_{k-1}^-1 by formula against LAPACK's inverse, on turning and scaling J."""
    n = 300
    J = RNG.normal(0, 1, (N_RUNS, n, 2, 2)) + 3 * np.eye(2)
    expected = J @ np.linalg.inv(np.concatenate([J[:, :1], J[:, :-1]], axis=1))
    got = estimate_kernels.walk_transition(J)
    np.testing.assert_allclose(got[:, 0], np.broadcast_to(np.eye(2), (N_RUNS, 2, 2)), rtol=0,
                               atol=4 * EPS)
    cond = np.linalg.cond(np.concatenate([J[:, :1], J[:, :-1]], axis=1))
    bound = 8 * EPS * cond[..., None, None] * np.abs(expected).max(axis=(-2, -1))[..., None, None]
    assert np.all(np.abs(got - expected) <= bound)


def test_estimate_equals_the_reference_path_within_its_own_rounding(case):
    """The whole estimate against reference=True. The literal path moves by itself when its
    input changes by one ulp (forward differences with 1e-9 steps of the bias): the compiled
    path must stay within ten times that movement of it."""
    setup, run = case
    ref = se.estimate_record(run, setup, reference=True)
    fast = se.estimate_record(run, setup)
    nudged = dataclasses.replace(run, gyro=run.gyro * (1 + EPS * RNG.choice([-1, 1],
                                                                             run.gyro.shape)))
    moved = se.estimate_record(nudged, setup, reference=True)
    self_move = np.abs(moved.values - ref.values)
    aim_move = np.abs(moved.aim_px - ref.aim_px)
    assert fast.passes == ref.passes
    np.testing.assert_array_equal(fast.converged, ref.converged)
    assert np.all(np.abs(fast.values - ref.values) <= 10 * self_move.max(axis=0) + 1e-9
                  * ref.sigma)
    assert np.all(np.abs(fast.aim_px - ref.aim_px) <= 10 * aim_move.max())  # px, either axis
    assert np.abs(fast.values - ref.values).max() > 0  # not the same path
    assert np.all(np.abs(fast.values - ref.values) < 1e-3 * ref.sigma)
    np.testing.assert_allclose(fast.sigma, ref.sigma, rtol=1e-5)
    np.testing.assert_allclose(fast.residual_rms, ref.residual_rms, rtol=1e-5)


def test_run_trials_reference_and_compiled_agree():
    params = {"duration": 10.0, "target_offset": 200.0}
    ref = ss.run_trials(params, np.random.default_rng(4), 2, reference=True)
    fast = ss.run_trials(params, np.random.default_rng(4), 2)
    assert ref.keys() == fast.keys()
    for q in ("dpx", "dgx", "dgy", "dz"):
        assert np.all(np.abs(fast[f"{q}_error"] - ref[f"{q}_error"]) < 1e-3 * ref[f"{q}_sigma"])
    np.testing.assert_allclose(fast["los_rms_after"], ref["los_rms_after"], rtol=1e-3)
    np.testing.assert_array_equal(fast["passes"], ref["passes"])


@pytest.mark.slow
def test_study_is_bit_identical_across_workers_and_chunks(tmp_path):
    """The compiled path's study summary does not depend on the workers or the trials per task
    (each block of trials draws from its own streams, whoever computes it)."""
    from montecarlo.engine.runner import RunOptions, run_study
    from montecarlo.systems import study_from_dict

    raw = {"study": {"name": "stab-det", "system": "stabilization", "trials": 64, "seed": 5},
           "params": {"duration_s": 2.0, "target_offset_px": 100.0}}
    study = study_from_dict(raw, "<test>")
    frames = [run_study(study, RunOptions(progress=False, checkpoint_dir=tmp_path / f"c{i}",
                                          **kw)).to_frame()
              for i, kw in enumerate(({"n_jobs": 1}, {"n_jobs": 2, "chunk_size": 32},
                                      {"n_jobs": 2, "chunk_size": 64}))]
    for frame in frames[1:]:
        assert frame.equals(frames[0])
