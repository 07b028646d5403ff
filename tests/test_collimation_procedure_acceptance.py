"""Acceptance of the procedure's fit by Monte Carlo: offsets within 2σ as often as a normal error
(the binomial band of 95.45 % at the number of trials), the σ not inflated.

Each case: γ, λ uniform in 10″–600″ with random signs, theodolite and INS errors 2″, mount roll
1° (1σ) unless the case is "level", 250 trials (docs/validation/collimation.md has the table).
"""

import math

import numpy as np
import pytest

from montecarlo.seed003 import procedure as pr
from tests.acceptance import check_coverage, check_not_inflated, coverage_band, slug


def _case(name: str, n: int, seed: int) -> dict:
    """``pr.acceptance_case`` with the prior of the unrecorded rolls at the simulated 1 deg roll
    (its default 2 deg prior makes the offsets' sigma conservative, which a two-sided check
    rejects)."""
    layout, rows, roll, side = pr.ACCEPTANCE_CASES[name]
    az, el, _ = pr.procedure_layout(pitches=pr.PAPER_PITCHES if layout == "paper-like"
                                    else pr.HIGH_PITCHES)
    return pr.acceptance_trials(n, np.random.default_rng(seed), az, el, side=side,
                                reference_rows=rows, roll=roll, roll_sigma=math.radians(1.0))


def _inside(out):
    return {k: int(np.sum(np.abs(out[f"{k}_error"]) <= 2 * out[f"{k}_sigma"]))
            for k in ("axis_az", "axis_el")}


def _sum_z2(out, k):
    return float(np.sum((out[f"{k}_error"] / out[f"{k}_sigma"]) ** 2))


FREE_ROLL_FINDING = pytest.mark.xfail(strict=True, reason=(
    "sigma of gamma optimistic with free rolls on the paper-like layout: gamma within 2 sigma in "
    "89.6 % (reference rows, right) and 90.0 % (relative, left) of 250 trials, below the band "
    "90.4-99.2 %, mean (error/sigma)^2 1.59 and 1.64 (error std 81 arcsec against a median "
    "sigma of 61); gamma is seen only through 1/cos(el) - 1 <= 0.05 and the free rolls turn "
    "lambda into heading, so the linearised sigma misses the spread; lambda's coverage holds"))


def _params(names):
    return [pytest.param(n, marks=FREE_ROLL_FINDING) if n.startswith("paper-like")
            and ", free," in n else n for n in names]


@pytest.mark.slow
@pytest.mark.parametrize("name", _params(pr.ACCEPTANCE_CASES))
def test_offsets_within_2_sigma_at_the_nominal_rate(name, figures):
    n = 250
    out = _case(name, n, 2024 + list(pr.ACCEPTANCE_CASES).index(name))
    inside = _inside(out)
    print(f"{name}: within 2σ γ {inside['axis_az'] / n:.3f}, λ {inside['axis_el'] / n:.3f}")
    for k, count in inside.items():
        check_coverage(figures, slug(name, f"{k}_within_2sigma"), count, n)
        check_not_inflated(figures, slug(name, f"{k}_mean_z2"), _sum_z2(out, k), n)


@pytest.mark.parametrize("name", ["pitch to 60°, reference rows, recorded, right",
                                  "pitch to 60°, relative, level, right"])
def test_offsets_within_2_sigma_small(name):
    """16 trials: within 2σ in the binomial band of 95.45 % (at 16 trials it bounds only from
    below, so the mean (error/σ)² is also kept above χ²'s 0.001 quantile); mean χ²_red within 3
    of its standard errors, sqrt(2 / 17 / n)."""
    n = 16
    out = _case(name, n, 7)
    assert coverage_band(n)[1] == 1.0
    for k, count in _inside(out).items():
        check_coverage(None, k, count, n)
        check_not_inflated(None, k, _sum_z2(out, k), n)
    assert abs(np.mean(out["chi2_red"]) - 1) < 3 * math.sqrt(2 / 17 / n)
