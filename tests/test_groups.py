"""Grouped observations: clustering of residuals by group and leave-one-group-out prediction,
against scipy / statsmodels and a direct numpy least-squares computation."""

from __future__ import annotations

import json
import re
from dataclasses import replace
from pathlib import Path
from types import SimpleNamespace
from typing import Any

import numpy as np
import pandas as pd
import pytest
from scipy import stats
from statsmodels.formula.api import ols
from statsmodels.stats.anova import anova_lm

from montecarlo.cli import main
from montecarlo.discrepancy.engine import diagnose
from montecarlo.discrepancy.fit import fit_model
from montecarlo.discrepancy.groups import (
    clustering,
    format_clustering,
    groups_of,
    one_way_anova,
)
from montecarlo.discrepancy.out_of_sample import format_leave_one_out, leave_one_group_out
from montecarlo.discrepancy.problem import Effect, Problem
from montecarlo.discrepancy.significance import practical_significance


def test_one_way_anova_matches_scipy_and_statsmodels() -> None:
    rng = np.random.default_rng(1)
    cells = np.repeat(np.arange(4), [5, 8, 6, 11])
    x = rng.normal(size=cells.size) + 0.4 * cells
    ours = one_way_anova(x, cells)
    ref = stats.f_oneway(*(x[cells == c] for c in range(4)))
    table = anova_lm(ols("x ~ C(g)", pd.DataFrame({"x": x, "g": cells})).fit())
    assert ours["F"] == pytest.approx(ref.statistic, rel=1e-12)
    assert ours["p_value"] == pytest.approx(ref.pvalue, rel=1e-9)
    assert ours["F"] == pytest.approx(table["F"].iloc[0], rel=1e-9)
    assert (ours["dof1"], ours["dof2"]) == (3, cells.size - 4)


def _stub(residual: np.ndarray, n_groups: int, per: int) -> tuple[Any, dict[str, list[int]]]:
    """A diagnosis of ``n_groups`` groups of ``per`` observations of two components each."""
    obs = tuple((f"g{i // per}/{i}", i + 1, (2 * i, 2 * i + 1)) for i in range(n_groups * per))
    n = residual.size
    d = SimpleNamespace(problem=SimpleNamespace(observations=obs), alpha=0.05,
                        after=SimpleNamespace(residual=residual - residual.mean(), effects=(
                            "base",), column_basis=np.full((n, 1), 1 / np.sqrt(n)), dof=n - 1))
    return d, {f"g{g}": list(range(g * per, (g + 1) * per)) for g in range(n_groups)}


def test_clustering_cells_and_scatter_test_match_scipy() -> None:
    rng = np.random.default_rng(2)
    r = rng.normal(size=2 * 3 * 7)
    d, groups = _stub(r, 3, 7)
    c = clustering(d, groups, "view")
    u, v = r[0::2].reshape(3, 7), r[1::2].reshape(3, 7)
    cells = [*u, *v]
    assert c["offset"]["F"] == pytest.approx(stats.f_oneway(*cells).statistic, rel=1e-12)
    assert c["scatter"]["p_value"] == pytest.approx(
        stats.levene(*cells, center="median").pvalue, rel=1e-9)
    assert c["rejected"] == (min(c["offset"]["p_value"], c["scatter"]["p_value"]) < 0.025)
    assert ("do not cluster" in format_clustering(c)) == (not c["rejected"])


@pytest.mark.parametrize("offset", [0.0, 1.0])
def test_clustering_rejection_rate(offset: float) -> None:
    """Null: the rate at alpha = 0.05 within its binomial 99.9 % band (two-sided); a per-group
    offset of one sigma in 6 groups of 10 points: rejected nearly always."""
    rng = np.random.default_rng(3)
    sets, n_groups, per = 600, 6, 10
    rejected = 0
    for _ in range(sets):
        r = rng.normal(size=(n_groups, per, 2))
        r += offset * rng.normal(size=(n_groups, 1, 2))
        d, groups = _stub(r.reshape(-1), n_groups, per)
        rejected += clustering(d, groups, "view")["rejected"]
    rate = rejected / sets
    if offset == 0.0:
        low, high = stats.binom.ppf([0.0005, 0.9995], sets, 0.05) / sets
        assert low <= rate <= high
    else:
        assert rate >= 0.9


