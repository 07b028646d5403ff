"""The observations' tests of the detection family (data snooping), all at once.

Each observation that can be wrong on its own is a candidate of the DIA engine
(:func:`montecarlo.discrepancy.problem.with_outliers`): a shift ``b`` of its whitened residuals,
``r - E b`` with ``E`` the observation's rows of the identity. Its columns are known exactly
(``G = E``), so its projection orthogonal to the model needs no Jacobian by differences and no
decomposition of its own: with ``Q`` an orthonormal basis of the model's columns (one SVD per
step, shared by every observation), ``Gbar = E - Q Q_R'`` (``Q_R`` the observation's rows of
``Q``), and the statistic, estimate, MDB and influence of every observation follow from its
``q x q`` normal matrix ``Gbar'Gbar``, batched over the observations.

:func:`analyse_observations` gives what :func:`~montecarlo.discrepancy.candidate_tests.
analyse_candidates` gives for the same candidates (the literal reference, one candidate at a
time; the two agree to round-off), in a fraction of the time on thousands of observations.
An observation with a parameter absorbed by the model (a point of leverage near 1) goes through
the reference's own per-candidate code.
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np
from numpy.typing import NDArray
from scipy import stats

from montecarlo.discrepancy.candidate_tests import (
    ABSORBED,
    ALPHA,
    POWER,
    CandidateTest,
    _orthonormal,
    absorption,
    candidate_statistics,
    family_levels,
    holm,
    log_chi2_sf_asymptotic,
    noncentrality,
)
from montecarlo.discrepancy.estimated_sigma import log_f_sf, noncentrality_f
from montecarlo.discrepancy.problem import OUTLIER, Effect, Problem
from montecarlo.lsq import LeastSquaresFit

FloatArray = NDArray[np.float64]


def analyse_observations(problem: Problem, fit: LeastSquaresFit, alpha: float = ALPHA,
                         power: float = POWER, absorbed: float = ABSORBED,
                         level: Callable[[int], float] | None = None, test: str = "chi2"
                         ) -> list[CandidateTest]:
    """:func:`~montecarlo.discrepancy.candidate_tests.analyse_candidates` of a problem whose
    candidates are all observations' shifts (:func:`~montecarlo.discrepancy.problem.
    with_outliers`), batched (module docstring). ``test`` is "chi2" or "tau" (or "F")."""
    rows_of = {f"{OUTLIER}{oid}": rows for oid, _, rows in problem.observations}
    A, r = fit.jacobian, fit.residual
    Q = _orthonormal(A)
    unavailable = {**problem.unavailable, **{
        c: f"needs {need} in the model first" for c, need in problem.requires.items()
        if need not in fit.effects and c not in problem.unavailable}}
    pending = [c for c in problem.candidates
               if c.name not in fit.effects and c.name not in unavailable]
    tests: dict[str, CandidateTest] = {}
    for c in problem.candidates:
        if c.name in fit.effects:
            tests[c.name] = CandidateTest(c.name, "in_model", reason="already in the model")
        elif c.name in unavailable:
            tests[c.name] = CandidateTest(c.name, "unavailable", reason=unavailable[c.name])
    rows = [list(rows_of[c.name]) for c in pending]
    if any(len(rw) != len(c.parameters) for rw, c in zip(rows, pending, strict=True)):
        raise ValueError("an observation's shift needs one parameter per residual row")
    flat = np.array([i for rw in rows for i in rw], dtype=np.int64)
    # the projected columns of every observation at once: E - Q Q_R', one column per parameter
    projected = -(Q @ Q[flat].T)
    projected[flat, np.arange(flat.size)] += 1.0
    N_diag = np.einsum("ij,ij->j", projected, projected)
    kept = np.sqrt(N_diag)
    Pr = projected.T @ r

    # observations with q parameters, all kept (the common case), batched by q
    groups: dict[int, list[int]] = {}
    work: list[int] = []
    start = np.cumsum([0, *(len(rw) for rw in rows)])
    irregular: dict[int, tuple[list[int], dict[str, float], dict[str, list[str]]]] = {}
    for k, c in enumerate(pending):
        cols = slice(start[k], start[k + 1])
        if np.all(kept[cols] >= absorbed) and _others_kept(projected[:, cols], absorbed):
            groups.setdefault(len(c.parameters), []).append(k)
            work.append(k)
            continue
        G = _unit_columns(r.size, rows[k])
        _, retained, absorbed_by, active = absorption(c, G, projected[:, cols], A, fit.names,
                                                      absorbed)
        if not active:
            tests[c.name] = CandidateTest(c.name, "absorbed", retained=retained,
                                          absorbed_by=absorbed_by,
                                          reason="absorbed by " + ", ".join(sorted(
                                              {n for v in absorbed_by.values() for n in v})))
        else:
            irregular[k] = (active, retained, absorbed_by)
            work.append(k)
    size = level(len(work)) if level is not None else family_levels(
        alpha, len(work), bool(problem.observations))[0]
    log_p: dict[int, float] = {}
    for k, (active, retained, absorbed_by) in irregular.items():
        cols = slice(start[k], start[k + 1])
        tests[pending[k].name], log_p[k] = candidate_statistics(
            pending[k], active, _unit_columns(r.size, rows[k]), projected[:, cols], retained,
            absorbed_by, fit, size, power, test)
    for q, members in groups.items():
        batch = _batch(pending, members, q, start, flat, projected, Pr, kept, fit, size, power,
                       test)
        for k, t, lp in zip(members, *batch, strict=True):
            tests[pending[k].name], log_p[k] = t, lp
    if work:
        adjusted = holm(np.exp([log_p[k] for k in work]))
        for k, p in zip(work, adjusted, strict=True):
            t = tests[pending[k].name]
            tests[t.name] = CandidateTest(**{**t.__dict__, "p_adjusted": float(p)})
    return [tests[c.name] for c in problem.candidates]


def _unit_columns(n: int, rows: list[int]) -> FloatArray:
    """The columns ``E`` of an observation's shift: its rows of the (n, n) identity."""
    E = np.zeros((n, len(rows)))
    E[rows, np.arange(len(rows))] = 1.0
    return E


def _others_kept(Gbar: FloatArray, absorbed: float) -> bool:
    """Does each column of ``Gbar`` keep at least ``absorbed`` of its unit norm orthogonal to
    the others (the reference's test of a parameter absorbed together with the others)?"""
    q = Gbar.shape[1]
    if q < 2:
        return True
    N = Gbar.T @ Gbar
    for j in range(q):
        o = [i for i in range(q) if i != j]
        try:
            rest = N[j, j] - N[j, o] @ np.linalg.solve(N[np.ix_(o, o)], N[o, j])
        except np.linalg.LinAlgError:
            return False
        if not rest >= absorbed**2:
            return False
    return True


def _batch(pending: list[Effect], members: list[int], q: int, start: NDArray[np.int64],
           flat: NDArray[np.int64], projected: FloatArray, Pr: FloatArray, kept: FloatArray,
           fit: LeastSquaresFit, size: float, power: float, test: str
           ) -> tuple[list[CandidateTest], list[float]]:
    """The tests of observations with ``q`` parameters, none absorbed, at once."""
    cols = np.concatenate([np.arange(start[k], start[k] + q) for k in members])
    Ga = projected[:, cols].reshape(-1, len(members), q).transpose(1, 0, 2)  # (K, n, q)
    N = np.einsum("kni,knj->kij", Ga, Ga)
    cov = np.linalg.inv(N)
    b = Pr[cols].reshape(len(members), q)
    est = np.einsum("kij,kj->ki", cov, b)
    T = np.einsum("ki,kij,kj->k", est, N, est)
    diag = np.einsum("kii->ki", N)
    dof2 = 0
    if test == "chi2":
        lam0 = noncentrality(size, q, power)
        log_p = stats.chi2.logsf(T, q)
        bad = ~np.isfinite(log_p)
        log_p[bad] = [log_chi2_sf_asymptotic(float(x), q) for x in T[bad]]
        stat = T
    elif fit.dof - q > 0:
        dof2 = fit.dof - q
        rest = fit.chi2 - T
        with np.errstate(divide="ignore"):
            F = np.where(rest <= 0.0, np.inf, (T / q) / (rest / dof2))
        lam0 = noncentrality_f(size, q, dof2, power)
        log_p = stats.f.logsf(F, q, dof2)
        bad = ~np.isfinite(log_p) & ~np.isinf(F)
        log_p[bad] = [log_f_sf(float(f), q, dof2) for f in F[bad]]
        if test == "F":
            stat = F
        else:
            stat = np.sqrt(T * fit.dof / fit.chi2) if fit.chi2 > 0 else np.full(T.shape, np.inf)
            dof2 = fit.dof
    else:
        out = [CandidateTest(pending[k].name, "undetectable", pending[k].parameters,
                             _retained(pending[k], kept, start[k]), {},
                             reason="no degree of freedom left to estimate the noise beside "
                             "it", test=test) for k in members]
        return out, [0.0] * len(members)
    mdb = np.sqrt(lam0 / diag)
    # A' E is A's rows of the observation: the model's shift by each parameter at its MDB
    shift = (fit.covariance @ fit.jacobian[flat[cols]].T).reshape(
        len(fit.names), len(members), q) * mdb
    influence = np.max(np.abs(shift), axis=2)  # (p, K)
    u, s, _ = np.linalg.svd(Ga, full_matrices=False)  # each one's orthonormal basis
    keep = s > 1e-12 * np.maximum(s[:, :1], 1e-300)
    stderr = np.sqrt(np.einsum("kii->ki", cov))
    bound = np.array([[max(abs(lo), abs(hi)) for lo, hi in pending[k].bounds] for k in members])
    with np.errstate(invalid="ignore"):
        reach = np.sum(bound * np.sqrt(diag), axis=1) ** 2
    out = []
    for i, k in enumerate(members):
        c = pending[k]
        status, reason = "testable", ""
        if reach[i] < lam0:
            status = "undetectable"
            reason = (f"noncentrality at most {reach[i]:.3g} within its physical bounds, "
                      f"{lam0:.3g} needed")
        names = c.parameters
        out.append(CandidateTest(
            c.name, status, names, _retained(c, kept, start[k]), {}, float(stat[i]), q,
            float(np.exp(log_p[i])), float(log_p[i]), math.nan,
            dict(zip(names, est[i].tolist(), strict=True)),
            dict(zip(names, stderr[i].tolist(), strict=True)),
            dict(zip(names, mdb[i].tolist(), strict=True)),
            dict(zip(fit.names, influence[:, i].tolist(), strict=True)),
            lam0, reason, size, u[i] if keep[i].all() else u[i][:, keep[i]], Ga[i], test,
            dof2))
    return out, log_p.tolist()


def _retained(c: Effect, kept: FloatArray, first: int | np.int64) -> dict[str, float]:
    return {p: float(kept[first + j]) for j, p in enumerate(c.parameters)}

