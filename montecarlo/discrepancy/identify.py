"""Identification stage of the DIA loop: the winner of a detection family, the candidate that
stands in for it and the candidates confounded with it.

The rules that compare candidates (whether the data separate two, whether an effect explains an
observation's signal, a group's minimal parametrisation) are
:mod:`montecarlo.discrepancy.confounding`.
"""

from __future__ import annotations

from dataclasses import dataclass

from montecarlo.discrepancy.candidate_tests import CandidateTest, canonical_correlation
from montecarlo.discrepancy.confounding import effect_for_observation, minimal_member, separated
from montecarlo.discrepancy.detect import Detection
from montecarlo.discrepancy.problem import is_outlier
from montecarlo.discrepancy.state import DiagnosisState


@dataclass(frozen=True)
class Winner:
    """The candidate to adapt (an effect, or an observation ``outlier:ID``) and its confounded
    group (the winner first; empty for an observation)."""

    test: CandidateTest
    group: tuple[str, ...]


def identify(state: DiagnosisState, detection: Detection) -> Winner | None:
    """The winner of the detection family, None if no candidate is rejected.

    Of the eligible candidates (testable, rejected, not dropped) the one with the smallest
    p-value; for an observation, an effect that explains its signal (alone or with one other,
    :func:`effect_for_observation`) comes first; an effect gives way to its group's minimal
    parametrisation (:func:`minimal_member`). Its partners are the testable candidates whose
    statistics correlate with it above ``confounded`` and that the data do not separate from it.
    """
    rules, residual = state.rules, detection.fit.residual
    eligible = [t for t in state.open_tests([*detection.tests, *detection.snoop])
                if t.p_adjusted < rules.alpha]
    if not eligible:
        return None
    effects = [t for t in eligible if not is_outlier(t.name)]
    win = min(eligible, key=lambda t: (t.log_p, t.dof))
    if is_outlier(win.name):
        win = effect_for_observation(win, effects, residual, win.level, rules.alpha,
                                     rules.absorbed) or win
    if is_outlier(win.name):
        return Winner(win, ())
    stand_in = minimal_member(win, effects, state.open_tests(detection.tests), residual,
                              rules.alpha, rules.absorbed, rules.confounded)
    win = win if stand_in is None else stand_in
    partners = [t.name for t in detection.tests if t.status == "testable" and t.name != win.name
                and canonical_correlation(win, t) > rules.confounded
                and not separated(win, t, residual, rules.alpha, rules.absorbed)]
    return Winner(win, (win.name, *partners))
