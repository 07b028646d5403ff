"""Seed 003's procedure simulated and fitted for a block of trials at once (the study's fast path).

:func:`procedure_block` does what a loop of
:func:`montecarlo.seed003.procedure.simulate_procedure` and
:func:`montecarlo.seed003.procedure.fit_procedure` does, trial after trial, but with a leading
trial axis on every array:

* the same draws in the same order (one ``standard_normal`` call whose rows are the trials:
  a generator's normal stream does not depend on how it is cut into calls);
* the same residuals (the procedure's own model, evaluated with a batch axis), the same central
  differences for the Jacobian and the residual covariance, the same two generalised
  least-squares passes, the same starts and choice of the smallest chi-square when rolls are
  fitted, and the same separability test;
* only the nonlinear solve differs: a batched Levenberg-Marquardt iteration (Marquardt's
  diagonal scaling, each trial with its own damping, each stopped when its step is below
  :data:`STEP_TOL`) in place of MINPACK's, which the literal path runs one trial at a time.
  Where the data do not determine every parameter the two may end in different places of the
  valley, so a trial the batch finds not separable, or whose solution wandered beyond
  :data:`FAR`, is fitted again by the literal path.

The two minimise the same cost from the same start, so they agree to the rounding of the
converged solution (tests/test_collimation_batch.py states and checks the tolerance). The literal
loop stays the reference (``run_trials(..., reference=True)`` of the collimation system).

References
----------
seed 003, section 3.2 (the procedure; least squares of the readings, iterated).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from montecarlo.seed003 import procedure as pr
from montecarlo.seed003 import reference as ref
from montecarlo.seed003.model import Noise, attitude_angles, attitude_matrix, direction, wrap

FloatArray = NDArray[np.float64]

STEP_TOL = 1e-14
"""A trial's Levenberg-Marquardt iteration stops once every component of its step is below this
[rad] (1e-14 rad = 2e-9 arc-seconds), or its step promises to lower the cost by less than
:data:`COST_TOL` of it, or its damping exceeds :data:`MAX_DAMPING`."""

COST_TOL = 1e-10
"""Relative decrease of the cost below which a step is not worth taking. The rounding of the
residuals (about 1e-16 rad on angles of order 1 rad, whitened by 1/sigma with sigma about
1e-5 rad) moves the cost by about 1e-11 of itself, and decreases promised below 1e-10 of it are
observed to be rejected as often as taken. At the minimum the cost is about the degrees of
freedom (10 to 30), so a decrease of 1e-10 of it is a distance of about 1e-4 sigma from the
minimum: 1e-9 rad for sigma 1e-5 rad."""

MIN_DAMPING = 1e-12
"""Smallest damping (relative to the diagonal): after a run of good steps a bad one needs only a
few increases to be damped enough."""

MAX_DAMPING = 1e12
"""Damping beyond which a trial's iteration has converged (relative to the diagonal)."""

MAX_ITERATIONS = 200
"""Iterations after which a batch stops, converged or not (never reached in the tests)."""

FAR = 1.0
"""A batched solution with a parameter or a core parameter's sigma beyond this [rad] has wandered
off along a direction the data hardly determine (the offsets and rolls are degrees at most);
that trial, like one the batch finds not separable, is fitted again by the literal path, whose
verdict it keeps. Where the layout does not determine the offsets (no pitch mirror with
fitted rolls, say) the literal fit itself may wander, and the two paths can then give
different numbers, both meaningless: their sigmas say so."""


@dataclass(frozen=True)
class BatchData:
    """Readings of ``T`` calibrations by the procedure, one row per trial, (T, rows) [rad].

    The layout (rows, reference mirrors, recorded roll or not) is common to all trials; the
    fields mean what they mean in :class:`montecarlo.seed003.procedure.ProcedureData`.
    """

    theodolite_az: FloatArray
    theodolite_el: FloatArray
    ins_az: FloatArray
    ins_el: FloatArray
    ins_roll: FloatArray | None = None
    center: int | None = None
    roll_mirror: int | None = None

    @property
    def trials(self) -> int:
        return self.ins_az.shape[0]

    def trial(self, i: int) -> pr.ProcedureData:
        """Trial ``i`` as the literal path's :class:`ProcedureData`."""
        return pr.ProcedureData(self.theodolite_az[i], self.theodolite_el[i], self.ins_az[i],
                                self.ins_el[i],
                                None if self.ins_roll is None else self.ins_roll[i],
                                self.center, self.roll_mirror)


