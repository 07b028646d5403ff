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
   (:func:`~montecarlo.discrepancy.confounding.minimal_member`); the groups reported are
   those of the final model. A rejected global test with no candidate rejected is a misfit no
   candidate explains. With the noise estimated from the data (``noise_estimated``) the tests
   are F and Pope's tau (:mod:`montecarlo.discrepancy.estimated_sigma`).
4. **Adapt**: add the winner's parameters, refit the nonlinear model, go back to 2 (a winner
   whose adapted model is singular is refitted with its least separable parameter held at
   zero, as an absorbed one, and dropped with p = NaN only if none of its parameters can be
   fitted; parameters absorbed where the winner is zero are freed when the adapted model
   separates them and they lower chi2 significantly at ``alpha``); stop when no candidate
   is rejected.
5. **Swap and report**: with two or more effects named, a named effect is replaced by another
   candidate while that lowers Akaike's criterion (a swap that adds parameters must also pass
   a chi2 test of them); the report gives the final model, the candidates it absorbs and the
   confounded group of each named effect.

The *minimal detectable bias* (MDB) of a parameter is the size ``|b|`` at which the
candidate's own test rejects with probability ``power`` (0.80) at its size in the family's
first Holm step (``alpha / (m + 2)`` for ``m`` candidate effects, the global test and the
observations; an observation's share is that over the number of observations): Baarda's
noncentrality ``lambda0`` of that chi2(q) test and ``MDB = sqrt(lambda0 / |Gbar e_k|^2)``. A
candidate that stays below ``lambda0`` anywhere inside its physical bounds is
*undetectable*: no physically possible size of it could be told from noise, so it is never
named (a significant signal along its columns must come from something else).

Each stage is a module over one :class:`~montecarlo.discrepancy.state.DiagnosisState`: the
fit :mod:`~montecarlo.discrepancy.fit`, then :mod:`~montecarlo.discrepancy.detect`,
:mod:`~montecarlo.discrepancy.identify` (its rules in :mod:`~montecarlo.discrepancy.confounding`),
:mod:`~montecarlo.discrepancy.adapt` and :mod:`~montecarlo.discrepancy.report`; the
statistics are :mod:`~montecarlo.discrepancy.candidate_tests`.

References
----------
Baarda, W. (1968), A testing procedure for use in geodetic networks; Teunissen, P. J. G. (2000),
Testing theory; Teunissen, P. J. G. (2018), Distributional theory for the DIA method,
J. Geodesy 92: 59-80. Holm, S. (1979), A simple sequentially rejective multiple test procedure.
"""

from __future__ import annotations

from montecarlo.discrepancy.adapt import adapt, explain_outliers, swap_named
from montecarlo.discrepancy.candidate_tests import ABSORBED, ALPHA, CONFOUNDED, POWER
from montecarlo.discrepancy.detect import detect, detection_family
from montecarlo.discrepancy.fit import ONE_THREAD
from montecarlo.discrepancy.identify import identify
from montecarlo.discrepancy.problem import Problem
from montecarlo.discrepancy.report import Diagnosis, Group, report
from montecarlo.discrepancy.state import DiagnosisState, Rules, Step

__all__ = ["ALPHA", "Diagnosis", "Group", "Step", "detection_family", "diagnose"]


@ONE_THREAD
def diagnose(problem: Problem, alpha: float = ALPHA, power: float = POWER,
             absorbed: float = ABSORBED, confounded: float = CONFOUNDED,
             noise_estimated: bool = False) -> Diagnosis:
    """Detect, identify and adapt until no candidate is rejected in the detection family.

    See the module docstring. Each step is three stages over one :class:`DiagnosisState`:
    :func:`detect` (the detection family of the current fit), :func:`identify` (its winner and
    confounded partners) and :func:`adapt` (add the winner, refit, drop what the others then
    explain); with nothing rejected, :func:`explain_outliers` first asks once whether one
    effect explains the flagged observations, then the loop stops. :func:`swap_named` improves
    the final model, :func:`report` states it. The base model is always fitted and its
    candidates analysed (for the absorbed list and the MDBs), whatever the tests say.

    Observations (``problem.observations``) are candidates of their own (data snooping): each
    step tests every observation's mean shift in the same family as the global test and the
    effects (:func:`detection_family`), and the winner is the effect or observation with the
    smallest p-value, unless an effect explains the observation's signal, alone or with one other
    (:func:`~montecarlo.discrepancy.confounding.effect_for_observation`): that effect comes
    first (not an effect of no fewer parameters whose signal the observation explains too).
    A flagged observation gets its shift parameters (it no longer weighs on the fit).
    After each effect is added, every named effect is tested given the others (Wald, Holm at
    ``alpha``); the least significant of those that are not is dropped and the model refitted,
    until all are significant. A dropped effect is not named again.

    With ``noise_estimated`` the noise the problem is whitened with is an estimate from these
    data: the family's tests are F and Pope's tau tests, the Wald tests F tests
    (:mod:`montecarlo.discrepancy.estimated_sigma`).
    """
    state = DiagnosisState.start(problem, Rules(alpha, power, absorbed, confounded,
                                                noise_estimated))
    while True:
        detection = detect(state)
        winner = identify(state, detection)
        if winner is not None:
            adapt(state, detection, winner)
        elif state.outliers and not state.retried:
            explain_outliers(state, detection)
        else:
            state.steps.append(detection.step())
            break
    swap_named(state)
    return report(state)
