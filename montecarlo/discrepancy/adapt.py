"""Adaptation stage of the DIA loop: add the winner to the model and refit, drop what the others
then explain, seek one effect for the flagged observations, and swap named effects for others
while that improves the final model."""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import replace

import numpy as np
from scipy import stats

from montecarlo.discrepancy.candidate_tests import ALPHA, holm, wald_test
from montecarlo.discrepancy.confounding import least_separable
from montecarlo.discrepancy.detect import Detection, detect
from montecarlo.discrepancy.fit import FitError, fit_model
from montecarlo.discrepancy.identify import Winner
from montecarlo.discrepancy.problem import Effect, Problem, is_outlier
from montecarlo.discrepancy.state import DiagnosisState
from montecarlo.lsq import LeastSquaresFit, orthonormal_basis


def adapt(state: DiagnosisState, detection: Detection, winner: Winner) -> None:
    """Add the winner's active parameters (started at their estimates, within bounds) and refit.

    A winner whose adapted model is singular with these data (an effect nearly degenerate with
    the model, e.g. a roll per pointing: one common to the measured mirrors turns their
    relative headings as the central mirror's azimuth does) is refitted with its least
    separable parameter held at zero (:func:`~montecarlo.discrepancy.confounding.
    least_separable`), as an absorbed one, until the fit is regular; one of which no
    parameter can be fitted is dropped, with p = NaN. Parameters absorbed where the winner is
    zero are freed if the adapted model separates them and they lower chi2 by more than the
    ``1 - alpha`` quantile of chi2(their number) (a roll moves the pitch by ``-gamma`` at zero,
    by about ``-lambda sin(roll)`` at 1°). A flagged observation gets its shift parameters.
    After an effect is named, the named effects and flagged observations no longer
    significant given the others are dropped (:func:`reconsider`).
    """
    win, rules = winner.test, state.rules
    effect = state.full.effect(win.name)
    start = {**state.fit.params, **moved_by_shifts(state.fit, state.full.unit_columns,
                                                    win.estimate)}
    for p, v in win.estimate.items():
        lo, hi = effect.bounds[effect.parameters.index(p)]
        start[p] = float(np.clip(v, lo, hi))
    fit = None
    while fit is None:
        try:
            fit = fit_with_fixed(state.full, (*state.fit.effects[1:], win.name), start,
                                 state.fixed | (set(effect.parameters) - set(win.active)))
        except (FitError, np.linalg.LinAlgError):
            # singular: hold the least separable parameter at zero, as an absorbed one
            gauge = least_separable(win)
            if gauge is None:  # not even one parameter of it can be adapted
                state.dropped[win.name] = math.nan
                return
            keep = [k for k, p in enumerate(win.active) if p != gauge]
            columns = win.projected[:, keep] if win.projected is not None else None
            win = replace(win, active=tuple(win.active[k] for k in keep), projected=columns,
                          basis=None if columns is None else orthonormal_basis(columns))
    held = set(effect.parameters) - set(win.active) - state.fixed
    if held:  # absorbed where the effect is zero, but separated where it is fitted?
        try:
            free = fit_with_fixed(state.full, fit.effects[1:], fit.params, state.fixed)
            if fit.chi2 - free.chi2 > stats.chi2.isf(rules.alpha, len(held)):
                fit = free
                win = replace(win, active=tuple(p for p in effect.parameters
                                                if p not in state.fixed))
        except (FitError, np.linalg.LinAlgError):
            pass
    state.fixed |= set(effect.parameters) - set(win.active)
    if is_outlier(win.name):
        state.fit = fit
        state.outliers.append(win)
        state.steps.append(detection.step(win.name))
        return
    state.named.append(win.name)
    state.fit, gone = reconsider(state.full, fit,
                                 [*state.named, *(t.name for t in state.outliers)],
                                 state.fixed, rules.alpha, rules.noise_estimated)
    for name, p_value in gone.items():
        if is_outlier(name):
            state.outliers = [t for t in state.outliers if t.name != name]
        else:
            state.named.remove(name)
        state.dropped[name] = p_value
    state.steps.append(detection.step(win.name, winner.group, gone))


