"""Seed 001's estimator on a carrier that does not move, where every answer has a closed form.

With the gimbal at rest at zero and a camera without installation angles, the camera frame is
the carrier frame and the line of sight its y axis. A gyro bias ``b`` the estimator assumes
turns the carrier it rebuilds from a zero gyro output by ``-b t``, which moves the target's
image by ``x = -k_x b_z t``, ``z = k_z b_x t`` to first order (scipy's rotation vector gives
the exact image). The installation angles and ``bias_y`` (a roll about the line of sight) do
not move the image of a target at the centre: their standard deviations stay the prior's. For
``bias_z`` (image x) and ``bias_x`` (image z) the estimator is a linear Gaussian regression of
each image axis on ``[k t, 1]`` with the prior ``PRIOR_SIGMA``; with gyro noise the LOS walk
adds ``(q k)^2 min(t_i - t_0, t_j - t_0)`` to the image noise's covariance ``r^2 I``. These
regressions, the rotations and the exponential of a constant rate are worked here with numpy
and scipy, not with the package.
"""

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from montecarlo.geometry.camera import Camera
from montecarlo.seed001 import estimate as se
from montecarlo.seed001 import kinematics as kin
from montecarlo.seed001 import simulate as sim

CAMERA = Camera.from_degrees(5.0, 4.0, 1024, 768)  # k_x != k_z: an axis swapped shows
KX, KZ = float(CAMERA.k_x), float(CAMERA.k_z)
T = 3.0 + np.arange(101) / 25.0
"""4 s at 25 Hz starting at 3 s (a walk counted from t = 0 instead of t[0] shows)."""
N = T.size
ZERO = np.zeros(N)
R_PX = 0.1
SIG_B, SIG_A, SIG_ANGLE = (se.PRIOR_SIGMA[k] for k in ("bias", "offset", "angle"))


def _gls(y, k, q=0.0, mean0=0.0, r=R_PX, lam=1.0):
    """Posterior mean and covariance of ``[b, a]`` for ``y = k (t - t0) b + a + walk + noise``
    with the prior ``N([0, mean0], diag(SIG_B^2, SIG_A^2))``; with forgetting ``lam``, sample
    k's information weighted by ``lam^(N-1-k)`` and the prior's by ``lam^N``."""
    s = T - T[0]
    H = np.stack([k * s, np.ones(N)], -1)
    noise_var = r**2 * lam ** -(N - 1.0 - np.arange(N))
    if q == 0.0:  # a diagonal covariance: weights (no N x N solve)
        weighted = H / noise_var[:, None]
    else:
        weighted = np.linalg.solve(np.diag(noise_var) + (q * k) ** 2 * np.minimum.outer(s, s), H)
    prior_info = np.diag([SIG_B**-2, SIG_A**-2]) * lam**N
    post = np.linalg.inv(prior_info + weighted.T @ H)
    mean = post @ (prior_info @ [0.0, mean0] + weighted.T @ y)
    return mean, post


def _image(omega, aim=(0.0, 0.0)):
    """Image [px] of the target seen at ``aim`` at ``T[0]`` by a camera on a carrier turning at
    the constant body rate ``omega``: ``u_k = exp([omega (t_k - t_0)]x)^T e`` (scipy)."""
    e = np.array([aim[0] / KX, 1.0, aim[1] / KZ])
    R = Rotation.from_rotvec(np.outer(T - T[0], omega)).as_matrix()
    u = np.swapaxes(R, -1, -2) @ (e / np.linalg.norm(e))
    return np.stack([KX * u[:, 0] / u[:, 1], KZ * u[:, 2] / u[:, 1]], -1)


@pytest.mark.parametrize("sampling", ["point", "interval-mean"])
def test_carrier_attitude_of_a_constant_rate_is_its_exponential_in_a_deep_batch(sampling):
    """A constant body rate ``w`` turns the carrier by ``exp([w (t - t0)]x)`` (scipy's rotation
    vector); the rates have the batch shape (2, 3), and their interval means are the rate."""
    omega = np.random.default_rng(3).normal(0.0, 0.2, (2, 3, 3))
    R = se.carrier_attitude(T, np.broadcast_to(omega[..., None, :], (2, 3, N, 3)), sampling)
    expected = Rotation.from_rotvec((omega[..., None, :] * (T - T[0])[:, None]).reshape(-1, 3))
    assert R.shape == (2, 3, N, 3, 3)
    np.testing.assert_allclose(R, expected.as_matrix().reshape(2, 3, N, 3, 3), rtol=0,
                               atol=1e-12)


