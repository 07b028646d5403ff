"""Confounding between candidates of the DIA engine (:mod:`montecarlo.discrepancy.engine`).

Whether the data separate two candidates (the partner, fitted instead, leaves a significant
signal in the winner's columns), whether an effect explains a flagged observation's signal (the
rule that keeps data snooping from blaming observations for a missing effect), and the minimal
parametrisation of a confounded group.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from numpy.typing import NDArray
from scipy import stats

from montecarlo.discrepancy.candidate_tests import (
    ABSORBED,
    ALPHA,
    CONFOUNDED,
    CandidateTest,
)
from montecarlo.lsq import orthonormal_basis

FloatArray = NDArray[np.float64]


def separated(winner: CandidateTest, partner: CandidateTest, residual: FloatArray,
              alpha: float = ALPHA, absorbed: float = ABSORBED) -> bool:
    """Do the data reject the partner as the explanation of the winner's signal?

    Fit the partner instead (linearised): the residual ``r_j`` and the winner's columns
    projected orthogonal to the model and the partner. If the partner absorbs the winner's
    columns it explains all the winner can: not separated. Otherwise the statistic of the
    winner's columns in ``r_j`` is chi2(q) if the partner is the true effect; significant at
    ``alpha`` means the data separate them.
    """
    return not _explains(partner.basis, winner, residual, alpha, absorbed)


def _explains(U: FloatArray, winner: CandidateTest, residual: FloatArray, alpha: float,
              absorbed: float) -> bool:
    """Do the columns of the orthonormal ``U``, fitted (linearised), leave no significant
    signal at ``alpha`` in the winner's columns projected orthogonal to them?"""
    rj = residual - U @ (U.T @ residual)
    W = winner.projected - U @ (U.T @ winner.projected)
    if np.linalg.norm(W) < absorbed * np.linalg.norm(winner.projected):
        return True
    basis = orthonormal_basis(W)
    T = float(np.sum((basis.T @ rj) ** 2))
    return bool(stats.chi2.sf(T, basis.shape[1]) >= alpha)


def effect_for_observation(observation: CandidateTest, effects: Sequence[CandidateTest],
                           residual: FloatArray, level: float, alpha: float = ALPHA,
                           absorbed: float = ABSORBED) -> CandidateTest | None:
    """The effect to adapt before a flagged observation, if one explains its signal.

    An effect of ``effects`` (Holm-significant) explains the observation's signal when,
    fitted instead (linearised), it leaves the observation's shift insignificant at ``level``
    (its family's share of ``alpha``, :func:`separated`), unless it has as many parameters as
    the observation or more and the observation's shift, fitted instead, leaves no significant
    signal at ``alpha`` in its columns: each then explains the other, and the observation,
    which has the smaller p-value and no more parameters, is flagged (a roll per pointing
    would otherwise take one bad reading for a roll at that pointing). Several effects
    present together can concentrate their signal on the observations of largest leverage (an
    INS scale factor and a pitch bias at the outermost mirrors), so a pair of effects also
    explains it
    when, fitted together, they leave the shift insignificant at ``level`` while their own
    columns, given the shift, stay significant at ``alpha`` (the observation alone does not
    explain them). The strongest effect (smallest p-value) that explains the signal, alone
    or in such a pair, is returned; None if none does.
    """
    ranked = sorted(effects, key=lambda t: (t.log_p, t.dof))
    for t in ranked:
        if not separated(observation, t, residual, level, absorbed) and (
                t.dof < observation.dof
                or not _explains(observation.basis, t, residual, alpha, absorbed)):
            return t
    for t in ranked:
        for other in ranked:
            if other.name == t.name:
                continue
            pair = np.column_stack([t.projected, other.projected])
            if _explains(orthonormal_basis(pair), observation, residual, level, absorbed) \
                    and not _explains(observation.basis, _columns(pair), residual, alpha,
                                      absorbed):
                return t
    return None


def least_separable(test: CandidateTest) -> str | None:
    """The active parameter of ``test`` that its other columns (projected orthogonal to the
    model, each normalised) come closest to reproducing: the largest entry of the right
    singular vector of the smallest singular value. None with fewer than two parameters."""
    if test.projected is None or len(test.active) < 2:
        return None
    G = test.projected
    norms = np.linalg.norm(G, axis=0)
    _, _, vt = np.linalg.svd(G / np.where(norms > 0, norms, 1.0), full_matrices=False)
    return test.active[int(np.argmax(np.abs(vt[-1])))]


def _columns(projected: FloatArray) -> CandidateTest:
    """A nameless candidate of the given projected columns (for :func:`_explains`)."""
    return CandidateTest("", "testable", basis=orthonormal_basis(projected), projected=projected)


def contained(inner: CandidateTest, outer: CandidateTest, level: float = CONFOUNDED) -> bool:
    """Does ``inner``'s projected column space lie (nearly) inside ``outer``'s: every
    canonical correlation of the two spaces above ``level`` (``inner`` has fewer columns)?"""
    if inner.basis is None or outer.basis is None or not inner.basis.size \
            or inner.basis.shape[1] > outer.basis.shape[1]:
        return False
    return bool(np.linalg.svd(inner.basis.T @ outer.basis, compute_uv=False).min() > level)


def minimal_member(winner: CandidateTest, eligible: Sequence[CandidateTest],
                   others: Sequence[CandidateTest], residual: FloatArray,
                   alpha: float = ALPHA, absorbed: float = ABSORBED,
                   confounded: float = CONFOUNDED) -> CandidateTest | None:
    """The minimal parametrisation of the winner's signal, if smaller than the winner.

    A candidate of ``eligible`` (Holm-significant) whose columns lie nearly inside the
    winner's (:func:`contained`) stands in for it when, fitted alone or together with one
    candidate of ``others`` (fewer parameters in total than the winner), it leaves no
    significant signal in the winner's columns (linearised, at ``alpha``): the winner's
    further parameters are then not needed, or explain what another effect does (a lever arm
    standing in for a range bias and a focal scale). Fewest parameters first, then the
    smallest p-value; None if no candidate qualifies.
    """
    best: tuple[tuple[int, float], CandidateTest] | None = None
    for inner in eligible:
        if inner.name == winner.name or inner.dof >= winner.dof \
                or not contained(inner, winner, confounded):
            continue
        for extra in (None, *others):
            if extra is not None and (extra.name in (winner.name, inner.name)
                                      or inner.dof + extra.dof >= winner.dof):
                continue
            columns = [inner.projected] + ([] if extra is None else [extra.projected])
            if _explains(orthonormal_basis(np.column_stack(columns)), winner, residual, alpha,
                         absorbed):
                key = (inner.dof + (0 if extra is None else extra.dof), inner.log_p)
                if best is None or key < best[0]:
                    best = (key, inner)
                break
    return None if best is None else best[1]


