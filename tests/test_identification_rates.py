"""The linearised first step of the diagnosis (montecarlo/discrepancy/identification_rates.py).

References the code did not compute: the closed form of the PCI of a single candidate under
Holm's procedure (noncentral chi2 tail and a scipy quadrature), scipy's chi2 tail, the engine's
own weighted Holm procedure, and the engine's whole diagnosis of the same simulated data, set
by set.
"""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest
from scipy import integrate, stats

from montecarlo.discrepancy import identification_rates as ir
from montecarlo.discrepancy.candidate_tests import log_chi2_sf, weighted_holm
from montecarlo.discrepancy.engine import diagnose
from montecarlo.discrepancy.fit import fit_model
from montecarlo.discrepancy.problem import Effect, Problem

FREE = (-math.inf, math.inf)


def linear_problem(A, columns, data=None, observations=()):
    """A linear model ``data = A x + sum_j G_j b_j + e`` with whitened noise: base
    parameters ``x0..``, one candidate ``c<j>`` per block ``G_j`` of ``columns`` (an (n, q)
    array: one candidate per column; or a list of (n, q_j) blocks), its parameters
    ``b<j>_<k>``."""
    n, p = A.shape
    blocks = [columns[:, [j]] for j in range(columns.shape[1])] \
        if isinstance(columns, np.ndarray) else list(columns)
    y = np.zeros(n) if data is None else np.asarray(data, float)
    base = Effect("base", tuple(f"x{i}" for i in range(p)), (FREE,) * p, (1.0,) * p)
    cands = tuple(Effect(f"c{j}", tuple(f"b{j}_{k}" for k in range(G.shape[1])),
                         (FREE,) * G.shape[1], (1.0,) * G.shape[1])
                  for j, G in enumerate(blocks))

    def residuals(values):
        pred = 0.0
        for i in range(p):
            pred = pred + np.asarray(values.get(f"x{i}", 0.0), float) * A[:, i]
        for j, G in enumerate(blocks):
            for k in range(G.shape[1]):
                pred = pred + np.asarray(values.get(f"b{j}_{k}", 0.0), float) * G[:, k]
        return y - pred

    return Problem("linear", base, cands, residuals, {}, observations=observations)


def holm_pci(lam, q, r, alpha):
    """Closed form: PCI of the only candidate (q dof, noncentrality ``lam``) in a family of it
    and the global test (r dof, weights 1 and 1). Holm rejects the candidate when its p-value
    is at most alpha/2, or at most alpha while the global test's is at most alpha/2; the
    global statistic is the candidate's plus an independent central chi2(r - q)."""
    c1, c2 = stats.chi2.isf(alpha / 2, q), stats.chi2.isf(alpha, q)
    g1 = stats.chi2.isf(alpha / 2, r)
    first = stats.ncx2.sf(c1, q, lam) if lam > 0 else stats.chi2.sf(c1, q)

    def density(t):
        f = stats.ncx2.pdf(t, q, lam) if lam > 0 else stats.chi2.pdf(t, q)
        return f * stats.chi2.sf(g1 - t, r - q)

    second, _ = integrate.quad(density, c2, c1, epsabs=1e-12)
    return first + second


@pytest.mark.parametrize("lam", [0.0, 8.0, 18.0])
def test_single_candidate_pci_matches_closed_form(lam):
    """One candidate (1 dof) on 30 observations, 3 base parameters: the simulated PCI on
    40,000 sets is within 4 binomial standard deviations of the closed form at noncentrality
    0 (false naming), 8 and 18."""
    rng = np.random.default_rng(5)
    A, G = rng.standard_normal((30, 3)), rng.standard_normal((30, 1))
    problem = linear_problem(A, G)
    fit = fit_model(problem, ())
    step = ir.first_step(problem, fit)
    assert step.names == ("c0",) and step.r == 27
    Gbar = G[:, 0] - A @ np.linalg.lstsq(A, G[:, 0], rcond=None)[0]
    b = math.sqrt(lam) / np.linalg.norm(Gbar)
    sets = 40_000
    rates = ir.LinearRates(step, sets, seed=11)
    got = rates.pci("c0", ir.signal(problem, fit, {"b0_0": b}))
    want = holm_pci(lam, 1, 27, 0.01)
    sd = math.sqrt(max(want * (1 - want), 1e-4) / sets)
    assert abs(got - want) <= 4 * sd, (got, want)


