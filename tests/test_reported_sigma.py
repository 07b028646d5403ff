"""Coverage of the σ each system reports: errors over reported σ, pooled over many data sets.

If a fit reports honest standard errors, ``z = (estimate - truth) / σ`` is standard normal, so
``Σ z²`` over ``m`` independent sets is χ² with ``m`` degrees of freedom, and the fit's own
``χ²`` summed over the sets is χ² with the summed degrees of freedom (χ²_red pooled ≈ 1). Each
test accepts these sums between the χ² quantiles at ``p/2`` and ``1 - p/2``, with ``p = 1e-3``
split (Bonferroni) over the quantities it checks. A σ reported too small or too large by 30 %
moves ``Σ z²/m`` by a factor 1.69 or 0.59, outside the bands of the fast versions (ground
[0.78, 1.25] for 450 terms, stabilisation [0.70, 1.37] for 250 runs); the slow versions use
about ten times more sets.

The air system's reported σ (the transfer-alignment filter's covariance) is checked the same
way in ``tests/test_transfer_alignment.py::test_filter_is_consistent_with_its_truth``.
"""

import numpy as np
import pytest
from scipy import stats

from montecarlo.discrepancy import ground_effects as ge
from montecarlo.discrepancy.fit import fit_model
from montecarlo.geometry.camera import Camera
from montecarlo.systems import stabilization as ss
from tests.acceptance import Figures

P = 1e-3


def _band(dof: int, checks: int) -> tuple[float, float]:
    """Bounds of ``χ²/dof`` at total two-sided probability P split over ``checks``."""
    q = P / checks
    lo, hi = stats.chi2.ppf([q / 2.0, 1.0 - q / 2.0], dof)
    return lo / dof, hi / dof


# --- ground: the fit of the mounting to targets of known position ---------------------------

CAMERA = Camera.from_degrees(60.0, 40.0, 1280, 720)
"""A non-square camera (16:9 pixels over 60 x 40 deg)."""
MOUNT = {"psi": np.radians(12.0), "theta": np.radians(-7.0), "gamma": np.radians(3.0)}
"""A mounting with a non-zero elevation (theta) [rad]."""


def _ground_coverage(sets: int, seed: int) -> tuple[float, int, float, int]:
    """Σ z² over sets and parameters (and its dof); pooled χ² of the fits (and its dof)."""
    layout = ge.field_layout(CAMERA, MOUNT, (40.0, 90.0, 150.0), (5, 4), 0.85, 1800.0, rng=seed)
    truth = np.array([MOUNT[k] for k in ("psi", "theta", "gamma")])
    rng = np.random.default_rng(seed)
    z2 = chi2 = 0.0
    dof = 0
    for _ in range(sets):
        data = ge.simulate(layout, CAMERA, MOUNT, 0.4, 0.01, rng)
        fit = fit_model(ge.ground_problem(data, CAMERA, 0.4, 0.01), ())
        e = fit.values - truth
        z2 += float(e @ np.linalg.solve(fit.covariance, e))
        chi2 += fit.chi2
        dof += fit.dof
    return z2, 3 * sets, chi2, dof


def _check_ground(sets: int, seed: int, figures: Figures | None = None) -> None:
    z2, k, chi2, dof = _ground_coverage(sets, seed)
    lo, hi = _band(k, 2)
    if figures is not None:
        figures.record("ground.mean_z2", z2 / k, lo, hi)
    assert lo < z2 / k < hi, z2 / k
    lo, hi = _band(dof, 2)
    if figures is not None:
        figures.record("ground.chi2_red", chi2 / dof, lo, hi)
    assert lo < chi2 / dof < hi, chi2 / dof


def test_ground_fit_sigma_covers_its_error():
    """150 sets of 20 targets at three ranges, pixel σ 0.4 px, survey σ 1 cm: the mounting's
    (ψ, θ, γ) error against its reported covariance (eᵀC⁻¹e is χ²₃ per set) and the pooled
    χ²_red of the fits (150 x 37 dof)."""
    _check_ground(150, 7)


@pytest.mark.slow
def test_ground_fit_sigma_covers_its_error_over_many_sets(figures):
    _check_ground(1500, 8, figures)


# --- stabilisation: the recursive estimate of the four observable combinations ---------------

COMBINATIONS = ("dpx", "dgx", "dgy", "dz", "dpy")


def _check_stabilization(params: dict, trials: int, seed: int,
                         figures: Figures | None = None) -> None:
    out = ss.run_trials(params, np.random.default_rng(seed), trials)
    lo, hi = _band(trials, len(COMBINATIONS))
    for q in COMBINATIONS:
        z2 = np.mean((out[f"{q}_error"] / out[f"{q}_sigma"]) ** 2)
        if figures is not None:
            figures.record(f"stabilization.{q}.mean_z2", z2, lo, hi)
        assert lo < z2 < hi, (q, z2)


def test_stabilization_sigma_covers_its_error():
    """250 runs of 10 s at 40 Hz (not the default 100 Hz), a target 200 px off centre: for
    each of the four combinations and δpy, the mean of (error / σ)² over the runs."""
    _check_stabilization({"duration": 10.0, "rate": 40.0, "target_offset": 200.0}, 250, 3)


@pytest.mark.slow
def test_stabilization_sigma_covers_its_error_over_many_runs(figures):
    """1000 runs at the defaults (60 s, 100 Hz; about 40 s)."""
    _check_stabilization({}, 1000, 4, figures)
