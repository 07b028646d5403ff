"""Acceptance of the procedure's fit by Monte Carlo: offsets within 2σ in ≥ 90 % of trials.

Each case: γ, λ uniform in 10″–600″ with random signs, theodolite and INS errors 2″, mount roll
1° (1σ) unless the case is "level", 500 trials (docs/collimation.md has the measured table).
"""

import math

import numpy as np
import pytest

from montecarlo.seed003 import procedure as pr


def _coverage(out):
    return {k: float(np.mean(np.abs(out[f"{k}_error"]) <= 2 * out[f"{k}_sigma"]))
            for k in ("axis_az", "axis_el")}


@pytest.mark.slow
@pytest.mark.parametrize("name", list(pr.ACCEPTANCE_CASES))
def test_offsets_within_2_sigma_in_90_percent(name):
    n = 500
    out = pr.acceptance_case(name, n, 2024 + list(pr.ACCEPTANCE_CASES).index(name))
    coverage = _coverage(out)
    print(f"{name}: within 2σ γ {coverage['axis_az']:.3f}, λ {coverage['axis_el']:.3f}")
    assert min(coverage.values()) >= 0.90  # acceptance


@pytest.mark.parametrize("name", ["pitch to 60°, reference rows, recorded, right",
                                  "pitch to 60°, relative, level, right"])
def test_offsets_within_2_sigma_small(name):
    """16 trials: at least the Gaussian 95.45 % minus 3 binomial standard errors (0.80);
    mean χ²_red within 3 of its standard errors, sqrt(2 / 17 / n)."""
    n, p = 16, 0.9545
    out = pr.acceptance_case(name, n, 7)
    for value in _coverage(out).values():
        assert value >= p - 3 * math.sqrt(p * (1 - p) / n)
    assert abs(np.mean(out["chi2_red"]) - 1) < 3 * math.sqrt(2 / 17 / n)
