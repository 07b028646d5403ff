"""Detection, identification and adaptation (DIA) of a missing effect in a least-squares model.

The generic engine of the discrepancy workflow. A :class:`Problem` states the measured data through
one function of named parameters, the *whitened* residuals ``r = W (observed - predicted)`` (unit
variance, uncorrelated when the model is right and the stated noise is true), a base model (an
:class:`Effect` whose parameters are always fitted) and a library of candidate effects, each a
parametric extension of the forward model that is zero (absent) when its parameters are zero. The
engine never sees how the data were made; it follows geodetic quality control (Baarda's data
snooping, Teunissen's DIA):

1. **Fit** the current model by nonlinear least squares (``scipy.optimize.least_squares``),
   candidate parameters within their physical bounds.
2. **Test**: for every candidate, its whitened Jacobian columns ``G`` (derivative of the
   prediction with respect to its parameters at zero) projected orthogonal to the model's
   columns ``A``: ``Gbar = (I - P_A) G``. Parameters whose projected column keeps less than
   ``absorbed`` (5 %) of its norm are *absorbed* (the model already explains them); a candidate
   with all parameters absorbed is never named. The likelihood-ratio statistic of the remaining
   columns is ``T = r' Gbar (Gbar'Gbar)^-1 Gbar' r ~ chi2(q)`` (central under the model,
   noncentral with ``lambda = |Gbar b|^2`` under a bias ``b``). Each observation that can be
   wrong on its own is a candidate too (its mean shift: data snooping; their tests are
   computed together from their exact columns, :mod:`montecarlo.discrepancy.observation_tests`).
3. **Detect and identify in one family**: the global test ``chi2 = r'r ~ chi2(n - p)``, each
   candidate effect's test and the observations' tests form one family under Holm's weighted
   step-down procedure at ``alpha`` (the global test and each effect weight 1, the
   observations weight 1 together): the family-wise rate of naming anything under a right
   model is at most ``alpha``, and a candidate whose own test is rejected is named whether or
   not the global test is (the global test over ``n - p`` degrees of freedom loses its power
   as ``n`` grows; a candidate's own test does not). The eligible candidate with the smallest
   p-value is the winner. Candidates whose statistics correlate with the winner's above
   ``confounded`` (0.9, the largest canonical correlation of the projected column spaces)
   form a *confounded group* with it unless the data separate them (the partner, fitted
   instead, leaves a significant signal in the winner's columns). A candidate inside the
   winner's column space with fewer parameters that explains its signal (alone or with one
   other candidate) is adapted instead: the group's minimal parametrisation
   (:func:`minimal_member`); the groups reported are those of the final model. A rejected
   global test with no candidate rejected is a misfit no candidate explains. With the noise
   estimated from the data (``noise_estimated``) the tests are F and Pope's tau
   (:mod:`montecarlo.discrepancy.estimated_sigma`).
4. **Adapt**: add the winner's parameters, refit the nonlinear model, go back to 2 (a winner
   whose adapted model is singular is not adapted but dropped, with p = NaN); stop when no
   candidate is rejected.

The *minimal detectable bias* (MDB) of a parameter is the size ``|b|`` at which the
candidate's own test rejects with probability ``power`` (0.80) at its size in the family's
first Holm step (``alpha / (m + 2)`` for ``m`` candidate effects, the global test and the
observations; an observation's share is that over the number of observations): Baarda's
noncentrality ``lambda0`` of that chi2(q) test and ``MDB = sqrt(lambda0 / |Gbar e_k|^2)``. A
candidate that stays below ``lambda0`` anywhere inside its physical bounds is
*undetectable*: no physically possible size of it could be told from noise, so it is never
named (a significant signal along its columns must come from something else).

References
----------
Baarda, W. (1968), A testing procedure for use in geodetic networks; Teunissen, P. J. G. (2000),
Testing theory; Teunissen, P. J. G. (2018), Distributional theory for the DIA method,
J. Geodesy 92: 59-80. Holm, S. (1979), A simple sequentially rejective multiple test procedure.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, replace

import numpy as np
from numpy.typing import NDArray
from scipy import stats

from montecarlo.discrepancy.candidate_tests import (
    ABSORBED,
    ALPHA,
    CONFOUNDED,
    POWER,
    CandidateTest,
    analyse_candidates,
    canonical_correlation,
    family_levels,
    holm,
    wald_test,
    weighted_holm,
)
from montecarlo.discrepancy.confounding import (
    effect_for_observation,
    minimal_member,
    separated,
)
from montecarlo.discrepancy.estimated_sigma import global_f
from montecarlo.discrepancy.fit import ONE_THREAD, FitError, fit_model
from montecarlo.discrepancy.observation_tests import analyse_observations
from montecarlo.discrepancy.problem import Effect, Problem, is_outlier, with_outliers
from montecarlo.lsq import LeastSquaresFit

FloatArray = NDArray[np.float64]

# --------------------------------------------------------------------------- the DIA loop


@dataclass(frozen=True)
class Step:
    """One identification step: the model tested, its fit, every candidate's statistics, the
    winner (None if nothing was significant: an effect, or an observation ``outlier:ID``), its
    confounded partners, each observation's outlier test (``snoop``), the named effects
    dropped after this step's adaptation because the others explain them (``dropped``:
    name -> Holm-adjusted p-value of its Wald test given the others) and the global test's
    Holm-adjusted p-value in the detection family (``global_p``)."""

    fit: LeastSquaresFit
    tests: list[CandidateTest]
    winner: str | None
    group: tuple[str, ...]
    snoop: list[CandidateTest] = field(default_factory=list)
    dropped: dict[str, float] = field(default_factory=dict)
    global_p: float = math.nan


@dataclass(frozen=True)
class Group:
    """A named effect and the candidates the data cannot tell from it.

    Attributes
    ----------
    fitted : the member in the final model: the group's minimal parametrisation.
    members : ``fitted`` first, then each candidate (not named) whose statistic correlates
        with the fitted one's above ``confounded`` given the rest of the final model, and
        which the data do not reject as the explanation of its signal (:func:`separated`).
    correlation : other member -> largest canonical correlation with ``fitted``.
    separating_data : other member -> the extra data that would tell it from ``fitted``
        (``Problem.separating_data``; "" where the problem does not say).
    """

    fitted: str
    members: tuple[str, ...]
    correlation: dict[str, float] = field(default_factory=dict)
    separating_data: dict[str, str] = field(default_factory=dict)


@dataclass(frozen=True)
class Diagnosis:
    """Result of :func:`diagnose`.

    Attributes
    ----------
    problem : the problem diagnosed.
    alpha : significance used.
    before, after : fits of the base model and of the final model.
    steps : the identification steps in order; the last one's global test passed, or no
        candidate was significant (``unexplained``).
    named : effects in the final model, in the order they were added.
    groups : the confounded group of each named effect (the effect first), as in
        ``confounded``.
    absorbed : candidates (not named) absorbed by the final model.
    outliers : the outlier test of each observation flagged, when it was flagged (its
        ``estimate`` is the shift of each residual component [sigma]).
    dropped : effects named at one step and dropped at a later one (not significant given
        the others), with their Holm-adjusted p-values then.
    """

    problem: Problem
    alpha: float
    before: LeastSquaresFit
    after: LeastSquaresFit
    steps: list[Step]
    named: list[str]
    groups: list[tuple[str, ...]]
    absorbed: list[str]
    outliers: list[CandidateTest] = field(default_factory=list)
    dropped: dict[str, float] = field(default_factory=dict)
    swaps: list[tuple[str, str, float, float]] = field(default_factory=list)
    """(effect out, effect in, AIC before, AIC after) of each swap that improved the final
    model (see :func:`diagnose`)."""
    confounded: list[Group] = field(default_factory=list)
    """The confounded group of each named effect, given the final model (see :class:`Group`)."""
    noise_estimated: bool = False
    """The tests took the noise as estimated from the data (F, Pope's tau), not as known."""

    @property
    def detected(self) -> bool:
        """The base model's detection family rejected something (its global test or a
        candidate)."""
        first = self.steps[0]
        return bool(first.global_p < self.alpha or first.winner is not None)

    @property
    def unexplained(self) -> bool:
        """A misfit remains that no candidate explains: the final model's global test is
        rejected in its detection family."""
        return bool(self.steps[-1].global_p < self.alpha)

    def effect_result(self, name: str) -> dict[str, object]:
        """Fitted parameters and 1-sigma of a named effect, and its identification p-value
        (for an effect swapped in at the end: its Wald test in the final model)."""
        fit = self.after
        params = {p: fit.params[p] for p in self.problem.effect(name).parameters
                  if p in fit.params}
        out: dict[str, object] = {"name": name, "parameters": params,
                                  "stderr": {p: fit.stderr[p] for p in params}}
        step = next((s for s in self.steps if s.winner == name), None)
        if step is None:
            T, dof, p = wald_test(fit, tuple(params), self.noise_estimated)
            return {**out, "p_value": p, "p_value_unadjusted": p, "statistic": T, "dof": dof,
                    "swapped_in": True}
        test = next(t for t in step.tests if t.name == name)
        return {**out, "p_value": test.p_adjusted, "p_value_unadjusted": test.p_value,
                "statistic": test.statistic, "dof": test.dof}


@ONE_THREAD
def diagnose(problem: Problem, alpha: float = ALPHA, power: float = POWER,
             absorbed: float = ABSORBED, confounded: float = CONFOUNDED,
             noise_estimated: bool = False) -> Diagnosis:
    """Detect, identify and adapt until no candidate is rejected in the detection family.

    See the module docstring. The base model is always fitted and its candidates analysed (for
    the absorbed list and the MDBs), whatever the tests say.

    Observations (``problem.observations``) are candidates of their own (data snooping): each
    step tests every observation's mean shift in the same family as the global test and the
    effects (:func:`detection_family`), and the winner is the effect or observation with the
    smallest p-value, unless an effect explains the observation's signal, alone or with one other
    (:func:`effect_for_observation`): that effect comes first. A flagged observation gets its
    shift parameters (it no longer weighs on the fit). After each
    effect is added, every named effect is tested given the others (Wald, Holm at ``alpha``);
    the least significant of those that are not is dropped and the model refitted, until all
    are significant. A dropped effect is not named again.

    With ``noise_estimated`` the noise the problem is whitened with is an estimate from these
    data: the family's tests are F and Pope's tau tests, the Wald tests F tests
    (:mod:`montecarlo.discrepancy.estimated_sigma`).
    """
    full = with_outliers(problem)
    effects_view = replace(full, candidates=problem.candidates)
    outlier_view = replace(full, candidates=full.candidates[len(problem.candidates):])
    fit = fit_model(full, ())
    before = fit
    steps: list[Step] = []
    named: list[str] = []
    outliers: list[CandidateTest] = []
    dropped: dict[str, float] = {}
    fixed: set[str] = set()
    retried = False
    while True:
        tests, snoop, global_p = detection_family(effects_view, outlier_view, fit, alpha,
                                                  power, absorbed, noise_estimated, alpha)
        eligible = [t for t in (*tests, *snoop) if t.status == "testable"
                    and t.p_adjusted < alpha and t.name not in dropped]
        if not eligible and outliers and not retried:
            # before stopping: would one effect explain what the flagged observations took?
            retried = True
            others = [t.name for t in tests if t.status == "testable" and t.name not in dropped]
            alt = _effect_for_outliers(full, fit, [t.name for t in outliers], others, fixed)
            if alt is not None:
                tested = fit
                name, fit = alt
                for t in outliers:
                    dropped[t.name] = math.nan
                steps.append(Step(tested, tests, name, (name,), snoop,
                                  {t.name: math.nan for t in outliers}, global_p))
                outliers = []
                named.append(name)
            continue
        if not eligible:
            steps.append(Step(fit, tests, None, (), snoop, {}, global_p))
            break
        win = min(eligible, key=lambda t: (t.log_p, t.dof))
        if is_outlier(win.name):
            # an effect that explains the observation's signal (alone or with one other
            # effect) comes first
            win = effect_for_observation(win, [t for t in eligible if not is_outlier(t.name)],
                                         fit.residual, win.level, alpha, absorbed) or win
        if not is_outlier(win.name):
            stand_in = minimal_member(
                win, [t for t in eligible if not is_outlier(t.name)],
                [t for t in tests if t.status == "testable" and t.name not in dropped],
                fit.residual, alpha, absorbed, confounded)
            win = win if stand_in is None else stand_in
        partners = [] if is_outlier(win.name) else [
            t for t in tests if t.status == "testable" and t.name != win.name
            and canonical_correlation(win, t) > confounded
            and not separated(win, t, fit.residual, alpha, absorbed)]
        group = (win.name, *(t.name for t in partners))
        start = {**fit.params}
        effect = full.effect(win.name)
        for p, v in win.estimate.items():
            lo, hi = effect.bounds[effect.parameters.index(p)]
            start[p] = float(np.clip(v, lo, hi))
        tested = fit
        try:
            fit = _fit_with_fixed(full, (*fit.effects[1:], win.name), start,
                                  fixed | (set(effect.parameters) - set(win.active)))
        except (FitError, np.linalg.LinAlgError):
            # the adapted model is singular with these data (an effect nearly degenerate with
            # the model, e.g. a roll per pointing with the offsets' direction): not adapted
            dropped[win.name] = math.nan
            fit = tested
            continue
        fixed |= set(effect.parameters) - set(win.active)
        if is_outlier(win.name):
            outliers.append(win)
            steps.append(Step(tested, tests, win.name, (), snoop, {}, global_p))
            continue
        named.append(win.name)
        fit, gone = _reconsider(full, fit, [*named, *(t.name for t in outliers)], fixed, alpha,
                                noise_estimated)
        for name, p in gone.items():
            if is_outlier(name):
                outliers = [t for t in outliers if t.name != name]
            else:
                named.remove(name)
            dropped[name] = p
        steps.append(Step(tested, tests, win.name, group, snoop, gone, global_p))
    swaps: list[tuple[str, str, float, float]] = []
    if len(named) >= 2:
        others = [t.name for t in steps[-1].tests
                  if t.status == "testable" and t.name not in dropped]
        # a candidate absorbed by a named effect may replace it with fewer parameters
        smaller = [t.name for t in steps[0].tests if t.status == "testable"
                   and t.name not in dropped and t.name not in named and t.name not in others]
        # candidates enter with their active parameters only (as an adapted winner does)
        inactive = {p for tests, names in ((steps[0].tests, smaller), (steps[-1].tests, others))
                    for t in tests if t.name in names
                    for p in full.effect(t.name).parameters if p not in t.active}
        fit, swaps = _swap(full, fit, named, others, fixed | inactive, smaller, alpha)
        for out, into, *_ in swaps:
            named[named.index(out)] = into
        if swaps:  # the lists of what the final model absorbs or could miss are its own
            tests, snoop, global_p = detection_family(effects_view, outlier_view, fit, alpha,
                                                      power, absorbed, noise_estimated, alpha)
            steps[-1] = Step(fit, tests, None, (), snoop, {}, global_p)
    final = steps[-1]
    absorbed_list = [t.name for t in final.tests if t.status == "absorbed"
                     and t.name not in named and t.name not in dropped]
    confounded_groups = [_group_of(full, effects_view, fit, name, named, fixed, alpha, power,
                                   absorbed, confounded, noise_estimated) for name in named]
    return Diagnosis(problem, alpha, before, fit, steps, named,
                     [g.members for g in confounded_groups], absorbed_list, outliers, dropped,
                     swaps, confounded_groups, noise_estimated)


def detection_family(effects: Problem, observations: Problem, fit: LeastSquaresFit,
                     alpha: float = ALPHA, power: float = POWER, absorbed: float = ABSORBED,
                     noise_estimated: bool = False, columns_below: float = math.inf
                     ) -> tuple[list[CandidateTest], list[CandidateTest], float]:
    """The tests of one step as one family under Holm's weighted procedure.

    ``effects`` carries the candidate effects, ``observations`` the observations' shift
    effects (no candidates: no data snooping). Members: the global test of ``fit`` and each
    effect (weight 1), the observations (weight 1 together, :func:`family_levels`). Returns
    the effects' and observations' tests with ``p_adjusted`` over the whole family and their
    MDBs at their own first-step sizes, and the global test's adjusted p-value. With the
    noise estimated, the effects' tests are F tests, the observations' Pope's tau and the
    global test the F test against every effect at once (:func:`global_f`). The
    observations' columns (``basis``, ``projected``) are formed for those whose adjusted
    p-value is below ``columns_below`` (all by default; the loop needs only those it can
    name: on thousands of observations the columns of all are an n x n matrix per step).
    """
    kind = ("F", "tau") if noise_estimated else ("chi2", "chi2")
    tests = analyse_candidates(effects, fit, alpha, power, absorbed, test=kind[0])
    members = [t for t in tests if math.isfinite(t.statistic)]
    has_obs = bool(observations.candidates)
    _, obs_share = family_levels(alpha, len(members), has_obs)
    snoop = analyse_observations(observations, fit, alpha, power, absorbed,
                                 level=lambda k: obs_share / max(k, 1),
                                 test=kind[1],
                                 columns_below=math.inf if columns_below == math.inf else 0.0
                                 ) if has_obs else []
    seen = [t for t in snoop if math.isfinite(t.statistic)]
    names = [t.name for t in (*members, *seen)]
    p = [t.p_value for t in (*members, *seen)]
    w = [1.0] * len(members) + [1.0 / max(len(seen), 1)] * len(seen)
    global_test = fit.p_value if not noise_estimated else global_f(
        fit.residual, [t.projected for t in members if t.projected is not None], fit.dof)[3]
    if fit.dof > 0 and math.isfinite(global_test):
        names, p, w = [*names, "global"], [*p, global_test], [*w, 1.0]
    if has_obs and not seen:  # the observations' share stays unspent
        names, p, w = [*names, "observations"], [*p, 1.0], [*w, 1.0]
    adjusted = dict(zip(names, weighted_holm(p, w).tolist(), strict=True)) if p else {}
    global_p = adjusted.get("global", math.nan)

    columns: dict[str, CandidateTest] = {}
    wanted = {t.name for t in seen if adjusted[t.name] < columns_below} \
        if columns_below < math.inf else set()
    if wanted:
        some = replace(observations, candidates=tuple(
            c for c in observations.candidates if c.name in wanted))
        columns = {t.name: t for t in analyse_observations(some, fit, absorbed=absorbed)}

    def update(ts: list[CandidateTest]) -> list[CandidateTest]:
        return [replace(t, p_adjusted=adjusted[t.name],
                        **({"basis": columns[t.name].basis,
                            "projected": columns[t.name].projected} if t.name in columns else {}))
                if t.name in adjusted else t for t in ts]

    return update(tests), update(snoop), global_p


def _group_of(problem: Problem, view: Problem, fit: LeastSquaresFit, name: str,
              named: Sequence[str], fixed: set[str], alpha: float, power: float,
              absorbed: float, confounded: float, noise_estimated: bool = False) -> Group:
    """The confounded group of the named effect ``name`` given the rest of the final model:
    refit without it and collect the candidates (not named) whose statistics correlate with
    its own above ``confounded`` and that the data do not separate from it."""
    try:
        without = _fit_with_fixed(problem, [e for e in fit.effects[1:] if e != name],
                                  fit.params, fixed)
    except (FitError, np.linalg.LinAlgError):
        return Group(name, (name,))
    tests = analyse_candidates(view, without, alpha, power, absorbed,
                               test="F" if noise_estimated else "chi2")
    own = next(t for t in tests if t.name == name)
    if own.status != "testable":
        return Group(name, (name,))
    correlation = {}
    for t in tests:
        if t.status == "testable" and t.name not in named:
            rho = canonical_correlation(own, t)
            if rho > confounded and not separated(own, t, without.residual, alpha, absorbed):
                correlation[t.name] = rho
    return Group(name, (name, *correlation), correlation,
                 {m: problem.separating_data.get(frozenset((name, m)), "") for m in correlation})


def _effect_for_outliers(problem: Problem, fit: LeastSquaresFit, flagged: Sequence[str],
                         others: Sequence[str], fixed: set[str]
                         ) -> tuple[str, LeastSquaresFit] | None:
    """The candidate that, fitted instead of all the flagged observations' shifts, gives the
    lowest Akaike criterion ``chi2 + 2 p``, if lower than the model with the shifts (a
    systematic effect seen first at the observations where it is largest); else None."""
    kept = [e for e in fit.effects[1:] if e not in flagged]
    best: tuple[float, str, LeastSquaresFit] | None = None
    for name in others:
        try:
            alt = _fit_with_fixed(problem, [*kept, name], fit.params, fixed)
        except (FitError, np.linalg.LinAlgError):
            continue
        score = alt.chi2 + 2.0 * len(alt.names)
        if score < fit.chi2 + 2.0 * len(fit.names) and (best is None or score < best[0]):
            best = (score, name, alt)
    return None if best is None else (best[1], best[2])


def _swap(problem: Problem, fit: LeastSquaresFit, named: Sequence[str],
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
                    alt = _fit_with_fixed(problem, model, fit.params, fixed)
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


def _reconsider(problem: Problem, fit: LeastSquaresFit, named: Sequence[str], fixed: set[str],
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
        fit = _fit_with_fixed(problem, model, fit.params, fixed)
    return fit, gone


def _fit_with_fixed(problem: Problem, effects: Sequence[str], start: Mapping[str, float],
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