def simulate_block(axis_az: float, axis_el: float, az: FloatArray, el: FloatArray, noise: Noise,
                   rng: np.random.Generator, n: int, *, side: float = 1.0,
                   frame_heading: float = 0.0, az_center: float = 0.0,
                   reference_rows: bool = True, with_roll: bool = True) -> BatchData:
    """``n`` calls of :func:`montecarlo.seed003.procedure.simulate_procedure` at once.

    Draws from ``rng`` exactly the numbers the ``n`` calls would draw, in the same order, so the
    readings equal theirs (to the rounding of the vectorised arithmetic).
    """
    az, el = np.asarray(az, float), np.asarray(el, float)
    m = az.size
    ref_az = np.array([az_center, float(ref.roll_mirror_azimuth(az_center, side))])
    all_az, all_el = np.concatenate([ref_az, az]), np.concatenate([np.zeros(2), el])
    k = m + 2 if reference_rows else m
    families = 5 if with_roll else 4
    draws = rng.standard_normal((n, m + 2 + k * families + (0 if reference_rows else 4)))
    rolls = noise.mount_roll * draws[:, :m + 2]
    if reference_rows:
        heading, pitch, roll = attitude_angles(
            ref.attitude_at(axis_az, axis_el, all_az, all_el, rolls))
        heading = wrap(heading + frame_heading)
        t_az, t_el = all_az, all_el
    else:
        scale = np.array([noise.ins_heading, noise.ins_pitch] * 2)
        heading, pitch, roll = ref.relative_readings(
            axis_az, axis_el, az, el, rolls[:, 2:], (az_center, 0.0, rolls[:, :1]),
            (ref_az[1], 0.0, rolls[:, 1:2]), side,
            reference_error=scale * draws[:, None, -4:])
        t_az, t_el = az, el
    e = [draws[:, m + 2 + j * k:m + 2 + (j + 1) * k] for j in range(families)]
    return BatchData(
        theodolite_az=wrap(t_az + noise.theodolite * e[0]),
        theodolite_el=t_el + noise.theodolite * e[1],
        ins_az=wrap(heading + noise.ins_heading * e[2]),
        ins_el=pitch + noise.ins_pitch * e[3],
        ins_roll=roll + noise.ins_roll * e[4] if with_roll else None,
        center=0 if reference_rows else None, roll_mirror=1 if reference_rows else None)


@dataclass(frozen=True)
class BatchFit:
    """Result of :func:`fit_block`, one row per trial; NaN rows where the fit failed.

    ``values`` (T, p) and ``covariance`` (T, p, p) [rad, rad^2] in the order ``names``;
    ``chi2`` (T,) including the roll prior, ``dof``; ``residuals`` (T, 2m) unwhitened (headings,
    then pitches) [rad]; ``rolls`` (T, pointings) the absolute rolls the model used [rad];
    ``ok`` (T,) whether the fit succeeded; ``roll_recorded`` whether the rolls were read.
    """

    names: tuple[str, ...]
    values: FloatArray
    covariance: FloatArray
    chi2: FloatArray
    dof: int
    residuals: FloatArray
    rolls: FloatArray
    ok: NDArray[np.bool_]
    roll_recorded: bool