def _toy(own_intercepts: bool = True) -> tuple[Problem, np.ndarray, np.ndarray, np.ndarray]:
    """y = a_g + b x + c x^2 + noise in 4 groups: intercepts local (or one shared, then
    fitted as ``a0``), b shared, c a candidate."""
    rng = np.random.default_rng(4)
    g = np.repeat(np.arange(4), 12)
    x = rng.uniform(-1, 1, g.size)
    y = np.array([1.0, -2.0, 0.5, 3.0])[g] + 0.7 * x + 0.3 * x ** 2 + 0.1 * rng.normal(size=x.size)
    sigma = 0.1
    intercepts_of = [f"a{k}" for k in range(4)]

    def residuals(values: Any) -> np.ndarray:
        given = [np.asarray(values.get(n, 0.0), float) for n in (*intercepts_of, "b", "c")]
        batched = any(v.ndim for v in given)
        cols = np.broadcast_arrays(*(v.reshape(-1, 1) for v in given))
        intercepts = np.hstack(cols[:4])[:, g] if own_intercepts else cols[0]
        pred = intercepts + cols[4] * x + cols[5] * x ** 2
        r = (y - pred) / sigma
        return r if batched else r[0]

    names = intercepts_of if own_intercepts else intercepts_of[:1]
    base = Effect("line", (*names, "b"), ((-np.inf, np.inf),) * (len(names) + 1),
                  (1e-4,) * (len(names) + 1))
    quad = Effect("quad", ("c",), ((-10.0, 10.0),), (1e-4,))
    obs = tuple((f"{g[i]}/{i}", i + 1, (i,)) for i in range(x.size))
    return Problem("toy", base, (quad,), residuals, dict.fromkeys((*names, "b"), 0.0),
                   observations=obs), g, x, y


@pytest.mark.parametrize("own_intercepts", [False, True])
def test_the_shift_test_is_statsmodels_partial_f_test(own_intercepts: bool) -> None:
    """A shift per group added to the final model: statsmodels' F test of ``y ~ x + x^2``
    against ``y ~ x + x^2 + C(g)``, the same data. With an intercept of its own per group the
    model takes up every shift: no offset test, and the scatter test carries alpha."""
    problem, g, x, y = _toy(own_intercepts)
    d = SimpleNamespace(problem=problem, after=fit_model(problem, ["quad"]), alpha=0.01)
    c = clustering(d, {str(k): np.flatnonzero(g == k).tolist() for k in range(4)}, "group")
    if own_intercepts:
        assert c["offset"] is None and "offset not tested" in format_clustering(c)
        assert c["rejected"] == (c["scatter"]["p_value"] < 0.01)
        return
    frame = pd.DataFrame({"y": y, "x": x, "g": g})
    ref = anova_lm(ols("y ~ x + I(x**2)", frame).fit(), ols("y ~ x + I(x**2) + C(g)",
                                                             frame).fit())
    assert c["offset"]["F"] == pytest.approx(ref["F"].iloc[1], rel=1e-6)
    assert c["offset"]["p_value"] == pytest.approx(ref["Pr(>F)"].iloc[1], rel=1e-6)
    assert (c["offset"]["dof1"], c["offset"]["dof2"]) == (3, x.size - 6)
    assert c["offset"]["p_value"] < 1e-6  # the groups' intercepts differ by tens of sigma


def test_leave_one_group_out_matches_lstsq() -> None:
    problem, g, x, y = _toy()
    after = fit_model(problem, ["quad"])
    d = SimpleNamespace(problem=problem, after=after, alpha=0.01)

    def raw(p: dict[str, float]) -> np.ndarray:
        a = np.array([p[f"a{k}"] for k in range(4)])[g]
        return (y - a - p["b"] * x - p.get("c", 0.0) * x ** 2)[:, None]

    view = SimpleNamespace(rms_unit="m", rms_scale=1.0, raw_residuals=raw)
    groups = {str(k): np.flatnonzero(g == k).tolist() for k in range(4)}
    loo = leave_one_group_out(d, view, groups, "group")  # type: ignore[arg-type]
    for label, quadratic in (("final model", True), ("without quad", False)):
        errors = []
        for k in range(4):
            train = g != k
            cols = [(g[train] == j).astype(float) for j in range(4) if j != k] + [x[train]]
            cols += [x[train] ** 2] if quadratic else []
            coef = np.linalg.lstsq(np.column_stack(cols), y[train], rcond=None)[0]
            slope, curve = coef[3], (coef[4] if quadratic else 0.0)
            rest = y[~train] - slope * x[~train] - curve * x[~train] ** 2
            e = rest - rest.mean()  # the left-out group's own intercept fitted to it alone
            errors.append(e)
            got = loo["models"][label]["per_group"][str(k)]
            assert got["rms"] == pytest.approx(np.sqrt(np.mean(e ** 2)), rel=1e-6)
            assert got["rms_sigma"] == pytest.approx(np.sqrt(np.mean(e ** 2)) / 0.1, rel=1e-6)
        pooled = np.sqrt(np.mean(np.concatenate(errors) ** 2))
        assert loo["models"][label]["rms"] == pytest.approx(pooled, rel=1e-6)
    # the rule: a paired t test of the per-group mean squares (scipy's), at the alpha of 0.01
    per = {label: [loo["models"][label]["per_group"][str(k)]["rms_sigma"] ** 2
                   for k in range(4)] for label in ("final model", "without quad")}
    ref = stats.ttest_rel(per["without quad"], per["final model"], alternative="greater")
    test = loo["models"]["without quad"]["test"]
    assert (test["t"], test["p_value"]) == pytest.approx((ref.statistic, ref.pvalue))
    assert loo["models"]["without quad"]["verdict"] == (
        "predicts" if ref.pvalue < 0.01 else "does not predict")
    assert "without quad" in format_leave_one_out(loo)