@pytest.mark.parametrize("n, sets", [(20, 40), pytest.param(32, 200, marks=pytest.mark.slow)])
def test_first_step_equals_the_engine_set_by_set(n, sets):
    """Three one-parameter candidates (two correlated) and n/2 observations of 2 rows: with
    c1 at noncentrality 12, the first-step winner of the vectorised rule equals the first
    step of the engine's whole diagnosis of the same data set by set, except where the rule
    flags an observation and the engine names an effect instead (an effect that explains a
    flagged observation's signal is adapted first: a refinement the linear rule leaves out),
    in at most 5 % of the sets."""
    rng = np.random.default_rng(7)
    A = rng.standard_normal((n, 2))
    G = rng.standard_normal((n, 3))
    G[:, 1] += 0.6 * G[:, 0]
    observations = tuple((f"o{k}", k + 1, (2 * k, 2 * k + 1)) for k in range(n // 2))
    design = linear_problem(A, G, observations=observations)
    fit = fit_model(design, ())
    step = ir.first_step(design, fit)
    Gbar = G[:, 1] - A @ np.linalg.lstsq(A, G[:, 1], rcond=None)[0]
    shift = math.sqrt(12.0) / np.linalg.norm(Gbar) * G[:, 1]
    noise = ir.whitened_noise(3, 0, sets, n)
    winners = ir.first_step_winners(step, ir.member_statistics(
        step, (noise + shift) @ step.projector))
    linear = [step.names[w] if w >= 0 else None for w in winners]
    engine = [diagnose(linear_problem(A, G, e + shift, observations)).steps[0].winner
              for e in noise]
    differ = [(a, b) for a, b in zip(linear, engine, strict=True) if a != b]
    assert all(a is not None and a.startswith("outlier:") and b is not None
               and not b.startswith("outlier:") for a, b in differ), differ
    assert len(differ) <= 0.05 * sets, differ
    assert 0.3 < linear.count("c1") / sets < 0.95  # the case tests something
    assert linear.count(None) + linear.count("c0") + linear.count("c2") > 0


def test_minimal_member_equals_the_engine_set_by_set():
    """A two-parameter candidate c2 whose columns contain c0's (c0's column and c0's plus a
    small other one): with c2 injected mostly along c0's column, c2 wins some sets with c0
    explaining its signal, and the engine names c0 instead (its minimal member). On 40 sets
    the vectorised rule gives the engine's first winner in every set, and the stand-in rule
    changed the winner in some of them."""
    rng = np.random.default_rng(3)
    n = 24
    A = rng.standard_normal((n, 2))
    G0, G1, other = rng.standard_normal((3, n))
    blocks = [G0[:, None], G1[:, None], np.column_stack([G0, G0 + 0.25 * other])]
    design = linear_problem(A, blocks)
    fit = fit_model(design, ())
    step = ir.first_step(design, fit)
    assert [(s.winner, s.inner) for s in step.stand_ins] == [(2, 0)]
    shift = ir.signal(design, fit, {"b2_0": 1.5, "b2_1": 1.5})
    noise = ir.whitened_noise(8, 0, 40, n)
    statistics = ir.member_statistics(step, (noise + shift) @ step.projector)
    winners = ir.first_step_winners(step, statistics)
    plain = ir.first_step_winners(replace(step, stand_ins=()), statistics)
    linear = [step.names[w] if w >= 0 else None for w in winners]
    engine = [diagnose(linear_problem(A, blocks, e + shift)).steps[0].winner for e in noise]
    assert linear == engine
    assert np.any(winners != plain) and "c2" in linear


def test_same_seed_same_numbers_whatever_the_batch():
    """Noise rows come from fixed blocks: any slice equals the same rows of a longer draw,
    and the PCI is identical with batches of 2500, 1000 and 333 sets."""
    whole = ir.whitened_noise(4, 0, 2600, 7)
    assert np.array_equal(ir.whitened_noise(4, 300, 1700, 7), whole[300:1700])
    assert not np.array_equal(ir.whitened_noise(5, 0, 10, 7), whole[:10])
    rng = np.random.default_rng(1)
    A, G = rng.standard_normal((25, 2)), rng.standard_normal((25, 2))
    problem = linear_problem(A, G)
    fit = fit_model(problem, ())
    step = ir.first_step(problem, fit)
    shift = ir.signal(problem, fit, {"b1_0": 1.0})
    values = {batch: ir.LinearRates(step, 2500, 9, batch).pci("c1", shift)
              for batch in (2500, 1000, 333)}
    assert len(set(values.values())) == 1, values
    assert 0.0 < values[2500] < 1.0


def test_log_tail_equals_scipy():
    """The closed forms and the incomplete gamma function give scipy's chi2 log tail (1e-10
    relative) for 1, 2, 3, 5 and 68 dof; far in the tail (T up to 1e5) they are finite and
    equal the engine's log tail (its asymptotic series) to 1e-6."""
    dof = np.array([1, 2, 3, 5, 68])
    T = np.array([[0.0, 0.5, 3.0, 20.0, 70.0], [1.0, 9.0, 40.0, 300.0, 900.0]])
    got = ir.log_chi2_sf_rows(T, dof)
    np.testing.assert_allclose(got, stats.chi2.logsf(T, dof), rtol=1e-10, atol=1e-300)
    far = np.full((1, 5), 1e5)
    tail = ir.log_chi2_sf_rows(far, dof)
    want = [log_chi2_sf(1e5, int(q)) for q in dof]
    assert np.all(np.isfinite(tail))
    np.testing.assert_allclose(tail[0], want, rtol=1e-6)


def test_holm_rejections_equal_the_engine():
    """Row by row, rejected exactly where the engine's weighted Holm adjusted p-value is below
    alpha (p-values spread around the thresholds so that some rows reject nothing, some one,
    some several)."""
    rng = np.random.default_rng(2)
    p = rng.uniform(0, 0.05, (400, 6)) ** rng.uniform(0.5, 3, (400, 6))
    w = np.array([1.0, 1.0, 1.0, 0.25, 0.25, 1.0])
    got = ir.holm_rejections(p, w, 0.01)
    want = np.array([weighted_holm(row, w) < 0.01 for row in p])
    np.testing.assert_array_equal(got, want)
    assert len(set(want.sum(axis=1))) >= 3