class _Batch:
    """The procedure's residual model with a leading trial axis on parameters and readings.

    The finite differences are grouped: the residuals of a measured mirror depend on its own
    readings and roll and on those of the reference pointings only, so the columns of all
    measured mirrors are perturbed in one evaluation (they touch disjoint residuals) and each
    reference column in its own. Every residual is computed from the same numbers as when its
    column is perturbed alone, so the differences equal the one-column-at-a-time ones.
    """

    def __init__(self, data: BatchData, side: float, free_roll: bool, roll_sigma: float):
        self.model = pr._Model(data.trial(0), side, free_roll, roll_sigma)
        mdl = self.model
        self.z0 = np.concatenate([getattr(data, g)[:, mdl.rows] for g in mdl.groups], axis=-1)
        self.n_params = len(mdl.names)
        position = {int(j): i for i, j in enumerate(mdl.k)}  # row -> measured mirror
        self.z_own = [(f, position.get(int(j), -1)) for f in range(len(mdl.groups))
                      for j in mdl.rows]
        if data.center is None:
            pointing = [*range(mdl.m), -1, -1]  # the two reference pointings last
        else:
            pointing = [position.get(j, -1) for j in range(data.ins_az.shape[-1])]
        self.x_own = [(0, -1)] * mdl.n_core + [(0, j if free_roll else -1) for j in
                                               (pointing if free_roll else [-1] * mdl.n_prior)]

    def residuals(self, x: FloatArray, z: FloatArray,
                  reference_error: FloatArray | None = None) -> FloatArray:
        return self.model.residuals(x, z, reference_error)

    def _differences(self, own: list[tuple[int, int]], columns: NDArray[np.intp],
                     evaluate: Callable[[FloatArray], FloatArray]) -> FloatArray:
        """(T, 2m, len(columns)) central differences of the residuals over ``columns``.

        ``own[c] = (family, mirror)``: column ``c`` moves the residuals of that measured mirror
        alone (the columns of one family, e.g. the INS headings, are perturbed together), or
        of all mirrors when ``mirror`` is -1. ``evaluate(steps)`` gives the residuals
        (T, S, 2m) at the perturbations ``steps`` (S, n).
        """
        m = self.model.m
        shared = [[j] for j, c in enumerate(columns) if own[c][1] < 0]
        families: dict[int, list[int]] = {}
        for j, c in enumerate(columns):
            if own[c][1] >= 0:
                families.setdefault(own[c][0], []).append(j)
        colours = shared + list(families.values())
        steps = np.zeros((2 * len(colours), len(own)))
        for i, colour in enumerate(colours):
            steps[i, columns[colour]] = pr._STEP
            steps[len(colours) + i, columns[colour]] = -pr._STEP
        r = evaluate(steps)
        D = (r[:, :len(colours)] - r[:, len(colours):]) / (2 * pr._STEP)  # (T, colours, 2m)
        out = np.zeros((r.shape[0], 2 * m, columns.size))
        for i, colour in enumerate(colours):
            if len(colour) == 1 and own[columns[colour[0]]][1] < 0:
                out[:, :, colour[0]] = D[:, i]
                continue
            pos = np.array([own[columns[j]][1] for j in colour])
            for half in (0, m):  # headings, then pitches
                out[:, half + pos, colour] = D[:, i, half + pos]
        return out

    def jacobian_x(self, x: FloatArray, z: FloatArray, free: NDArray[np.intp]) -> FloatArray:
        """(T, 2m, len(free)) central differences, as ``_Model.jacobian_x`` per trial."""
        return self._differences(self.x_own, free, lambda steps: self.residuals(
            x[:, None, :] + steps, z[:, None, :]))

    def residual_covariance(self, x: FloatArray, z: FloatArray, sigma_ins: float,
                            sigma_theodolite: float) -> FloatArray:
        """(T, 2m, 2m), as ``_Model.residual_covariance`` per trial [rad^2]."""
        G = self._differences(self.z_own, np.arange(z.shape[-1]), lambda steps: self.residuals(
            x[:, None, :], z[:, None, :] + steps))
        s = np.where(self.model.is_ins, sigma_ins, sigma_theodolite)
        cov = (G * s**2) @ np.swapaxes(G, 1, 2)
        if not self.model.data.has_reference:
            H = self.model.reference_error_columns(x, z)
            cov = cov + sigma_ins**2 * (H @ np.swapaxes(H, 1, 2))
        return cov


