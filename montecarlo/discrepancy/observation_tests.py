"""The observations' tests of the detection family (data snooping), all at once.

Each observation that can be wrong on its own is a candidate of the DIA engine
(:func:`montecarlo.discrepancy.problem.with_outliers`): a shift ``b`` of its whitened residuals,
``r - E b`` with ``E`` the observation's rows of the identity. Its columns are known exactly
(``G = E``), so its projection orthogonal to the model needs no Jacobian by differences and no
decomposition of its own: with ``Q`` an orthonormal basis of the model's columns (one SVD per
step, shared by every observation), ``Gbar = E - Q Q_R'`` (``Q_R`` the observation's rows of
``Q``), and the statistic, estimate, MDB and influence of every observation follow from its
``q x q`` normal matrix ``Gbar'Gbar``, batched over the observations. The projected columns
and their bases themselves (``n x q`` each, ``n x n`` for all observations together) are formed
only for the observations whose test is below ``columns_below`` (the engine asks for those its
identification can pick; a test's adjusted p-value is never below its own).

:func:`analyse_observations` gives what :func:`~montecarlo.discrepancy.candidate_tests.
analyse_candidates` gives for the same candidates (the literal reference, one candidate at a
time; the two agree to round-off), in a fraction of the time on thousands of observations.
An observation with a parameter absorbed by the model (a point of leverage near 1) goes through
the reference's own per-candidate code.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import replace
from typing import Any

import numpy as np
from numpy.typing import NDArray
from scipy import stats

from montecarlo.discrepancy.candidate_tests import (
    ABSORBED,
    ALPHA,
    POWER,
    CandidateTest,
    RowOfValues,
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
                         level: Callable[[int], float] | None = None, test: str = "chi2",
                         columns_below: float = math.inf, adjust: bool = True
                         ) -> list[CandidateTest]:
    """:func:`~montecarlo.discrepancy.candidate_tests.analyse_candidates` of a problem whose
    candidates are all observations' shifts (:func:`~montecarlo.discrepancy.problem.
    with_outliers`), batched (module docstring). ``test`` is "chi2" or "tau" (or "F"). The
    ``basis`` and ``projected`` columns are given for tests whose p-value is below
    ``columns_below`` (all by default), None for the others. ``p_adjusted`` is Holm's over
    these observations, or NaN without ``adjust`` (a caller that adjusts over a larger family:
    thousands of tests are not built twice)."""
    rows_of = {f"{OUTLIER}{oid}": rows for oid, _, rows in problem.observations}
    A, r = fit.jacobian, fit.residual
    Q = fit.column_basis
    unavailable = {**problem.unavailable, **{
        c: f"needs {need} in the model first" for c, need in problem.requires.items()
        if need not in fit.effects and c not in problem.unavailable}}
    in_model = set(fit.effects)
    pending = [c for c in problem.candidates
               if c.name not in in_model and c.name not in unavailable]
    tests: dict[str, CandidateTest] = {}
    for c in problem.candidates:
        if c.name in in_model:
            tests[c.name] = CandidateTest(c.name, "in_model", reason="already in the model")
        elif c.name in unavailable:
            tests[c.name] = CandidateTest(c.name, "unavailable", reason=unavailable[c.name])
    rows = [list(rows_of[c.name]) for c in pending]
    if any(len(rw) != len(c.parameters) for rw, c in zip(rows, pending, strict=True)):
        raise ValueError("an observation's shift needs one parameter per residual row")
    flat = np.array([i for rw in rows for i in rw], dtype=np.int64)
    Qf = Q[flat]
    kept = np.sqrt(np.maximum(1.0 - np.einsum("ij,ij->i", Qf, Qf), 0.0))  # |e - Q q|^2 = 1 - |q|^2
    Pr = r[flat] - Qf @ (Q.T @ r)

    # observations with q parameters, all kept (the common case), batched by q
    groups: dict[int, list[int]] = {}
    work: list[int] = []
    start = np.cumsum([0, *(len(rw) for rw in rows)])
    irregular: dict[int, tuple[list[int], dict[str, float], dict[str, list[str]]]] = {}
    regular = _all_kept(Qf, start, kept, absorbed)
    for k, c in enumerate(pending):
        cols = slice(start[k], start[k + 1])
        if regular[k]:
            groups.setdefault(len(c.parameters), []).append(k)
            work.append(k)
            continue
        G = _unit_columns(r.size, rows[k])
        _, retained, absorbed_by, active = absorption(c, G, _projected(Q, Qf, flat, cols), A,
                                                      fit.names, absorbed)
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
            pending[k], active, _unit_columns(r.size, rows[k]), _projected(Q, Qf, flat, cols),
            retained, absorbed_by, fit, size, power, test)
        if not (columns_below > 0 and log_p[k] < math.log(columns_below)):
            tests[pending[k].name] = replace(tests[pending[k].name], basis=None, projected=None)
    for q, members in groups.items():
        batch = _batch(pending, members, q, start, flat, Q, Qf, Pr, kept, fit, size, power,
                       test, columns_below)
        for k, t, lp in zip(members, *batch, strict=True):
            tests[pending[k].name], log_p[k] = t, lp
    if work and adjust:
        adjusted = holm(np.exp([log_p[k] for k in work]))
        for k, p in zip(work, adjusted, strict=True):
            t = tests[pending[k].name]
            tests[t.name] = t.with_fields(p_adjusted=float(p))
    return [tests[c.name] for c in problem.candidates]


def _projected(Q: FloatArray, Qf: FloatArray, flat: NDArray[np.int64],
               cols: slice | NDArray[np.int64]) -> FloatArray:
    """The projected columns ``E - Q Q_R'`` of parameters ``cols`` (indices into ``flat``, the
    residual row of each parameter), shape (n, len(cols))."""
    columns = -(Q @ Qf[cols].T)
    index = np.atleast_1d(np.arange(flat.size)[cols])
    columns[flat[index], np.arange(index.size)] += 1.0
    return columns


def _unit_columns(n: int, rows: list[int]) -> FloatArray:
    """The columns ``E`` of an observation's shift: its rows of the (n, n) identity."""
    E = np.zeros((n, len(rows)))
    E[rows, np.arange(len(rows))] = 1.0
    return E


def _gram(Qf: FloatArray, cols: NDArray[np.int64], q: int) -> FloatArray:
    """The Gram matrices ``Gbar'Gbar = I - Q_R Q_R'`` of observations with ``q`` parameters
    (their rows ``Q_R`` of the model's basis: ``cols`` of ``Qf``), shape (K, q, q)."""
    Qk = Qf[cols].reshape(-1, q, Qf.shape[1])
    return np.eye(q) - Qk @ Qk.transpose(0, 2, 1)


def _all_kept(Qf: FloatArray, start: NDArray[np.int64], kept: FloatArray,
              absorbed: float) -> list[bool]:
    """For each observation (rows ``start[k]:start[k+1]`` of ``Qf``): does each of its
    columns keep at least ``absorbed`` of its unit norm orthogonal to the model and to its
    other columns (the reference's tests of a parameter absorbed, alone or together with the
    others)? The part orthogonal to the others is the Schur complement
    ``N_jj - N_jo N_oo^-1 N_oj = 1 / (N^-1)_jj``, computed for all observations of one size
    at once."""
    sizes = np.diff(start)
    if not sizes.size:
        return []
    out = np.minimum.reduceat(kept >= absorbed, start[:-1]).tolist()
    for q in set(sizes[sizes > 1].tolist()):
        members = np.array([k for k in np.flatnonzero(sizes == q) if out[k]], np.int64)
        if not members.size:
            continue
        cols = (start[members][:, None] + np.arange(q)).reshape(-1)
        N = _gram(Qf, cols, q)
        det_ok = np.linalg.cond(N) < 1.0 / np.finfo(float).eps
        rest = np.zeros((len(members), q))
        rest[det_ok] = 1.0 / np.einsum("kii->ki", np.linalg.inv(N[det_ok]))
        ok = det_ok & np.all(rest >= absorbed**2, axis=1)
        for k, kept_all in zip(members.tolist(), ok.tolist(), strict=True):
            out[k] = kept_all
    return out


def _batch(pending: list[Effect], members: list[int], q: int, start: NDArray[np.int64],
           flat: NDArray[np.int64], Q: FloatArray, Qf: FloatArray, Pr: FloatArray,
           kept: FloatArray, fit: LeastSquaresFit, size: float, power: float, test: str,
           columns_below: float) -> tuple[list[CandidateTest], list[float]]:
    """The tests of observations with ``q`` parameters, none absorbed, at once; the columns
    of those below ``columns_below``."""
    cols = (start[members][:, None] + np.arange(q)).reshape(-1)
    N = _gram(Qf, cols, q)
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
    wanted = np.flatnonzero(log_p < math.log(columns_below)) if columns_below > 0 else \
        np.zeros(0, np.int64)
    if wanted.size:
        picked = cols.reshape(len(members), q)[wanted].reshape(-1)
        basis = _bases(N[wanted], Q, Qf, picked, flat)
        projected = _projected(Q, Qf, flat, picked)
    slot = {int(i): j for j, i in enumerate(wanted)}
    stderr = np.sqrt(np.einsum("kii->ki", cov))
    bound = np.array([[max(abs(lo), abs(hi)) for lo, hi in pending[k].bounds] for k in members])
    with np.errstate(invalid="ignore"):
        reach = np.sum(bound * np.sqrt(diag), axis=1) ** 2
    later = _Fields(tuple(pending[k].parameters for k in members), kept[cols].reshape(
        len(members), q), est, stderr, mdb, influence, {n: j for j, n in enumerate(fit.names)})
    out = []
    for i, (k, st, pv, lp) in enumerate(zip(members, stat.tolist(), np.exp(log_p).tolist(),
                                            log_p.tolist(), strict=True)):
        c = pending[k]
        status, reason = "testable", ""
        if reach[i] < lam0:
            status = "undetectable"
            reason = (f"noncentrality at most {reach[i]:.3g} within its physical bounds, "
                      f"{lam0:.3g} needed")
        t = object.__new__(CandidateTest)
        t.__dict__.update(
            name=c.name, status=status, active=c.parameters, absorbed_by={}, statistic=st,
            dof=q, p_value=pv, log_p=lp, p_adjusted=math.nan, lambda0=lam0, reason=reason,
            level=size, basis=None, projected=None, test=test, dof2=dof2, _later=(later, i))
        if i in slot:
            t.__dict__.update(basis=basis[:, slot[i] * q:(slot[i] + 1) * q].copy(),
                              projected=projected[:, slot[i] * q:(slot[i] + 1) * q].copy())
        out.append(t)
    return out, log_p.tolist()


class _Fields:
    """The fields of a batch's tests that a step reads for a few of them only (estimate,
    stderr, MDB, influence, share of each column kept), made for one test when it is first
    asked for one (:meth:`CandidateTest.__getattr__`)."""

    def __init__(self, names: tuple[tuple[str, ...], ...], kept: FloatArray,
                 estimate: FloatArray, stderr: FloatArray, mdb: FloatArray,
                 influence: FloatArray, index: dict[str, int]) -> None:
        self.names, self.kept, self.estimate, self.stderr = names, kept, estimate, stderr
        self.mdb, self.influence, self.index = mdb, influence, index

    def fields(self, i: int) -> dict[str, Any]:
        names = self.names[i]
        return {"retained": dict(zip(names, self.kept[i].tolist(), strict=True)),
                "estimate": dict(zip(names, self.estimate[i].tolist(), strict=True)),
                "stderr": dict(zip(names, self.stderr[i].tolist(), strict=True)),
                "mdb": dict(zip(names, self.mdb[i].tolist(), strict=True)),
                "influence": RowOfValues(self.index, self.influence[:, i])}


def _bases(N: FloatArray, Q: FloatArray, Qf: FloatArray, cols: NDArray[np.int64],
           flat: NDArray[np.int64]) -> FloatArray:
    """Orthonormal bases of the observations' projected columns ``Gbar_k = E_k - Q Q_k'``, side
    by side, shape (n, K q): ``Gbar_k W_k`` with ``W_k = V diag(l^-1/2)`` from
    ``N_k = V diag(l) V'`` (their columns are well conditioned: none absorbed, alone or by
    the others), i.e. ``E_k W_k - Q (Q_k' W_k)``, one product for all."""
    K, q = N.shape[0], N.shape[1]
    eigenvalues, V = np.linalg.eigh(N)
    W = V / np.sqrt(eigenvalues)[:, None, :]  # (K, q, q)
    Qk = Qf[cols].reshape(K, q, -1)
    M = (Qk.transpose(0, 2, 1) @ W).transpose(1, 0, 2).reshape(Q.shape[1], K * q)
    basis = -(Q @ M)
    rows = flat[cols].reshape(K, q)
    basis[rows[:, :, None], np.arange(K * q).reshape(K, 1, q)] += W
    return basis


def _retained(c: Effect, kept: FloatArray, first: int | np.int64) -> dict[str, float]:
    return {p: float(kept[first + j]) for j, p in enumerate(c.parameters)}