@pytest.mark.parametrize("sampling", ["point", "interval-mean"])
def test_predict_los_takes_the_batch_from_whichever_input_has_it(sampling):
    """The image of a still or turning carrier against :func:`_image`, with a batch of three in
    the parameters (the biases), in the gyro output (constant rates) or in the aim point only."""
    kw = {"gyro_sampling": sampling}
    g = np.random.default_rng(4)
    biases = g.normal(0.0, 3e-5, (3, 3))
    rates = g.normal(0.0, 3e-3, (3, 3))
    aims = np.array([[40.0, -25.0], [-300.0, 120.0], [0.0, 200.0]])
    params = np.zeros((3, 8))
    params[:, 5:8] = biases
    cases = [  # (gyro, params, aim, expected)
        (np.zeros((N, 3)), params, 0.0, [_image(-b) for b in biases]),
        (np.broadcast_to(rates[:, None, :], (3, N, 3)), np.zeros(8), aims[0],
         [_image(w, aims[0]) for w in rates]),
        (np.broadcast_to(rates[0], (N, 3)), np.zeros(8), aims, [_image(rates[0], a)
                                                                for a in aims]),
    ]
    for gyro, p, aim, expected in cases:
        got = se.predict_los(T, gyro, ZERO, ZERO, p, CAMERA, aim, **kw)
        assert got.shape == (3, N, 2)
        np.testing.assert_allclose(got, np.array(expected), rtol=0, atol=1e-9)


@pytest.mark.parametrize("reference", [False, True])
@pytest.mark.parametrize("mount", ["patent", "inner-gimbal"])
@pytest.mark.parametrize("gyro_noise", [0.0, np.radians(0.02) / 60.0])
def test_a_still_recording_keeps_the_prior_of_what_it_cannot_see(gyro_noise, mount, reference):
    """The target stays at the centre: every estimate is zero after one pass, the aim point is
    the centre, and the standard deviations are the prior's for the angles and ``bias_y`` and
    the regression's for ``bias_z`` (x) and ``bias_x`` (z), with the LOS walk of the gyro noise
    (0.02 deg/sqrt(h)) in the image noise's covariance."""
    est = se.estimate(T, np.zeros((N, 3)), ZERO, ZERO, np.zeros((N, 2)), CAMERA, R_PX,
                      gyro_noise, mount=mount, reference=reference)
    n = 9 if mount == "inner-gimbal" else 8
    assert est.values.shape == (n,) and est.covariance.shape == (n, n)
    assert est.passes == 1 and est.converged
    np.testing.assert_array_equal(est.values, np.zeros(n))
    np.testing.assert_array_equal(est.aim_px, [0.0, 0.0])
    assert est.residual_rms == 0.0
    unseen = [0, 1, 2, 3, 4, 6] + [8] * (n - 8)
    np.testing.assert_allclose(est.sigma[unseen], [SIG_ANGLE] * 5 + [SIG_B]
                               + [SIG_ANGLE] * (n - 8), rtol=1e-12)
    for index, k in ((7, -KX), (5, KZ)):
        _, post = _gls(np.zeros(N), k, gyro_noise)
        assert est.sigma[index] == pytest.approx(np.sqrt(post[0, 0]), rel=1e-9)