def _levenberg_marquardt(fun: Callable[[FloatArray, NDArray[np.intp]], FloatArray],
                         jac: Callable[[FloatArray, NDArray[np.intp]], FloatArray],
                         x0: FloatArray) -> FloatArray:
    """Minimise ``|fun(x)|^2`` for every row of ``x0`` (T, p), each trial on its own.

    ``fun(x, idx)``/``jac(x, idx)`` evaluate the rows ``idx`` of the batch at ``x`` (len(idx), p).
    Marquardt's step ``(A + mu diag A) d = -J'r``; mu /10 after a step that lowers the cost,
    x10 after one that does not.
    """
    x = x0.copy()
    everyone = np.arange(x.shape[0])
    r = fun(x, everyone)
    cost = np.einsum("ti,ti->t", r, r)
    J = jac(x, everyone)
    mu = np.full(x.shape[0], 1e-3)
    active = np.ones(x.shape[0], bool)
    for _ in range(MAX_ITERATIONS):
        idx = np.flatnonzero(active)
        if idx.size == 0:
            break
        Ji, ri = J[idx], r[idx]
        A = np.swapaxes(Ji, 1, 2) @ Ji
        g = np.einsum("tij,ti->tj", Ji, ri)
        diag = np.diagonal(A, axis1=1, axis2=2)
        damped = A + mu[idx, None, None] * (np.eye(A.shape[-1]) * np.where(diag > 0, diag, 1.0)
                                            [:, None, :])
        d = np.linalg.solve(damped, -g[..., None])[..., 0]
        predicted = -2.0 * np.einsum("ti,ti->t", g, d) - np.einsum("ti,tij,tj->t", d, A, d)
        x_new = x[idx] + d
        r_new = fun(x_new, idx)
        cost_new = np.einsum("ti,ti->t", r_new, r_new)
        better = cost_new < cost[idx]
        took = idx[better]
        x[took], r[took], cost[took] = x_new[better], r_new[better], cost_new[better]
        if took.size:
            J[took] = jac(x[took], took)
        mu[took] = np.maximum(mu[took] / 10.0, MIN_DAMPING)
        mu[idx[~better]] *= 10.0
        done = (np.max(np.abs(d), axis=-1) <= STEP_TOL) | (predicted <= COST_TOL * cost[idx])
        active[idx[done]] = False
        active[mu > MAX_DAMPING] = False
    return x


def _inverse_spd(A: FloatArray) -> FloatArray:
    """Inverse of symmetric positive definite matrices (..., p, p) through their Cholesky factor
    (as ``cho_solve(cho_factor(A), I)``); LinAlgError if one is not positive definite."""
    ci = np.linalg.inv(np.linalg.cholesky(A))
    return np.swapaxes(ci, -1, -2) @ ci


def _solve(b: _Batch, x0: FloatArray, free: NDArray[np.intp], sigma_ins: float,
           sigma_theodolite: float) -> tuple[FloatArray, FloatArray, FloatArray, NDArray[np.bool_]]:
    """Batched ``procedure._solve``: x (T, p), cov (T, f, f), whitened residuals, ok (T,)."""
    mdl = b.model
    x = x0.copy()
    z = b.z0
    Jp = np.zeros((mdl.n_prior, free.size))
    for j, i in enumerate(free):
        if i >= mdl.n_core:
            Jp[i - mdl.n_core, j] = 1.0 / mdl.roll_sigma
    W = np.empty(0)
    for _ in range(2):  # the residual covariance at the start, then at the first solution
        L = np.linalg.cholesky(b.residual_covariance(x, z, sigma_ins, sigma_theodolite))
        W = np.linalg.solve(L, np.broadcast_to(np.eye(L.shape[-1]), L.shape))  # L^-1
        held = x.copy()

        def whitened(xf: FloatArray, idx: NDArray[np.intp], W: FloatArray = W,
                     held: FloatArray = held) -> FloatArray:
            xx = held[idx].copy()
            xx[:, free] = xf
            res = b.residuals(xx, z[idx])
            return np.concatenate([np.einsum("tij,tj->ti", W[idx], res), mdl.prior(xx)], axis=-1)

        def jac(xf: FloatArray, idx: NDArray[np.intp], W: FloatArray = W,
                held: FloatArray = held) -> FloatArray:
            xx = held[idx].copy()
            xx[:, free] = xf
            J = W[idx] @ b.jacobian_x(xx, z[idx], free)
            return np.concatenate([J, np.broadcast_to(Jp, (idx.size, *Jp.shape))], axis=1)

        x[:, free] = _levenberg_marquardt(whitened, jac, x[:, free])
    everyone = np.arange(x.shape[0])
    J = jac(x[:, free], everyone)
    norms = np.linalg.norm(J, axis=1)
    singular = np.linalg.svd(J / np.where(norms > 0, norms, 1.0)[:, None, :], compute_uv=False)
    ok = (norms.min(axis=-1) > 0.0) & (singular[:, -1] >= pr._SEPARABLE * singular[:, 0])
    A = np.swapaxes(J, 1, 2) @ J
    cov = np.full(A.shape, np.nan)
    try:
        cov[ok] = _inverse_spd(A[ok])
    except np.linalg.LinAlgError:
        for i in np.flatnonzero(ok):  # one at a time: a failure fails that trial only
            try:
                cov[i] = _inverse_spd(A[i])
            except np.linalg.LinAlgError:
                ok[i] = False
    return x, cov, whitened(x[:, free], everyone), ok


