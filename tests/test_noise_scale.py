"""The noise scale the data give (a-posteriori variance factor) and its interval.

Simulated linear models with a true noise 1.3 times the stated one: the interval's coverage
is checked two-sided against a binomial band, the estimate's spread against 5 %.
"""

import numpy as np
import pytest
from scipy import stats

from montecarlo.discrepancy.fit import fit_model
from montecarlo.discrepancy.noise import format_noise, noise_scale
from montecarlo.discrepancy.problem import Effect, Problem
from montecarlo.lsq import LeastSquaresFit

LINE = Effect("line", ("a", "b"), ((-np.inf, np.inf),) * 2, (1e-3,) * 2)
TRUE = 1.3  # true noise / stated noise


def line_fit(y, x):
    """The least-squares line through (x, y) as the engine's fit type (numpy's lstsq)."""
    A = np.column_stack([np.ones_like(x), x])
    coef, *_ = np.linalg.lstsq(A, y, rcond=None)
    return LeastSquaresFit(("a", "b"), coef, np.linalg.inv(A.T @ A), y - A @ coef, A)


def test_the_factor_of_the_engines_fit_is_sqrt_chi2_over_dof():
    x = np.linspace(-1, 1, 50)
    y = 0.2 + TRUE * np.random.default_rng(0).standard_normal(x.size)

    def residuals(v):
        return y - np.asarray(v.get("a", 0.0)) - np.asarray(v.get("b", 0.0)) * x

    fit = fit_model(Problem("toy", LINE, (), residuals, {"a": 0.0, "b": 0.0}), ())
    s = noise_scale(fit)
    assert s["factor"] == pytest.approx(np.sqrt(line_fit(y, x).chi2 / 48), rel=1e-9)
    lo, hi = stats.chi2.ppf([0.025, 0.975], 48)
    assert (s["low"], s["high"]) == pytest.approx(
        (np.sqrt(fit.chi2 / hi), np.sqrt(fit.chi2 / lo)), rel=1e-12)


def test_interval_coverage_and_precision_on_1000_residuals():
    """2,000 sets of 1,000 residuals: the 95 % interval holds the true factor in 93-97 % of
    sets (two-sided), the estimate is within 5 % of it in at least 95 %."""
    x = np.linspace(-1, 1, 1000)
    sets = 2000
    A = np.column_stack([np.ones_like(x), x])
    Q = np.linalg.qr(A)[0]
    Y = TRUE * np.random.default_rng(7).standard_normal((x.size, sets))
    R = Y - Q @ (Q.T @ Y)  # every set's least-squares residuals at once
    cov = np.linalg.inv(A.T @ A)
    inside = close = 0
    for j in range(sets):
        s = noise_scale(LeastSquaresFit(("a", "b"), np.zeros(2), cov, R[:, j], A))
        inside += s["low"] <= TRUE <= s["high"]
        close += abs(s["factor"] / TRUE - 1.0) <= 0.05
    assert 0.93 <= inside / sets <= 0.97
    assert close / sets >= 0.95


@pytest.mark.parametrize(("scale", "verdict"), [(1.0, "consistent"), (1.3, "stated too small"),
                                                 (0.7, "stated too large")])
def test_a_stated_noise_the_data_reject_is_warned(scale, verdict):
    x = np.linspace(-1, 1, 1000)
    s = noise_scale(line_fit(scale * np.random.default_rng(3).standard_normal(x.size), x))
    assert s["verdict"] == verdict
    text = format_noise(s, {"pixel sigma px": 0.25})
    assert ("warning: the stated noise is rejected" in text) == (verdict != "consistent")
    assert f"pixel sigma px {0.25 * s['factor']:.4g}" in text


def test_pixel_sigma_flag_takes_auto_or_a_positive_number(capsys):
    from montecarlo.cli import main

    assert main(["diagnose", "camera", "m.csv", "v.csv", "--pixel-sigma-px", "often"]) == 2
    assert "--pixel-sigma-px" in capsys.readouterr().err