def moved_by_shifts(fit: LeastSquaresFit, unit_columns: Mapping[str, int],
                    shifts: Mapping[str, float]) -> dict[str, float]:
    """The fitted parameters once ``shifts`` of single whitened residuals (an observation's
    shift parameters, ``problem.unit_columns``) are fitted too, to first order: the least-squares
    step ``A d = -G b`` (``G`` those rows of the identity, ``b`` the shifts); empty if a shift is
    not of one residual. The adapted fit starts there: the nonlinear refit then converges in
    fewer iterations (dozens of flagged observations are dozens of refits)."""
    if not shifts or not set(shifts) <= set(unit_columns):
        return {}
    moved = np.zeros(fit.residual.size)
    for name, b in shifts.items():
        moved[unit_columns[name]] = -b
    step = fit.covariance @ (fit.jacobian.T @ moved)
    return dict(zip(fit.names, (fit.values + step).tolist(), strict=True))


def explain_outliers(state: DiagnosisState, detection: Detection) -> None:
    """Before stopping, once: would one effect explain what the flagged observations took?

    If a candidate fitted instead of all their shifts lowers Akaike's criterion
    (:func:`effect_for_outliers`), it is named and the observations are no longer flagged.
    """
    state.retried = True
    others = [t.name for t in state.open_tests(detection.tests)]
    alt = effect_for_outliers(state.full, state.fit, [t.name for t in state.outliers], others,
                              state.fixed)
    if alt is None:
        return
    name, state.fit = alt
    flagged = {t.name: math.nan for t in state.outliers}
    state.dropped.update(flagged)
    state.steps.append(detection.step(name, (name,), flagged))
    state.outliers = []
    state.named.append(name)


def swap_named(state: DiagnosisState) -> None:
    """With two or more effects named, replace them by other candidates while that improves
    the final model (:func:`swap`); after a swap the last step's family is the final model's."""
    if len(state.named) < 2:
        return
    first, last = state.steps[0], state.steps[-1]
    others = [t.name for t in state.open_tests(last.tests)]
    # a candidate absorbed by a named effect may replace it with fewer parameters
    smaller = [t.name for t in state.open_tests(first.tests)
               if t.name not in state.named and t.name not in others]
    # candidates enter with their active parameters only (as an adapted winner does)
    inactive = {p for tests, names in ((first.tests, smaller), (last.tests, others))
                for t in tests if t.name in names
                for p in state.full.effect(t.name).parameters if p not in t.active}
    state.fit, state.swaps = swap(state.full, state.fit, state.named, others,
                                  state.fixed | inactive, smaller, state.rules.alpha)
    for out, into, *_ in state.swaps:
        state.named[state.named.index(out)] = into
    if state.swaps:  # the lists of what the final model absorbs or could miss are its own
        state.steps[-1] = detect(state).step()


def effect_for_outliers(problem: Problem, fit: LeastSquaresFit, flagged: Sequence[str],
                        others: Sequence[str], fixed: set[str]
                        ) -> tuple[str, LeastSquaresFit] | None:
    """The candidate that, fitted instead of all the flagged observations' shifts, gives the
    lowest Akaike criterion ``chi2 + 2 p``, if lower than the model with the shifts (a
    systematic effect seen first at the observations where it is largest); else None."""
    kept = [e for e in fit.effects[1:] if e not in flagged]
    best: tuple[float, str, LeastSquaresFit] | None = None
    for name in others:
        try:
            alt = fit_with_fixed(problem, [*kept, name], fit.params, fixed)
        except (FitError, np.linalg.LinAlgError):
            continue
        score = alt.chi2 + 2.0 * len(alt.names)
        if score < fit.chi2 + 2.0 * len(fit.names) and (best is None or score < best[0]):
            best = (score, name, alt)
    return None if best is None else (best[1], best[2])