@pytest.mark.parametrize("reference", [False, True])
def test_drifting_images_in_a_batch_give_the_regressions_estimates(reference):
    """Three recordings of one still carrier (the batch is in the images only) whose images
    drift as the biases ``[2, 0, -1]``, ``[-1, 0, 3]`` and ``[0, 0, 0]`` x 1e-5 rad/s would turn
    them, plus 0.1 px of image noise: ``bias_z``, ``bias_x`` and the aim point are the
    regressions' means (each axis on ``[k t, 1]``, the aim's prior centred at the first image),
    the residual RMS that of the regressions' residuals.

    Tolerances: the exact kinematics differ from the regression by the image's turn about its
    aim point (the aim is within 0.05 px of the centre, 4e-6 rad off the axis, times the turn
    8e-5 rad) and by the camera angles the prior lets trade against a bias (a few 1e-5 of it):
    below 1e-3 of a standard deviation."""
    biases = np.array([[2.0, 0.0, -1.0], [-1.0, 0.0, 3.0], [0.0, 0.0, 0.0]]) * 1e-5
    noise = R_PX * np.random.default_rng(1).standard_normal((3, N, 2))
    los = np.stack([_image(-b) for b in biases]) + noise
    est = se.estimate(T, np.zeros((N, 3)), ZERO, ZERO, los, CAMERA, R_PX, reference=reference)
    assert est.values.shape == (3, 8) and est.aim_px.shape == (3, 2)
    assert np.all(est.converged) and est.passes == 2
    residual = np.empty_like(los)
    for i in range(3):
        for axis, (index, k) in enumerate(((7, -KX), (5, KZ))):
            mean, post = _gls(los[i, :, axis], k, mean0=los[i, 0, axis])
            sig = np.sqrt(np.diag(post))
            assert abs(est.values[i, index] - mean[0]) < 1e-3 * sig[0], (i, axis)
            assert abs(est.aim_px[i, axis] - mean[1]) < 1e-3 * sig[1], (i, axis)
            residual[i, :, axis] = los[i, :, axis] - k * (T - T[0]) * mean[0] - mean[1]
        # the data see the biases: far from the prior
        assert np.all(est.sigma[i, [5, 7]] < 0.02 * SIG_B)
    np.testing.assert_allclose(est.residual_rms, np.sqrt(np.mean(residual**2, axis=(1, 2))),
                               rtol=1e-6)


@pytest.mark.parametrize("reference", [False, True])
def test_weak_images_keep_the_prior_at_zero_on_every_pass(reference):
    """With 30 px of image noise the data and the prior weigh alike on the biases (posterior
    sigma 0.67-0.69 of the prior's): the estimate is the regression's with the prior centred at
    zero, on the last pass as on the first (a prior re-centred on an earlier pass's estimate
    would move it by about half a sigma). Biases of 2-4e-4 rad/s, 3 passes. Tolerance 0.1 sigma:
    the bias's trade with the camera angles the prior allows, worked out below 0.02 sigma."""
    r = 30.0
    biases = np.array([[3.0, 0.0, -2.0], [-2.0, 0.0, 4.0]]) * 1e-4
    noise = r * np.random.default_rng(2).standard_normal((2, N, 2))
    los = np.stack([_image(-b) for b in biases]) + noise
    est = se.estimate(T, np.zeros((N, 3)), ZERO, ZERO, los, CAMERA, r, reference=reference)
    assert np.all(est.converged) and est.passes > 2
    for i in range(2):
        for axis, (index, k) in enumerate(((7, -KX), (5, KZ))):
            mean, post = _gls(los[i, :, axis], k, mean0=los[i, 0, axis], r=r)
            sig = np.sqrt(np.diag(post))
            assert 0.5 * SIG_B < sig[0] < 0.8 * SIG_B  # the prior matters
            assert abs(est.values[i, index] - mean[0]) < 0.1 * sig[0], (i, axis)
            assert abs(est.aim_px[i, axis] - mean[1]) < 0.1 * sig[1], (i, axis)


@pytest.mark.parametrize("reference", [False, True])
def test_forgetting_on_a_still_recording(reference):
    """Forgetting ``lam = 0.99`` over 101 samples: what the data do not see has the prior's
    variance divided by ``lam`` at every sample, ``sigma lam^(-N/2)``; ``bias_z`` and ``bias_x``
    have the regressions' with sample k weighted by ``lam^(N-1-k)`` and the prior by
    ``lam^N``."""
    lam = 0.99
    est = se.estimate(T, np.zeros((N, 3)), ZERO, ZERO, np.zeros((N, 2)), CAMERA, R_PX,
                      forgetting=lam, reference=reference)
    np.testing.assert_allclose(est.sigma[[0, 1, 2, 3, 4, 6]] * lam ** (N / 2),
                               [SIG_ANGLE] * 5 + [SIG_B], rtol=1e-9)
    for index, k in ((7, -KX), (5, KZ)):
        post = _gls(np.zeros(N), k, lam=lam)[1]
        assert est.sigma[index] == pytest.approx(np.sqrt(post[0, 0]), rel=1e-9)


