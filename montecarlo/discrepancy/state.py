"""What the DIA loop (:func:`montecarlo.discrepancy.engine.diagnose`) carries from step to step.

:class:`Rules` holds the levels a diagnosis is run at, :class:`DiagnosisState` the problem's
views and everything the stages (detect, identify, adapt) read and change, and :class:`Step`
the record of one identification step.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace

from montecarlo.discrepancy.candidate_tests import CandidateTest
from montecarlo.discrepancy.fit import fit_model
from montecarlo.discrepancy.problem import Problem, with_outliers
from montecarlo.lsq import LeastSquaresFit


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
class Rules:
    """The levels of a diagnosis: significance ``alpha``, the MDBs' ``power``, the share of a
    column's norm below which it is ``absorbed``, the canonical correlation above which two
    candidates are ``confounded``, and whether the noise is estimated from the data."""

    alpha: float
    power: float
    absorbed: float
    confounded: float
    noise_estimated: bool


@dataclass
class DiagnosisState:
    """The diagnosis so far.

    Attributes
    ----------
    problem : the problem diagnosed.
    rules : the levels it is diagnosed at.
    full : the problem with each observation's shift effect among its candidates.
    effects, observations : ``full`` with only the candidate effects, only the observations'
        shift effects as candidates (the two parts of the detection family).
    before : the fit of the base model.
    fit : the fit of the current model.
    steps : the identification steps so far.
    named : effects in the current model, in the order they were added.
    outliers : the outlier test of each observation flagged, when it was flagged.
    dropped : effects and observations not to be named again, with their adjusted p-values
        when they were dropped (NaN: their adapted model was singular, or an effect explained
        them).
    fixed : parameters held at zero (absorbed when their effect was adapted).
    retried : whether an effect was already sought for the flagged observations.
    swaps : (effect out, effect in, AIC before, AIC after) of each swap that improved the
        final model.
    """

    problem: Problem
    rules: Rules
    full: Problem
    effects: Problem
    observations: Problem
    before: LeastSquaresFit
    fit: LeastSquaresFit
    steps: list[Step] = field(default_factory=list)
    named: list[str] = field(default_factory=list)
    outliers: list[CandidateTest] = field(default_factory=list)
    dropped: dict[str, float] = field(default_factory=dict)
    fixed: set[str] = field(default_factory=set)
    retried: bool = False
    swaps: list[tuple[str, str, float, float]] = field(default_factory=list)

    @classmethod
    def start(cls, problem: Problem, rules: Rules) -> DiagnosisState:
        """The state before the first step: the problem's views and the base model's fit."""
        full = with_outliers(problem)
        base = fit_model(full, ())
        return cls(problem, rules, full,
                   effects=replace(full, candidates=problem.candidates),
                   observations=replace(full, candidates=full.candidates[len(problem.candidates):]),
                   before=base, fit=base)

    def open_tests(self, tests: list[CandidateTest]) -> list[CandidateTest]:
        """The testable candidates of ``tests`` that were not dropped."""
        return [t for t in tests if t.status == "testable" and t.name not in self.dropped]