def swap(problem: Problem, fit: LeastSquaresFit, named: Sequence[str],
         others: Sequence[str], fixed: set[str], smaller: Sequence[str] = (),
         alpha: float = ALPHA) -> tuple[LeastSquaresFit, list[tuple[str, str, float, float]]]:
    """Replace named effects by other candidates while that lowers Akaike's criterion
    ``chi2 + 2 p`` (the models compared are not nested; the step-wise additions can pick an
    effect that stands in for another when several are present). A swap that adds ``k``
    parameters must also lower chi2 by more than the ``1 - alpha`` quantile of chi2(k), as a
    test of the extra parameters would (AIC alone accepts two unneeded parameters, a lever arm
    for the range bias it contains, with probability P(chi2(2) > 4) = 13.5 %). Candidates of
    ``smaller`` (absorbed by the final model) replace only an effect with more parameters
    (those not held at zero by ``fixed``). A swap keeps the problem's hierarchy
    (``Problem.requires``). Returns the final fit and the swaps made."""
    swaps: list[tuple[str, str, float, float]] = []
    named, others = list(named), [*others, *smaller]

    def size(name: str) -> int:
        return len(set(problem.effect(name).parameters) - fixed)

    def allowed(out: str, into: str) -> bool:
        # the hierarchy stays (k3 only with k2): nothing left needs ``out``, ``into``'s need
        # stays in the model
        kept = [n for n in named if n != out]
        need = problem.requires.get(into)
        if (need is not None and need not in kept) or any(
                problem.requires.get(n) == out for n in kept):
            return False
        return into not in smaller or size(into) < size(out)

    def aic(f: LeastSquaresFit) -> float:
        return f.chi2 + 2.0 * len(f.names)

    while True:
        best: tuple[float, str, str, LeastSquaresFit] | None = None
        for out in named:
            for into in (c for c in others if allowed(out, c)):
                model = [into if e == out else e for e in fit.effects[1:]]
                try:
                    alt = fit_with_fixed(problem, model, fit.params, fixed)
                except (FitError, np.linalg.LinAlgError):  # not separable: no candidate
                    continue
                extra = len(alt.names) - len(fit.names)
                if extra > 0 and fit.chi2 - alt.chi2 <= stats.chi2.isf(alpha, extra):
                    continue
                if aic(alt) < aic(fit) and (best is None or aic(alt) < best[0]):
                    best = (aic(alt), out, into, alt)
        if best is None:
            return fit, swaps
        _, out, into, alt = best
        swaps.append((out, into, aic(fit), aic(alt)))
        named[named.index(out)] = into
        others[others.index(into)] = out
        fit = alt


def reconsider(problem: Problem, fit: LeastSquaresFit, named: Sequence[str], fixed: set[str],
               alpha: float, noise_estimated: bool = False
               ) -> tuple[LeastSquaresFit, dict[str, float]]:
    """Drop, one at a time, the least significant of the named effects and flagged
    observations while any is not significant given the others (Wald tests; Holm over the
    effects, and separately over the observations); returns the refitted model and what was
    dropped, with its adjusted p-value."""
    gone: dict[str, float] = {}
    kept = list(named)
    while kept:
        adjusted: dict[str, float] = {}
        for family in ([n for n in kept if not is_outlier(n)], [n for n in kept if is_outlier(n)]):
            if len(family) > (1 if family and not is_outlier(family[0]) else 0):
                p = [wald_test(fit, problem.effect(n).parameters, noise_estimated)[2]
                     for n in family]
                adjusted.update(zip(family, holm(p).tolist(), strict=True))
        if not adjusted:
            break
        worst = max(adjusted, key=lambda n: adjusted[n])
        if adjusted[worst] < alpha:
            break
        kept.remove(worst)
        gone[worst] = adjusted[worst]
        model = [e for e in fit.effects[1:] if e not in gone]
        fit = fit_with_fixed(problem, model, fit.params, fixed)
    return fit, gone


def fit_with_fixed(problem: Problem, effects: Sequence[str], start: Mapping[str, float],
                   fixed: set[str]) -> LeastSquaresFit:
    """Fit ``effects``, holding the parameters in ``fixed`` (absorbed ones) at zero.

    Absorbed parameters cannot be estimated (their columns are in the model's span), so the
    adapted model drops them: the effect enters with its active parameters only.
    """
    if not fixed:
        return fit_model(problem, effects, start)
    reduced = tuple(
        Effect(e.name, tuple(p for p in e.parameters if p not in fixed),
               tuple(b for p, b in zip(e.parameters, e.bounds, strict=True) if p not in fixed),
               tuple(s for p, s in zip(e.parameters, e.steps, strict=True) if p not in fixed),
               e.description)
        if set(e.parameters) & fixed else e
        for e in problem.candidates)
    return fit_model(replace(problem, candidates=reduced), effects, start)