def _fit_from_starts(b: _Batch, sigma_ins: float, sigma_theodolite: float
                     ) -> tuple[FloatArray, FloatArray, FloatArray, NDArray[np.bool_]]:
    """Batched ``procedure._fit_from_starts``: level start, then its mirror images."""
    mdl = b.model
    T = b.z0.shape[0]
    x0 = np.zeros((T, b.n_params))
    if not mdl.data.has_reference:
        n = mdl.rows.size
        t_az, i_az = b.z0[:, -2 * n:-n], b.z0[:, :n]  # theodolite_az and ins_az at the rows
        x0[:, 2] = np.angle(np.mean(np.exp(1j * (t_az - i_az)), axis=-1))
    free = np.arange(b.n_params)
    if not mdl.n_prior:
        return _solve(b, x0, free, sigma_ins, sigma_theodolite)
    level, _, _, ok = _solve(b, x0, np.arange(mdl.n_core), sigma_ins, sigma_theodolite)
    level[~ok] = x0[~ok]  # a failed trial stays failed; keep its numbers harmless
    best: tuple[FloatArray, FloatArray, FloatArray] | None = None
    for flip in ((1.0, 1.0), (-1.0, 1.0), (1.0, -1.0)):
        start = level.copy()
        start[:, :2] *= flip
        *got, got_ok = _solve(b, start, free, sigma_ins, sigma_theodolite)
        ok &= got_ok  # the literal fit fails the trial if any of its solves fails
        if best is None:
            best = (got[0], got[1], got[2])
            continue
        better = np.einsum("ti,ti->t", got[2], got[2]) < np.einsum("ti,ti->t", best[2], best[2])
        best = (np.where(better[:, None], got[0], best[0]),
                np.where(better[:, None, None], got[1], best[1]),
                np.where(better[:, None], got[2], best[2]))
    assert best is not None
    return best[0], best[1], best[2], ok


def fit_block(data: BatchData, *, sigma_ins: float, sigma_theodolite: float, side: float = 1.0,
              free_roll: bool = False, roll_sigma: float = math.radians(2.0)) -> BatchFit:
    """:func:`montecarlo.seed003.procedure.fit_procedure` of every trial of ``data`` at once.

    The reading errors are given (the a-posteriori scale of the literal fit is not batched);
    the fit with the offsets held at zero (``before``) is not done.

    Raises
    ------
    montecarlo.seed003.procedure.NotDetermined
        Fewer readings than parameters (the layout is common to all trials).
    """
    b = _Batch(data, side, free_roll, roll_sigma)
    mdl = b.model
    p = b.n_params
    dof = 2 * mdl.m + mdl.n_prior - p
    if dof < 1:
        raise pr.NotDetermined(f"{mdl.m} measured mirrors give {2 * mdl.m} readings; "
                               f"{mdl.n_core} parameters need more measured mirrors")
    try:
        x, cov, w, ok = _fit_from_starts(b, float(sigma_ins), float(sigma_theodolite))
    except np.linalg.LinAlgError:  # one trial's matrix stopped the batch: all go one by one
        T, n_res = data.trials, 2 * mdl.m + mdl.n_prior
        x, cov = np.zeros((T, p)), np.full((T, p, p), np.nan)
        w, ok = np.zeros((T, n_res)), np.zeros(T, bool)
    res = b.residuals(x, b.z0)
    T = data.trials
    if free_roll:
        rolls = x[:, mdl.n_core:]
    elif mdl.recorded_roll and data.center is not None:
        rolls = data.ins_roll[:, mdl.rows]
    elif mdl.recorded_roll:
        rolls = np.concatenate([data.ins_roll[:, mdl.rows], x[:, mdl.n_core:]], axis=-1)
    else:
        rolls = np.zeros((T, mdl.rows.size + (0 if data.center is not None else 2)))
    x, cov, res, rolls = x.copy(), cov.copy(), res.copy(), rolls.copy()
    chi2 = np.einsum("ti,ti->t", w, w)
    # A trial that failed, or whose solution or core sigma is beyond FAR (the offsets and
    # rolls are degrees at most), is fitted again by the literal path, which decides it.
    core_sigma = np.sqrt(np.abs(np.diagonal(cov, axis1=1, axis2=2)[:, :mdl.n_core]))
    far = ~(np.abs(x) <= FAR).all(axis=-1) | ~(core_sigma <= FAR).all(axis=-1)
    for i in np.flatnonzero(~ok | far):
        try:
            f = pr.fit_procedure(data.trial(i), side=side, free_roll=free_roll,
                                 roll_sigma=roll_sigma, sigma_ins=sigma_ins,
                                 sigma_theodolite=sigma_theodolite, before=False)
        except pr.NotDetermined:
            ok[i] = False
            continue
        ok[i] = True
        x[i], cov[i], chi2[i], rolls[i] = f.values, f.covariance, f.chi2, f.rolls
        res[i] = np.concatenate([f.residuals[:, 0], f.residuals[:, 1]])
    bad = ~ok
    x[bad], cov[bad], res[bad], chi2[bad] = np.nan, np.nan, np.nan, np.nan
    return BatchFit(mdl.names, x, cov, chi2, dof, res, rolls, ok, mdl.recorded_roll)


