"""Detection stage of the DIA loop: the tests of one step as one family under Holm's weighted
procedure (the global test, each candidate effect, the observations together)."""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

from montecarlo.discrepancy.candidate_tests import (
    ABSORBED,
    ALPHA,
    POWER,
    CandidateTest,
    analyse_candidates,
    family_levels,
    weighted_holm,
)
from montecarlo.discrepancy.estimated_sigma import global_f
from montecarlo.discrepancy.observation_tests import analyse_observations
from montecarlo.discrepancy.problem import Problem
from montecarlo.discrepancy.state import DiagnosisState, Step
from montecarlo.lsq import LeastSquaresFit


@dataclass(frozen=True)
class Detection:
    """The detection family at the current fit: each candidate effect's test (``tests``), each
    observation's (``snoop``), with Holm-adjusted p-values, and the global test's (``global_p``)."""

    fit: LeastSquaresFit
    tests: list[CandidateTest]
    snoop: list[CandidateTest]
    global_p: float

    def step(self, winner: str | None = None, group: tuple[str, ...] = (),
             dropped: dict[str, float] | None = None) -> Step:
        """The record of a step that tested this family."""
        return Step(self.fit, self.tests, winner, group, self.snoop, dropped or {},
                    self.global_p)


def detect(state: DiagnosisState) -> Detection:
    """The detection family of the state's current fit (:func:`detection_family`)."""
    rules = state.rules
    tests, snoop, global_p = detection_family(state.effects, state.observations, state.fit,
                                              rules.alpha, rules.power, rules.absorbed,
                                              rules.noise_estimated, rules.alpha)
    return Detection(state.fit, tests, snoop, global_p)


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
                                 columns_below=math.inf if columns_below == math.inf else 0.0,
                                 adjust=False) if has_obs else []
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

    for t in (*tests, *snoop):  # made above for this family alone: set, not copied
        if t.name in adjusted:
            t.__dict__["p_adjusted"] = adjusted[t.name]
        if t.name in columns:
            t.__dict__.update(basis=columns[t.name].basis, projected=columns[t.name].projected)
    return tests, snoop, global_p
