"""Report stage of the DIA loop: the final model's confounded groups and absorbed candidates,
and the :class:`Diagnosis`."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from montecarlo.discrepancy.adapt import fit_with_fixed
from montecarlo.discrepancy.candidate_tests import (
    CandidateTest,
    analyse_candidates,
    canonical_correlation,
    wald_test,
)
from montecarlo.discrepancy.confounding import separated
from montecarlo.discrepancy.fit import FitError
from montecarlo.discrepancy.problem import Problem
from montecarlo.discrepancy.state import DiagnosisState, Step
from montecarlo.lsq import LeastSquaresFit


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
    """Result of :func:`~montecarlo.discrepancy.engine.diagnose`.

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
    model (see :func:`~montecarlo.discrepancy.engine.diagnose`)."""
    confounded: list[Group] = field(default_factory=list)
    """The confounded group of each named effect, given the final model (see :class:`Group`)."""
    noise_estimated: bool = False
    """The tests took the noise as estimated from the data (F, Pope's tau), not as known."""
    without: dict[str, LeastSquaresFit] = field(default_factory=dict, repr=False)
    """The final model refitted without each named effect, from the final values (as
    :func:`~montecarlo.discrepancy.significance.practical_significance` refits it), where no
    parameter is held at zero."""

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


def report(state: DiagnosisState) -> Diagnosis:
    """The diagnosis of the final state: the candidates the final model absorbs (not named,
    not dropped) and the confounded group of each named effect."""
    absorbed = [t.name for t in state.steps[-1].tests if t.status == "absorbed"
                and t.name not in state.named and t.name not in state.dropped]
    refits = {name: group_of(state, name) for name in state.named}
    groups = [g for g, _ in refits.values()]
    without = {name: fit for name, (_, fit) in refits.items()
               if fit is not None and not state.fixed}
    return Diagnosis(state.problem, state.rules.alpha, state.before, state.fit, state.steps,
                     state.named, [g.members for g in groups], absorbed, state.outliers,
                     state.dropped, state.swaps, groups, state.rules.noise_estimated, without)


def group_of(state: DiagnosisState, name: str) -> tuple[Group, LeastSquaresFit | None]:
    """The confounded group of the named effect ``name`` given the rest of the final model:
    refit without it and collect the candidates (not named) whose statistics correlate with
    its own above ``confounded`` and that the data do not separate from it. Also returns
    that refit (None where it failed)."""
    rules, fit, problem = state.rules, state.fit, state.full
    try:
        without = fit_with_fixed(problem, [e for e in fit.effects[1:] if e != name],
                                 fit.params, state.fixed)
    except (FitError, np.linalg.LinAlgError):
        return Group(name, (name,)), None
    tests = analyse_candidates(state.effects, without, rules.alpha, rules.power, rules.absorbed,
                               test="F" if rules.noise_estimated else "chi2")
    own = next(t for t in tests if t.name == name)
    if own.status != "testable":
        return Group(name, (name,)), without
    correlation = {}
    for t in tests:
        if t.status == "testable" and t.name not in state.named:
            rho = canonical_correlation(own, t)
            if rho > rules.confounded and not separated(own, t, without.residual, rules.alpha,
                                                        rules.absorbed):
                correlation[t.name] = rho
    return Group(name, (name, *correlation), correlation,
                 {m: problem.separating_data.get(frozenset((name, m)), "")
                  for m in correlation}), without