# --- the recursion against batch least squares, written out ----------------------------------


def _batch_gls(rows, obs, mean0, cov0, r, walk_var, transition=None, forgetting=1.0):
    """Posterior of ``[x, w_0]`` for ``y_k = A_k x + w_k + v_k``, ``w_k = F_k w_{k-1} + q_k``,
    ``q_k ~ N(0, diag(walk_var_k))``, as one generalised least squares: ``w_k = Phi_k w_0 +
    e_k`` with ``Phi_k = F_k ... F_1`` and ``e_k = sum_j F_k ... F_{j+1} q_j``. With
    ``forgetting = lam`` (no walk): step k's information weighted by ``lam^(N-1-k)``, the
    prior's by ``lam^N``."""
    n, _, p = rows.shape
    F = np.broadcast_to(np.eye(2), (n, 2, 2)) if transition is None else transition
    carry = np.zeros((n, n, 2, 2))  # carry[k, j] = F_k ... F_{j+1} for j <= k
    for j in range(n):
        carry[j, j] = np.eye(2)
        for k in range(j + 1, n):
            carry[k, j] = F[k] @ carry[k - 1, j]
    cov_e = np.zeros((2 * n, 2 * n))
    for j in range(1, n):
        B = carry[:, j].reshape(2 * n, 2)
        cov_e += B @ np.diag(walk_var[j]) @ B.T
    H = np.concatenate([rows.reshape(-1, p), carry[:, 0].reshape(2 * n, 2)], axis=1)
    weight = np.repeat(forgetting ** (n - 1 - np.arange(n)), 2)
    cov_y = cov_e + r * np.diag(1.0 / weight)
    prior_info = np.linalg.inv(cov0) * forgetting**n
    post = np.linalg.inv(prior_info + H.T @ np.linalg.solve(cov_y, H))
    return post @ (prior_info @ mean0 + H.T @ np.linalg.solve(cov_y, obs.ravel())), post


@pytest.mark.parametrize("held_by", ["rows", "obs", "prior_mean", "prior_cov", "walk_var",
                                     "walk_transition"])
def test_rls_takes_the_batch_from_whichever_input_has_it(held_by):
    """Three problems that differ in one input only (a turning, growing walk), against
    :func:`_batch_gls` each."""
    n, p, r = 30, 3, 0.04
    g = np.random.default_rng(8)
    scale = np.array([1.0, 0.5, 2.0])
    turn = g.uniform(-0.1, 0.1, n) * (scale[:, None] if held_by == "walk_transition" else 1.0)
    inputs = {"rows": g.normal(size=(n, 2, p)), "obs": g.normal(size=(n, 2)),
              "prior_mean": g.normal(size=p + 2), "prior_cov": np.diag([4.0, 4.0, 4.0, 9.0, 9.0]),
              "walk_var": g.uniform(0.01, 0.05, (n, 2)),
              "walk_transition": 1.01 * np.stack([np.stack([np.cos(turn), -np.sin(turn)], -1),
                                                  np.stack([np.sin(turn), np.cos(turn)], -1)],
                                                 -2)}
    if held_by != "walk_transition":  # the turns differ, the growth 1.01 is shared
        inputs[held_by] = inputs[held_by] * scale.reshape(3, *[1] * inputs[held_by].ndim)
    mean, cov = se.recursive_least_squares(inputs["rows"], inputs["obs"], inputs["prior_mean"],
                                           inputs["prior_cov"], r,
                                           walk_transition=inputs["walk_transition"],
                                           walk_var=inputs["walk_var"])
    assert mean.shape == (3, p + 2) and cov.shape == (3, p + 2, p + 2)
    for i in range(3):
        one = {k: v[i] if k == held_by else v for k, v in inputs.items()}
        m, c = _batch_gls(one["rows"], one["obs"], one["prior_mean"], one["prior_cov"], r,
                          one["walk_var"], one["walk_transition"])
        np.testing.assert_allclose(mean[i, :p], m[:p], rtol=1e-8)
        np.testing.assert_allclose(cov[i, :p, :p], c[:p, :p], rtol=1e-8)


