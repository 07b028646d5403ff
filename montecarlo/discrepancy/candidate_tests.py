"""Identification statistics of the DIA engine (:mod:`montecarlo.discrepancy.engine`).

Each candidate effect's columns projected orthogonal to the current model, the absorbed
parameters, the likelihood-ratio statistic ``T ~ chi2(q)``, the minimal detectable bias of the
candidate's own test (Baarda's noncentrality ``lambda0`` at that test's size in the detection
family, :func:`family_levels`), Holm's (weighted) step-down adjustment, canonical correlations
between candidates, and the Wald test of fitted parameters. References in the engine's
docstring.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterator, Mapping, Sequence
from dataclasses import dataclass, field
from functools import lru_cache
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray
from scipy import special, stats

from montecarlo.discrepancy.estimated_sigma import (
    f_statistic,
    log_f_sf,
    noncentrality_f,
    pope_tau,
)
from montecarlo.discrepancy.fit import candidate_columns
from montecarlo.discrepancy.problem import Effect, Problem
from montecarlo.lsq import LeastSquaresFit, orthonormal_basis

FloatArray = NDArray[np.float64]

ALPHA = 0.01
"""Significance of the global test and family-wise error of the identification."""
POWER = 0.80
"""Power at which the minimal detectable bias is defined (Baarda's beta0 = 0.80)."""
ABSORBED = 0.05
"""A projected column keeping less than this fraction of its norm is absorbed."""
CONFOUNDED = 0.9
"""Candidates whose statistics correlate above this form a confounded group."""


def holm(p_values: Sequence[float]) -> FloatArray:
    """Holm's step-down adjusted p-values (reject where adjusted < alpha).

    ``p_(i) (m - i + 1)`` for the i-th smallest, made monotone and capped at 1; equals
    ``statsmodels.stats.multitest.multipletests(method="holm")`` (which also runs a garbage
    collection on every call, 100 ms here, too slow for Monte Carlo loops).
    """
    p = np.asarray(p_values, float)
    order = np.argsort(p, kind="stable")
    m = p.size
    stepped = np.minimum(1.0, np.maximum.accumulate(p[order] * (m - np.arange(m))))
    out = np.empty(m)
    out[order] = stepped
    return out


def weighted_holm(p_values: Sequence[float], weights: Sequence[float]) -> FloatArray:
    """Holm's weighted step-down adjusted p-values (Holm 1979, section 3).

    Hypotheses are ordered by ``p_i / w_i``; the j-th is rejected at ``alpha`` when all before
    it are and ``p_(j) <= alpha w_(j) / sum of the weights not yet rejected``. The adjusted
    p-value is ``max_{i <= j} min(1, p_(i) W_i / w_(i))`` with ``W_i`` the weight left at
    step i. The family-wise error rate is at most ``alpha`` under any dependence. Equal
    weights give :func:`holm`.
    """
    p = np.asarray(p_values, float)
    w = np.asarray(weights, float)
    order = np.argsort(p / w, kind="stable")
    left = np.cumsum(w[order][::-1])[::-1]
    stepped = np.minimum(1.0, np.maximum.accumulate(p[order] * left / w[order]))
    out = np.empty(p.size)
    out[order] = stepped
    return out


def family_levels(alpha: float, n_effects: int, observations: bool) -> tuple[float, float]:
    """Size of each member's own test at the first step of the detection family.

    The family is the global test, each of ``n_effects`` candidate effects (weight 1 each) and,
    when the data have observations that can be wrong on their own, the observations (weight
    1 together, shared equally). Returns (level of the global test and of each effect, level
    of the observations together); one observation's is the latter over their number.
    """
    share = alpha / (1 + n_effects + int(observations))
    return share, share if observations else 0.0


@lru_cache(maxsize=4096)
def noncentrality(alpha: float, dof: int, power: float = POWER) -> float:
    """Noncentrality ``lambda`` at which a chi2(dof) test of size ``alpha`` has ``power``.

    Solves ``P(chi2'(dof, lambda) > chi2_{1-alpha}(dof)) = power`` (Baarda's lambda0) with
    ``scipy.special.chndtrinc``, the inverse of the noncentral chi2 distribution in lambda.
    """
    return float(special.chndtrinc(stats.chi2.isf(alpha, dof), dof, 1.0 - power))


def log_chi2_sf(x: float, dof: int) -> float:
    """``log P(chi2(dof) > x)``, finite far into the tail (for ranking huge statistics).

    scipy's ``chi2.logsf`` underflows to -inf near x = 1500; beyond that the asymptotic series
    of the upper incomplete gamma function is used,
    ``log Gamma(a, y) = (a - 1) log y - y + log(1 + (a-1)/y + (a-1)(a-2)/y^2 + ...)``
    with ``a = dof/2``, ``y = x/2`` (relative error below 1e-6 there).
    """
    value = float(stats.chi2.logsf(x, dof))
    return value if np.isfinite(value) else log_chi2_sf_asymptotic(x, dof)


def log_chi2_sf_asymptotic(x: float, dof: int) -> float:
    a, y = dof / 2.0, x / 2.0
    series = 1.0 + (a - 1.0) / y + (a - 1.0) * (a - 2.0) / y**2
    return (a - 1.0) * math.log(y) - y + math.log(series) - math.lgamma(a)


class RowOfValues(Mapping[str, float]):
    """Parameter -> value, read from one row of an array shared by many tests: a step tests
    thousands of observations, each with an influence on every model parameter, and builds no
    dictionary for them."""

    __slots__ = ("_index", "_row")

    def __init__(self, index: Mapping[str, int], row: FloatArray) -> None:
        self._index, self._row = index, row

    def __getitem__(self, name: str) -> float:
        return float(self._row[self._index[name]])

    def __iter__(self) -> Iterator[str]:
        return iter(self._index)

    def __len__(self) -> int:
        return len(self._index)

    def __repr__(self) -> str:
        return repr(dict(self))


@dataclass(frozen=True)
class CandidateTest:
    """Identification statistics of one candidate against the current model.

    Attributes
    ----------
    name : candidate name.
    status : ``"testable"``, ``"absorbed"`` (all parameters absorbed), ``"undetectable"``
        (below the MDB anywhere within its physical bounds), ``"no_effect"`` (its columns are
        zero with these data), ``"unavailable"`` (the data lack what it needs) or ``"in_model"``.
    active : parameters tested (not absorbed).
    retained : parameter -> fraction of its column's norm left after projection on the model.
    absorbed_by : absorbed parameter -> model parameters that absorb it.
    statistic, dof, p_value, log_p : the statistic of its test and its tail: ``T`` and
        chi2(dof) with the noise known (``test`` "chi2"); with the noise estimated, ``F`` and
        F(dof, dof2) for an effect ("F"), Pope's ``tau`` for an observation ("tau", the same
        p-value, :mod:`montecarlo.discrepancy.estimated_sigma`).
    p_adjusted : Holm-adjusted p-value over the detection family (NaN outside it); the engine
        sets it over the whole family (global test, effects, observations), this module
        within the candidates analysed together.
    estimate, stderr : linearised size of the active parameters and its 1-sigma.
    mdb : active parameter -> minimal detectable bias (alone, others zero) of the candidate's
        own chi2(dof) test at size ``level`` with power :data:`POWER`.
    influence : model parameter -> largest shift of its estimate caused by one of the
        candidate's parameters left out at its MDB (Baarda's external reliability: how much an
        effect the test cannot see may bias the fitted model).
    lambda0 : noncentrality at which its own test rejects with ``power``.
    level : size of its own test at the first step of Holm's procedure (the MDB's test).
    reason : text for statuses other than testable.
    test, dof2 : the test ("chi2", "F" or "tau") and its second degrees of freedom (F's
        denominator ``n - p - q``; for tau the model's ``n - p``; 0 for chi2).
    """

    name: str
    status: str
    active: tuple[str, ...] = ()
    retained: dict[str, float] = field(default_factory=dict)
    absorbed_by: dict[str, list[str]] = field(default_factory=dict)
    statistic: float = math.nan
    dof: int = 0
    p_value: float = math.nan
    log_p: float = math.nan
    p_adjusted: float = math.nan
    estimate: dict[str, float] = field(default_factory=dict)
    stderr: dict[str, float] = field(default_factory=dict)
    mdb: dict[str, float] = field(default_factory=dict)
    influence: Mapping[str, float] = field(default_factory=dict)
    lambda0: float = math.nan
    reason: str = ""
    level: float = math.nan
    basis: FloatArray | None = field(default=None, repr=False, compare=False)
    projected: FloatArray | None = field(default=None, repr=False, compare=False)
    test: str = "chi2"
    dof2: int = 0

    if not TYPE_CHECKING:  # a type checker still flags a misspelt field

        def __getattr__(self, name: str) -> Any:
            """A field left to be filled when first read (``_later`` = (source, row): a step
            tests thousands of observations and reads the estimates and MDBs of a few; see
            :mod:`~montecarlo.discrepancy.observation_tests`)."""
            later = self.__dict__.get("_later")
            if later is None or name not in self.__dataclass_fields__:
                raise AttributeError(name)
            self.__dict__.update(later[0].fields(later[1]))
            del self.__dict__["_later"]
            return self.__dict__[name]

    def with_fields(self, **changes: Any) -> CandidateTest:
        """A copy with ``changes`` (as :func:`dataclasses.replace`, without ``__init__``, so a
        field not yet filled stays so: the adjusted p-values of thousands of observations'
        tests)."""
        unknown = set(changes) - set(self.__dataclass_fields__)
        if unknown:
            raise TypeError(f"CandidateTest has no field {sorted(unknown)[0]!r}")
        new = object.__new__(CandidateTest)
        new.__dict__.update(self.__dict__, **changes)
        return new


def _absorbed_by(column: FloatArray, A: FloatArray, names: Sequence[str]) -> list[str]:
    """Model parameters that carry most of ``column`` (normalised least-squares weights)."""
    norms = np.linalg.norm(A, axis=0)
    w = np.linalg.lstsq(A / norms, column, rcond=None)[0]
    big = np.abs(w) >= 0.3 * np.max(np.abs(w)) if np.any(w) else np.zeros(w.size, bool)
    return [names[i] for i in np.flatnonzero(big)]


def absorption(c: Effect, G: FloatArray, Gbar: FloatArray, A: FloatArray, names: Sequence[str],
               absorbed: float = ABSORBED
               ) -> tuple[FloatArray, dict[str, float], dict[str, list[str]], list[int]]:
    """A candidate's columns ``G`` against the model's ``A`` (``Gbar`` projected orthogonal
    to it): the column norms, the fraction of each kept (``retained``), the absorbed
    parameters and the model parameters that absorb them, and the indices of the active ones
    (a parameter is also absorbed by the model together with the candidate's others)."""
    norms = np.linalg.norm(G, axis=0)
    kept = np.linalg.norm(Gbar, axis=0) / np.where(norms > 0, norms, 1.0)
    retained = {p: float(kept[j]) for j, p in enumerate(c.parameters)}
    absorbed_by: dict[str, list[str]] = {}
    active = [j for j in range(len(c.parameters)) if norms[j] > 0]
    for j in active:
        if kept[j] < absorbed:
            absorbed_by[c.parameters[j]] = _absorbed_by(G[:, j], A, names)
    active = [j for j in active if kept[j] >= absorbed]
    while len(active) > 1:
        fractions = []
        for j in active:
            others = orthonormal_basis(Gbar[:, [i for i in active if i != j]])
            rest = Gbar[:, j] - others @ (others.T @ Gbar[:, j])
            fractions.append(np.linalg.norm(rest) / norms[j])
        worst = int(np.argmin(fractions))
        if fractions[worst] >= absorbed:
            break
        j = active.pop(worst)
        absorbed_by[c.parameters[j]] = _absorbed_by(
            G[:, j], np.column_stack([A, G[:, active]]),
            [*names, *(c.parameters[i] for i in active)])
    return norms, retained, absorbed_by, active


def analyse_candidates(problem: Problem, fit: LeastSquaresFit, alpha: float = ALPHA,
                       power: float = POWER, absorbed: float = ABSORBED,
                       level: Callable[[int], float] | None = None, test: str = "chi2"
                       ) -> list[CandidateTest]:
    """Identification statistics of every candidate against the model of ``fit``.

    Linearised at the fitted values with each candidate's parameters at zero. See the module
    docstring for the statistic, absorption, MDB and undetectability. The members of the
    family are the candidates with at least one active parameter; ``level(m)`` is the size of
    each one's own test when there are ``m`` (default: candidate effects in the detection
    family of :func:`family_levels`); Holm's adjustment here is within these candidates.
    ``test`` is "chi2" (the noise known), "F" or "tau" (the noise estimated: effects,
    observations).
    """
    A = fit.jacobian
    Q = fit.column_basis
    r = fit.residual
    values = fit.params
    unavailable = {**problem.unavailable, **{
        c: f"needs {need} in the model first" for c, need in problem.requires.items()
        if need not in fit.effects and c not in problem.unavailable}}
    pending = [c for c in problem.candidates
               if c.name not in fit.effects and c.name not in unavailable]
    all_params = [p for c in pending for p in c.parameters]
    G_all = candidate_columns(problem, values, all_params) if all_params else \
        np.zeros((r.size, 0))

    tests: dict[str, CandidateTest] = {}
    work: list[tuple[Effect, list[int], FloatArray, FloatArray, dict, dict]] = []
    offset = 0
    for c in problem.candidates:
        if c.name in fit.effects:
            tests[c.name] = CandidateTest(c.name, "in_model", reason="already in the model")
            continue
        if c.name in unavailable:
            tests[c.name] = CandidateTest(c.name, "unavailable", reason=unavailable[c.name])
            continue
        G = G_all[:, offset:offset + len(c.parameters)]
        offset += len(c.parameters)
        Gbar = G - Q @ (Q.T @ G)
        norms, retained, absorbed_by, active = absorption(c, G, Gbar, A, fit.names, absorbed)
        if not np.any(norms > 0):
            tests[c.name] = CandidateTest(c.name, "no_effect", retained=retained,
                                          reason="its parameters do not change these data")
        elif not active:
            tests[c.name] = CandidateTest(c.name, "absorbed", retained=retained,
                                          absorbed_by=absorbed_by,
                                          reason="absorbed by " + ", ".join(sorted(
                                              {n for v in absorbed_by.values() for n in v})))
        else:
            work.append((c, active, G, Gbar, retained, absorbed_by))

    m = len(work)
    size = level(m) if level is not None else family_levels(
        alpha, m, bool(problem.observations))[0]
    log_ps = []
    for c, active, G, Gbar, retained, absorbed_by in work:
        tests[c.name], log_p = candidate_statistics(c, active, G, Gbar, retained, absorbed_by,
                                                    fit, size, power, test)
        log_ps.append(log_p)
    if work:
        adjusted = holm(np.exp(log_ps))
        for (c, *_), p in zip(work, adjusted, strict=True):
            t = tests[c.name]
            tests[c.name] = t.with_fields(p_adjusted=float(p))
    return [tests[c.name] for c in problem.candidates]


def candidate_statistics(c: Effect, active: list[int], G: FloatArray, Gbar: FloatArray,
                         retained: dict[str, float], absorbed_by: dict[str, list[str]],
                         fit: LeastSquaresFit, size: float, power: float = POWER,
                         test: str = "chi2") -> tuple[CandidateTest, float]:
    """The test of one candidate with ``active`` parameters (columns ``G``, projected
    ``Gbar``) at size ``size``, and its log p-value (0 where it cannot be tested)."""
    A, r = fit.jacobian, fit.residual
    Ga = Gbar[:, active]
    names = tuple(c.parameters[j] for j in active)
    N = Ga.T @ Ga
    cov = np.linalg.inv(N)
    est = cov @ (Ga.T @ r)
    T = float(est @ N @ est)
    q = len(active)
    stat, dof2 = T, 0
    if test == "chi2":
        lam0 = noncentrality(size, q, power)
        log_p = log_chi2_sf(T, q)
    elif fit.dof - q > 0:
        dof2 = fit.dof - q
        F = f_statistic(T, fit.chi2, fit.dof, q)
        lam0 = noncentrality_f(size, q, dof2, power)
        log_p = log_f_sf(F, q, dof2)
        stat, dof2 = (F, dof2) if test == "F" else (pope_tau(T, fit.chi2, fit.dof), fit.dof)
    else:  # no degree of freedom left to estimate the noise beside it: not testable
        return CandidateTest(c.name, "undetectable", names, retained, absorbed_by,
                             reason="no degree of freedom left to estimate the noise beside "
                             "it", test=test), 0.0
    mdb = {n: math.sqrt(lam0 / N[k, k]) for k, n in enumerate(names)}
    shift = fit.covariance @ (A.T @ G[:, active]) * np.array(list(mdb.values()))
    influence = dict(zip(fit.names, np.max(np.abs(shift), axis=1).tolist(), strict=True))
    reach = sum(max(abs(c.bounds[j][0]), abs(c.bounds[j][1])) * math.sqrt(N[k, k])
                for k, j in enumerate(active)) ** 2
    status, reason = "testable", ""
    if reach < lam0:
        status = "undetectable"
        reason = (f"noncentrality at most {reach:.3g} within its physical bounds, "
                  f"{lam0:.3g} needed")
    return CandidateTest(
        c.name, status, names, retained, absorbed_by, stat, q, float(np.exp(log_p)), log_p,
        math.nan, dict(zip(names, est.tolist(), strict=True)),
        dict(zip(names, np.sqrt(np.diag(cov)).tolist(), strict=True)), mdb, influence,
        lam0, reason, size, orthonormal_basis(Ga), Ga, test, dof2), log_p


def canonical_correlation(a: CandidateTest, b: CandidateTest) -> float:
    """Largest canonical correlation of two candidates' projected column spaces.

    For one-parameter candidates this is ``|corr(w_a, w_b)|`` of their w-test statistics under
    the model; in general the cosine of the smallest principal angle between the spaces.
    """
    if a.basis is None or b.basis is None or not a.basis.size or not b.basis.size:
        return 0.0
    return float(min(1.0, np.linalg.svd(a.basis.T @ b.basis, compute_uv=False)[0]))


def wald_test(fit: LeastSquaresFit, parameters: Sequence[str], estimated: bool = False
              ) -> tuple[float, int, float]:
    """Wald statistic ``b' C^-1 b`` of fitted ``parameters`` (those in the fit) against zero,
    its degrees of freedom and its chi-square p-value; with the noise ``estimated``, the
    statistic over ``q`` and the fit's variance factor, ``F(q, n - p)``."""
    idx = [fit.names.index(p) for p in parameters if p in fit.names]
    if not idx:
        return 0.0, 0, 1.0
    b = fit.values[idx]
    T = float(b @ np.linalg.solve(fit.covariance[np.ix_(idx, idx)], b))
    if estimated:
        F = T / len(idx) / fit.chi2_red
        return F, len(idx), float(stats.f.sf(F, len(idx), fit.dof))
    return T, len(idx), float(stats.chi2.sf(T, len(idx)))


def chi2_red_band(dof: int, level: float = 0.99) -> tuple[float, float]:
    """Central ``level`` band of chi2(dof)/dof, the reduced chi-square of a right model."""
    lo, hi = stats.chi2.ppf([(1 - level) / 2, (1 + level) / 2], dof)
    return float(lo / dof), float(hi / dof)