def test_small_cells_skip_the_scatter_test_and_singletons_have_no_groups() -> None:
    """Two values a cell: deviations from the median are equal, so no scatter test; the
    offset test then carries the whole alpha."""
    rng = np.random.default_rng(5)
    d, groups = _stub(rng.normal(size=2 * 4 * 2), 4, 2)
    c = clustering(d, groups, "mirror")
    assert c["scatter"] is None
    assert c["rejected"] == (c["offset"]["p_value"] < 0.05)
    assert "scatter not tested" in format_clustering(c)
    assert groups_of(["A", "B", "C"]) is None
    assert groups_of(["A", "B", "A"]) == {"A": [0, 2], "B": [1]}


def test_collimation_cli_reports_clustering_by_mirror(tmp_path, capsys) -> None:
    """Each mirror read in both sets: two observations a mirror, the line is printed and the
    JSON carries it; the shipped example (one observation a mirror) has no groups."""
    shipped = Path("results/examples/discrepancy_collimation/data.csv")
    data = tmp_path / "twice.csv"
    data.write_text(re.sub(r"^P(\d),pitch", r"A\1,pitch", shipped.read_text(), flags=re.M))
    out = tmp_path / "d.json"
    assert main(["diagnose", "collimation", str(data), "--angle-sigma-arcsec", "5",
                 "--readings", "absolute", "--json", str(out)]) == 0
    c = json.loads(out.read_text())["clustering"]
    # 7 mirrors x 2 components; the named axis misalignment shifts every mirror alike in
    # each component, so the model takes up two of the 14 cells' shifts
    assert (c["kind"], c["groups"], c["offset"]["dof1"]) == ("mirror", 7, 12)
    capsys.readouterr()
    assert main(["diagnose", "collimation", str(shipped), "--angle-sigma-arcsec", "5",
                 "--readings", "absolute"]) == 0
    assert "cluster" not in capsys.readouterr().out


def test_practical_significance_takes_the_diagnosis_refit_and_it_is_ordinary_least_squares(
        ) -> None:
    """The refit without the named quadratic term that the diagnosis keeps is numpy's least
    squares of ``y ~ C(g) + x``; practical significance gives the same with or without it."""
    problem, g, x, y = _toy()
    d = diagnose(problem, 0.01)
    assert d.named == ["quad"] and set(d.without) == {"quad"}
    design = np.column_stack([(g == k).astype(float) for k in range(4)] + [x])
    coef = np.linalg.lstsq(design, y, rcond=None)[0]
    got = d.without["quad"].params
    assert [got[n] for n in ("a0", "a1", "a2", "a3", "b")] == pytest.approx(coef, rel=1e-6)

    def raw(p: dict[str, float]) -> np.ndarray:
        a = np.array([p[f"a{k}"] for k in range(4)])[g]
        return y - a - p["b"] * x - p.get("c", 0.0) * x ** 2

    view = SimpleNamespace(rms_unit="m", rms_scale=1.0, raw_residuals=raw,
                           display_unit=lambda name: ("", 1.0))
    kept = practical_significance(d, view)  # type: ignore[arg-type]
    assert kept == practical_significance(replace(d, without={}), view)  # type: ignore[arg-type]
    assert kept[0]["rms_without"] == pytest.approx(np.sqrt(np.mean((y - design @ coef) ** 2)))