def consistency_angles(data: BatchData, fit: BatchFit, side: float = 1.0) -> FloatArray:
    """Angle between each corrected reading and the theodolite's relative direction (T, m) [rad].

    :func:`montecarlo.seed003.procedure.corrected_and_theodolite` of every trial at once.
    """
    x, rolls = fit.values, fit.rolls
    gamma, lam = x[:, 0], x[:, 1]
    k = data.trial(0).measured
    if data.center is not None:
        c, r = data.center, data.roll_mirror
        center = (data.theodolite_az[:, c], data.theodolite_el[:, c], rolls[:, c])
        mirror = (data.theodolite_az[:, r], data.theodolite_el[:, r], rolls[:, r])
        h, p, roll = ref.relative_from_absolute(
            data.ins_az, data.ins_el, rolls,
            (data.ins_az[:, c, None], data.ins_el[:, c, None], rolls[:, c, None]),
            (data.ins_az[:, r, None], data.ins_el[:, r, None], rolls[:, r, None]), side)
        rel_c, rel_r = (h[:, c], p[:, c], roll[:, c]), (h[:, r], p[:, r], roll[:, r])
        h, p, roll = h[:, k], p[:, k], roll[:, k]
    else:
        m = k.size
        az_c = x[:, 2]
        center = (az_c, np.zeros_like(az_c), rolls[:, m])
        mirror = (ref.roll_mirror_azimuth(az_c, side), np.zeros_like(az_c), rolls[:, m + 1])
        C_c = ref.attitude_at(gamma, lam, *center)
        C_r = ref.attitude_at(gamma, lam, *mirror)
        C_Rt = np.swapaxes(ref.reference_frame(C_c, C_r, side), -1, -2)
        rel_c, rel_r = attitude_angles(C_Rt @ C_c), attitude_angles(C_Rt @ C_r)
        h, p = data.ins_az, data.ins_el
        if fit.roll_recorded:
            roll = data.ins_roll
        else:
            C_k = ref.attitude_at(gamma[:, None], lam[:, None], data.theodolite_az,
                                  data.theodolite_el, rolls[:, :m])
            roll = attitude_angles(C_Rt[:, None] @ C_k)[2]
    u = direction(gamma, lam)  # (T, 3)
    optical = [np.matmul(attitude_matrix(*att), u[..., None])[..., 0] for att in (rel_c, rel_r)]
    frame = ref.frame_from_axes(optical[0], optical[1], side)  # (T, 3, 3)
    axis = np.matmul(attitude_matrix(h, p, roll), u[:, None, :, None])[..., 0]
    a = np.matmul(axis, frame)  # corrected optical axis, seed 003 section 2 (T, m, 3)
    t_frame = ref.frame_from_axes(direction(*center[:2]), direction(*mirror[:2]), side)
    t = np.matmul(direction(data.theodolite_az[:, k], data.theodolite_el[:, k]), t_frame)
    a = a / np.linalg.norm(a, axis=-1, keepdims=True)
    t = t / np.linalg.norm(t, axis=-1, keepdims=True)
    return np.arctan2(np.linalg.norm(np.cross(a, t), axis=-1), np.sum(a * t, axis=-1))