def test_rls_with_forgetting_is_exponentially_weighted_least_squares():
    """Dividing the covariance by lam before each update weights step k by lam^(N-1-k) and the
    prior by lam^N (information form: I <- lam I + A^T A / r, b <- lam b + A^T y / r)."""
    n, p, r, lam = 40, 3, 0.01, 0.9
    g = np.random.default_rng(9)
    rows, obs = g.normal(size=(n, 2, p)), g.normal(size=(n, 2))
    mean0, cov0 = g.normal(size=p + 2), np.diag([4.0, 4.0, 4.0, 9.0, 9.0])
    mean, cov = se.recursive_least_squares(rows, obs, mean0, cov0, r, forgetting=lam)
    m, c = _batch_gls(rows, obs, mean0, cov0, r, np.zeros((n, 2)), forgetting=lam)
    np.testing.assert_allclose(mean, m, rtol=1e-8)
    np.testing.assert_allclose(cov, c, rtol=1e-8, atol=1e-14)


def test_ten_passes_by_default_when_a_pass_never_counts_as_converged():
    """``tol = 0``: no step is below zero standard deviations, so every pass runs (10 by
    default) and the estimate is not converged; one pass with ``max_passes = 1``."""
    args = (T, np.zeros((N, 3)), ZERO, ZERO, np.zeros((N, 2)), CAMERA, R_PX)
    est = se.estimate(*args, tol=0.0)
    assert est.passes == 10 and not est.converged
    assert se.estimate(*args, tol=0.0, max_passes=1).passes == 1
    none = se.estimate(*args, max_passes=0)  # no pass: the prior, not converged
    assert none.passes == 0 and none.converged.dtype == np.bool_ and not none.converged
    np.testing.assert_array_equal(none.values, np.zeros(8))
    np.testing.assert_allclose(none.sigma, [SIG_ANGLE] * 5 + [SIG_B] * 3, rtol=1e-12)


def test_one_pass_sees_the_inner_gimbal_dgz_to_first_order():
    """The first pass's rows are the first-order model about zero, ``dgz`` included with the
    inner-gimbal mount: on noise-free exact data (10 s at 25 Hz, angles of 0.3-0.7 deg) its
    estimate of the five angles is off only by the second-order terms, a few percent (as the
    patent mount's single pass in ``test_printed_h21_biases_the_single_pass_estimate``)."""
    d = np.pi / 180.0
    setup = sim.Setup(duration=10.0, rate=25.0, aim_azimuth=20 * d, aim_pitch=10 * d,
                      mount="inner-gimbal")
    rock = kin.Rocking(np.full(3, 5 * d), [0.25, 0.4, 0.32], [0.0, 1.0, 2.0])
    dg, dp = np.array([0.5, -0.3, 0.7]) * d, np.array([0.4, 0.6, -0.6]) * d
    run = sim.simulate(rock, setup, dg, dp)
    truth = np.array([dp[0], dg[0], dg[1], dp[2] - dg[2], dg[2]])
    one = se.estimate(run.t, run.gyro, run.eta, run.eps, run.los_px_true, setup.camera,
                      setup.image_noise, mount="inner-gimbal", max_passes=1)
    assert one.passes == 1
    assert np.all(np.abs(one.values[[0, 1, 2, 3, 8]] - truth) < 0.05 * np.abs(truth))


