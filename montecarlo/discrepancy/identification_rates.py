"""Probability of correct identification on the linearised model, thousands of sets a second.

At a design's linearisation point the DIA engine's first step is a function of the whitened
misclosures alone (Imparato, Teunissen & Tiberius 2019, Survey Review 51: 437-445, "Minimal
detectable and identifiable biases for quality control", sections 2-3). With ``A`` the
whitened Jacobian of the model, ``B`` an orthonormal basis of its orthogonal complement
(``B'A = 0``, ``r = n - p`` columns) and ``y = e + G b`` the whitened data (``e ~ N(0, I_n)``,
a candidate's columns ``G`` at the size ``b``), the misclosures are ``t = B'y ~ N(B'G b, I_r)``
and every statistic of the first step is a quadratic form of them:

- the global test ``|t|^2 ~ chi2(r)``;
- each candidate's test ``|U_j'y|^2 ~ chi2(q_j)``, ``U_j`` an orthonormal basis of its projected
  columns ``Gbar_j = (I - P_A) G_j`` (which lie in the span of ``B``), and each observation's
  test the same with its rows (data snooping).

:func:`first_step_winners` applies the engine's rule (the first step of
:func:`~montecarlo.discrepancy.engine.diagnose`) to a batch of sets: Holm's weighted
step-down procedure over the global test, each candidate effect (weight 1) and the
observations (weight 1 together), a member rejected where its adjusted p-value is below
``alpha``; the winner is the rejected *testable* member with the smallest p-value (fewer
degrees of freedom on a tie), so an absorbed or undetectable candidate is never named; a
smaller candidate inside the winner's columns that explains its signal, alone or with one
other, is named instead (the engine's
:func:`~montecarlo.discrepancy.confounding.minimal_member`, its tests quadratic forms of the
misclosures too). The bases, degrees of freedom, weights and statuses are the engine's
(:func:`~montecarlo.discrepancy.detect.detection_family` at the noise-free fit of the design);
only the per-set statistics are computed here, for a batch of sets by one matrix product.

Not reproduced: an effect that explains a flagged observation's signal, adapted before the
observation (:func:`~montecarlo.discrepancy.confounding.effect_for_observation`), and the
later steps (adapting the winner, testing again, the swaps). The nonlinear Monte Carlo of the
whole diagnosis (:mod:`montecarlo.systems.identifiability`) is the check of this
approximation.

Reproducible: the noise of set ``i`` comes from block ``i // BLOCK`` of ``SeedSequence(seed)``
(spawn key = block index), so the same seed gives the same sets, and the same PCI, whatever
the batch size.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, replace

import numpy as np
from numpy.typing import NDArray
from scipy import special

from montecarlo.discrepancy.candidate_tests import (
    ABSORBED,
    ALPHA,
    CONFOUNDED,
    POWER,
    CandidateTest,
    log_chi2_sf_asymptotic,
)
from montecarlo.discrepancy.confounding import contained
from montecarlo.discrepancy.detect import detection_family
from montecarlo.discrepancy.fit import jacobian
from montecarlo.discrepancy.problem import Problem, with_outliers
from montecarlo.lsq import LeastSquaresFit, orthonormal_basis

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]

BLOCK = 1000
"""Sets per noise block (one seeded stream each): the unit of reproducibility."""


@dataclass(frozen=True)
class StandIn:
    """A smaller candidate that may be named instead of a winner (the engine's
    :func:`~montecarlo.discrepancy.confounding.minimal_member`): ``inner``'s columns lie nearly
    inside ``winner``'s; fitted alone or with one other candidate (``extras``, in the engine's
    order: (parameters added, index of the quadratic form of the winner's columns left
    unexplained, -1 where nothing is left)) it explains the winner's signal when that form's
    chi2 tail is at least ``alpha``."""

    winner: int
    inner: int
    extras: tuple[tuple[int, int], ...]


@dataclass(frozen=True)
class FirstStep:
    """The detection family of the first identification step at a linearisation point.

    Attributes
    ----------
    names : members other than the global test: candidate effects, then observations.
    dof, weights : each member's degrees of freedom and Holm weight (global test last).
    eligible : members that can be named (status ``testable``).
    projector : (n, r + c) ``[B | U_1 | ... | U_k | V_1 | ...]``: the complement of the
        model's columns, each member's orthonormal basis, then the bases ``V`` of the
        :class:`StandIn` forms.
    summing : (r + c, k + 1 + f) 0/1: which squared projections add up to each statistic
        (the members', the global test's, the forms').
    extra_dof : degrees of freedom of each ``V``.
    stand_ins : the :class:`StandIn` of each winner that has any.
    spare : weight of the observations' share when no observation is tested (p = 1).
    alpha : the family-wise level.
    """

    names: tuple[str, ...]
    dof: IntArray
    weights: FloatArray
    eligible: NDArray[np.bool_]
    projector: FloatArray
    summing: FloatArray
    extra_dof: IntArray
    stand_ins: tuple[StandIn, ...]
    spare: float
    alpha: float

    @property
    def r(self) -> int:
        """Degrees of freedom of the global test (misclosures)."""
        return int(self.dof[-1])


def first_step(problem: Problem, fit: LeastSquaresFit, alpha: float = ALPHA,
               power: float = POWER, absorbed: float = ABSORBED,
               confounded: float = CONFOUNDED) -> FirstStep:
    """The engine's detection family at ``fit`` (the linearisation point: the model there,
    e.g. noise-free data of a design with its effects present) as :class:`FirstStep`."""
    full = with_outliers(problem)
    effects = replace(full, candidates=problem.candidates)
    observations = replace(full, candidates=full.candidates[len(problem.candidates):])
    tests, snoop, _ = detection_family(effects, observations, fit, alpha, power, absorbed)
    members = [t for t in tests if math.isfinite(t.statistic)]
    seen = [t for t in snoop if math.isfinite(t.statistic)]
    if fit.dof <= 0:
        raise ValueError("the model leaves no degree of freedom: nothing to identify")
    u, s, _ = np.linalg.svd(fit.jacobian, full_matrices=True)
    rank = int(np.sum(s > 1e-12 * s[0]))
    complement = u[:, rank:]
    bases = [t.basis for t in (*members, *seen) if t.basis is not None]
    stand_ins, forms = _stand_ins(members, [t for t in tests if t.status == "testable"],
                                  absorbed, confounded)
    dof = [b.shape[1] for b in (*bases, *forms)]
    r = complement.shape[1]
    group = np.repeat([len(bases), *range(len(bases)), *range(len(bases) + 1, len(dof) + 1)],
                      [r, *dof])  # each column's statistic: the global test after the members
    summing = (group[:, None] == np.arange(len(dof) + 1)).astype(float)
    return FirstStep(
        tuple(t.name for t in (*members, *seen)),
        np.array([*dof[:len(bases)], complement.shape[1]], np.int64),
        np.array([1.0] * len(members) + [1.0 / max(len(seen), 1)] * len(seen) + [1.0]),
        np.array([t.status == "testable" for t in (*members, *seen)], bool),
        np.column_stack([complement, *bases, *forms]), summing,
        np.array(dof[len(bases):], np.int64), tuple(stand_ins),
        1.0 if observations.candidates and not seen else 0.0,
        alpha)


def _stand_ins(members: Sequence[CandidateTest], others: Sequence[CandidateTest],
               absorbed: float, confounded: float
               ) -> tuple[list[StandIn], list[FloatArray]]:
    """Every (winner, inner, extra) of :func:`~montecarlo.discrepancy.confounding.minimal_member`
    that the design allows, and the bases of the quadratic forms that decide them (the
    winner's projected columns orthogonal to inner's and extra's), in order."""
    out: list[StandIn] = []
    forms: list[FloatArray] = []
    for w, winner in enumerate(members):
        if winner.status != "testable" or winner.projected is None:
            continue
        for i, inner in enumerate(members):
            if inner.name == winner.name or inner.status != "testable" \
                    or inner.dof >= winner.dof or not contained(inner, winner, confounded):
                continue
            extras = []
            for extra in (None, *others):
                if extra is not None and (extra.name in (winner.name, inner.name)
                                          or inner.dof + extra.dof >= winner.dof):
                    continue
                columns = [c.projected for c in (inner, extra)
                           if c is not None and c.projected is not None]
                U = orthonormal_basis(np.column_stack(columns))
                W = winner.projected - U @ (U.T @ winner.projected)
                added = inner.dof + (0 if extra is None else extra.dof)
                if np.linalg.norm(W) < absorbed * np.linalg.norm(winner.projected):
                    extras.append((added, -1))
                    break  # explains in every set: later extras are never reached
                forms.append(orthonormal_basis(W))
                extras.append((added, len(forms) - 1))
            out.append(StandIn(w, i, tuple(extras)))
    return out, forms


def signal(problem: Problem, fit: LeastSquaresFit, values: Mapping[str, float]) -> FloatArray:
    """Whitened signal ``G b`` (n,) of candidate parameter ``values`` [SI] at ``fit``
    (linearised: the Jacobian columns at the fitted values, the candidate's at zero)."""
    names = list(values)
    G = jacobian(problem, fit.params, names)
    return G @ np.array([values[k] for k in names], float)


def whitened_noise(seed: int, start: int, stop: int, n: int) -> FloatArray:
    """Standard normal whitened noise (stop - start, n) of sets ``start`` .. ``stop - 1``.

    Set ``i`` is row ``i % BLOCK`` of block ``i // BLOCK``, drawn from
    ``SeedSequence(seed, spawn_key=(block,))``: the same whatever the batch it is drawn in.
    """
    first, last = start // BLOCK, (stop - 1) // BLOCK
    blocks = [np.random.default_rng(np.random.SeedSequence(seed, spawn_key=(b,)))
              .standard_normal((BLOCK, n)) for b in range(first, last + 1)]
    return np.concatenate(blocks)[start - first * BLOCK: stop - first * BLOCK]


def member_statistics(step: FirstStep, projected: FloatArray) -> FloatArray:
    """Statistics (N, k + 1 + f) of each member, the global test, then the stand-ins'
    forms, from ``projected`` (N, r + c), the data times :attr:`FirstStep.projector`."""
    return (projected**2) @ step.summing


def log_chi2_sf_rows(statistics: FloatArray, dof: IntArray) -> FloatArray:
    """``log P(chi2(dof_j) > T_ij)`` of statistics (N, k) with degrees of freedom (k,).

    Closed forms where they exist (1 dof: ``log 2 + log Phi(-sqrt(T))``; 2 dof: ``-T/2``),
    finite far into the tail; other dof by scipy's regularised upper incomplete gamma
    function, beyond its range by :func:`~montecarlo.discrepancy.candidate_tests.log_chi2_sf`'s
    asymptotic series. Equals ``scipy.stats.chi2.logsf`` within round-off.
    """
    out = np.empty_like(statistics)
    for q in np.unique(dof):
        cols = np.flatnonzero(dof == q)
        T = statistics[:, cols]
        if q == 1:
            out[:, cols] = math.log(2.0) + special.log_ndtr(-np.sqrt(T))
        elif q == 2:
            out[:, cols] = -0.5 * T
        else:
            p = special.gammaincc(0.5 * q, 0.5 * T)
            logs = np.log(p, where=p > 0, out=np.full_like(p, -np.inf))
            for i, j in np.argwhere(p == 0):
                logs[i, j] = log_chi2_sf_asymptotic(float(T[i, j]), int(q))
            out[:, cols] = logs
    return out


def holm_rejections(p: FloatArray, weights: FloatArray, alpha: float) -> NDArray[np.bool_]:
    """Where :func:`montecarlo.discrepancy.candidate_tests.weighted_holm`'s adjusted p-value of
    each row of ``p`` (N, k), with the same ``weights`` (k,), is below ``alpha`` (< 1): the
    same arithmetic along the rows, the step-down stopped at the first member not rejected
    (an adjusted p-value is the running maximum of ``p_(i) W_i / w_(i)``)."""
    order = np.argsort(p / weights, axis=1, kind="stable")
    w = weights[order]
    left = np.cumsum(w[:, ::-1], axis=1)[:, ::-1]
    stepped = np.take_along_axis(p, order, axis=1) * left / w < alpha
    out = np.empty_like(stepped)
    np.put_along_axis(out, order, np.logical_and.accumulate(stepped, axis=1), axis=1)
    return out


def first_step_winners(step: FirstStep, statistics: FloatArray) -> IntArray:
    """Index (in :attr:`FirstStep.names`) of the member named at the first step of each set,
    -1 where nothing is named; ``statistics`` from :func:`member_statistics`.

    The engine's rule: Holm's weighted procedure over the family at ``alpha``; among the
    rejected testable members, the smallest p-value (``log_p``: the chi2 tail, asymptotic
    beyond scipy's range, :func:`~montecarlo.discrepancy.candidate_tests.log_chi2_sf`), then
    the fewest degrees of freedom, then the first in order; then the minimal member of its
    confounded group where one explains its signal (:func:`_apply_stand_ins`).
    """
    if not step.names:
        return np.full(statistics.shape[0], -1, np.int64)
    k = len(step.names)
    log_p = log_chi2_sf_rows(statistics[:, :k + 1], step.dof)
    p = np.exp(log_p)
    weights = step.weights
    if step.spare:
        p = np.column_stack([p, np.ones(p.shape[0])])
        weights = np.append(weights, step.spare)
    ok = step.eligible & holm_rejections(p, weights, step.alpha)[:, :k]
    key = np.where(ok, log_p[:, :len(step.names)], np.inf)
    best = key.min(axis=1, initial=np.inf)
    tied = ok & (key == best[:, None])
    winner = np.argmin(np.where(tied, step.dof[:-1], np.iinfo(np.int64).max), axis=1)
    winner = np.where(tied.any(axis=1), winner, -1)
    return _apply_stand_ins(step, winner, ok, log_p, statistics[:, k + 1:])


def _apply_stand_ins(step: FirstStep, winner: IntArray, ok: NDArray[np.bool_],
                     log_p: FloatArray, forms: FloatArray) -> IntArray:
    """The engine's :func:`~montecarlo.discrepancy.confounding.minimal_member` on each set:
    the rejected stand-in of the winner that explains its signal with the fewest parameters
    (alone, or with the first extra candidate in order that does: the winner's columns left
    insignificant at ``alpha``, ``forms`` the statistics of what they leave), then the
    smallest p-value, then the first in order, named instead of the winner."""
    out = winner.copy()
    for w in sorted({s.winner for s in step.stand_ins}):
        rows = np.flatnonzero(winner == w)
        if not rows.size:
            continue
        explained = log_chi2_sf_rows(forms[rows], step.extra_dof) >= math.log(step.alpha)
        best = np.full(rows.size, -1)
        best_dof = np.full(rows.size, np.inf)
        best_log_p = np.full(rows.size, np.inf)
        for s in (x for x in step.stand_ins if x.winner == w):
            added = np.full(rows.size, np.inf)
            for dof, form in reversed(s.extras):  # the first extra that explains counts
                hit = np.ones(rows.size, bool) if form < 0 else explained[:, form]
                added = np.where(hit, float(dof), added)
            lp = log_p[rows, s.inner]
            better = ok[rows, s.inner] & np.isfinite(added) & (
                (added < best_dof) | ((added == best_dof) & (lp < best_log_p)))
            best = np.where(better, s.inner, best)
            best_dof = np.where(better, added, best_dof)
            best_log_p = np.where(better, lp, best_log_p)
        out[rows] = np.where(best >= 0, best, w)
    return out


class LinearRates:
    """First-step winners of one family on one draw of noise, held in memory.

    The noise of ``sets`` sets is projected once, one matrix product per batch of ``batch``
    sets (``sets x (r + c)`` floats kept); every size of every candidate tested in this family
    then costs the tests alone, and sees the same noise (common random numbers).
    """

    def __init__(self, step: FirstStep, sets: int, seed: int, batch: int = 5000) -> None:
        if sets < 1 or batch < 1:
            raise ValueError("sets and batch must be positive")
        self.step, self.sets = step, sets
        n = step.projector.shape[0]
        self.noise = [whitened_noise(seed, a, min(sets, a + batch), n) @ step.projector
                      for a in range(0, sets, batch)]

    def pci(self, member: str, signal: FloatArray) -> float:
        """Share of the sets [1] in which ``member`` is named at the first step, the
        whitened ``signal`` (n,) added to each (its columns times its size, :func:`signal`)."""
        index = self.step.names.index(member)
        shift = np.asarray(signal, float) @ self.step.projector
        hits = sum(int(np.count_nonzero(first_step_winners(
            self.step, member_statistics(self.step, z + shift)) == index)) for z in self.noise)
        return hits / self.sets