@pytest.mark.parametrize("reference", [False, True])
@pytest.mark.parametrize("held_by", ["gyro", "eta", "eps"])
def test_a_still_recording_batch_held_by_one_input(held_by, reference):
    """Three still recordings whose target stays at the centre, differing in one input only.

    ``gyro``: constant outputs ``g`` (x and z, up to 3e-5 rad/s) with the gimbal at rest: no
    image motion means ``bias = g``, the regressions of ``-k g t`` (x on ``bias_z``) and
    ``k g t`` (z on ``bias_x``). ``eta`` / ``eps``: the gimbal at rest at azimuth or pitch
    ``a``; the image then moves with the biases' components along the camera's axes: image x
    with ``bias_z`` (azimuth) or ``[0, -sin a, cos a]`` (pitch), image z with
    ``[cos a, sin a, 0]`` (azimuth) or ``bias_x`` (pitch), whose variances are the
    regressions'; the component along the LOS, ``[-sin a, cos a, 0]`` or ``[0, cos a, sin a]``,
    keeps the prior's, and so do the angles."""
    g = np.array([[2.0, 0.0, -1.0], [-1.0, 0.0, 3.0], [0.5, 0.0, 0.5]]) * 1e-5
    a = np.array([0.3, -0.5, 1.0])
    gyro, eta, eps = np.zeros((N, 3)), ZERO, ZERO
    if held_by == "gyro":
        gyro = np.broadcast_to(g[:, None, :], (3, N, 3))
    elif held_by == "eta":
        eta = np.broadcast_to(a[:, None], (3, N))
    else:
        eps = np.broadcast_to(a[:, None], (3, N))
    est = se.estimate(T, gyro, eta, eps, np.zeros((N, 2)), CAMERA, R_PX, reference=reference)
    assert est.values.shape == (3, 8) and est.covariance.shape == (3, 8, 8)
    np.testing.assert_allclose(est.sigma[:, :5], SIG_ANGLE, rtol=1e-9)
    s = T - T[0]
    for i in range(3):
        cov = est.covariance[i, 5:8, 5:8]
        if held_by == "gyro":
            for index, k, y in ((7, -KX, -KX * g[i, 2] * s), (5, KZ, KZ * g[i, 0] * s)):
                mean, post = _gls(y, k)
                assert abs(est.values[i, index] - mean[0]) < 1e-3 * np.sqrt(post[0, 0])
            continue
        c, sn = np.cos(a[i]), np.sin(a[i])
        if held_by == "eta":
            along_x, along_z, los = [0.0, 0.0, 1.0], [c, sn, 0.0], [-sn, c, 0.0]
        else:
            along_x, along_z, los = [0.0, -sn, c], [1.0, 0.0, 0.0], [0.0, c, sn]
        for u, k in ((along_x, -KX), (along_z, KZ)):
            assert np.dot(u, cov @ u) == pytest.approx(_gls(np.zeros(N), k)[1][0, 0], rel=1e-9)
        assert np.dot(los, cov @ los) == pytest.approx(SIG_B**2, rel=1e-9)
        assert np.all(np.abs(est.values[i]) < 1e-9 * est.sigma[i])  # zero but for rounding


def test_names_and_the_compensation_taken_from_an_estimate():
    """The state order written out, and the loop's corrections picked from it by name
    (claim 1, fourth step): ``[dpx, dgx, dgy, dz]``, the three biases, and ``dgz`` for the
    inner-gimbal mount only (the patent mount's loop needs no ``dgz``: zero)."""
    names = ("delta_px", "delta_gx", "delta_gy", "delta_z", "delta_py",
             "bias_x", "bias_y", "bias_z")
    assert se.parameter_names() == names
    assert se.parameter_names("inner-gimbal") == (*names, "delta_gz")
    values = np.arange(1.0, 10.0)
    for mount, n in (("patent", 8), ("inner-gimbal", 9)):
        est = se.Estimate(values=values[:n], covariance=np.eye(n), passes=1,
                          converged=np.True_, residual_rms=0.0, aim_px=np.zeros(2), mount=mount)
        assert est.names == se.parameter_names(mount)
        comp = est.compensation()
        by_name = dict(zip(est.names, values[:n], strict=True))
        np.testing.assert_array_equal(comp.angles, [by_name[k] for k in names[:4]])
        np.testing.assert_array_equal(comp.gyro_bias, [by_name[k] for k in names[5:8]])
        assert comp.delta_gz == by_name.get("delta_gz", 0.0) and comp.mount == mount
