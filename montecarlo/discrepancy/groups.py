"""Groups of observations (camera views, mirror pointings, targets): correlated misfit.

An additive check of a diagnosis whose data come in groups; it does not change what it names
(the out-of-sample check by group is :mod:`montecarlo.discrepancy.out_of_sample`).

- :func:`clustering`: do the final model's whitened residuals cluster by group? One-way
  analysis of variance (the random-effects model ``r = b_group + e``): the ratio of the
  between-group to the within-group mean square, F(k - 1, N - k) under independent noise, with
  each residual component (u and v, say) a cell of its own. Rejected, the stated sigma is too
  optimistic for points of one group: a correlated misfit, not missing physics. Residuals of a
  fit are not exactly independent (n - p of n degrees of freedom); with a few parameters per
  group against many points the F distribution holds closely. Group parameters (a view's pose)
  absorb what they can of a per-group offset: the test sees what they leave.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np
from numpy.typing import NDArray
from scipy import stats

from montecarlo.discrepancy.engine import Diagnosis
from montecarlo.discrepancy.problem import OUTLIER, Problem, is_outlier

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.intp]


def one_way_anova(values: FloatArray, cells: IntArray) -> dict[str, float]:
    """One-way analysis of variance of ``values`` in ``cells`` (integer labels).

    Returns F = MS_between / MS_within, its degrees of freedom, p-value (F distribution), and
    the random-effects estimate of the between-cell standard deviation
    ``sqrt(max(0, (MS_between - MS_within) / n0))``, ``n0`` the effective cell size, in the
    values' unit.
    """
    values = np.asarray(values, float)
    _, cells = np.unique(np.asarray(cells), return_inverse=True)
    k, n = int(cells.max()) + 1, values.size
    if k < 2 or n <= k:
        raise ValueError(f"{k} groups of {n} values: no between- and within-group variance")
    counts = np.bincount(cells, minlength=k).astype(float)
    means = np.bincount(cells, values, minlength=k) / counts
    ss_between = float(np.sum(counts * (means - values.mean()) ** 2))
    ss_within = float(np.sum((values - means[cells]) ** 2))
    ms_between, ms_within = ss_between / (k - 1), ss_within / (n - k)
    F = ms_between / ms_within
    n0 = (n - np.sum(counts ** 2) / n) / (k - 1)
    return {"F": F, "dof1": k - 1, "dof2": n - k, "p_value": float(stats.f.sf(F, k - 1, n - k)),
            "between_sd": float(np.sqrt(max(0.0, (ms_between - ms_within) / n0))),
            "within_sd": float(np.sqrt(ms_within))}


def label_groups(labels: Sequence[str]) -> dict[str, list[int]]:
    """Observations (0-based) of each label, in order of first appearance (a label seen once
    is a group of one: a target observed once can still be left out)."""
    out: dict[str, list[int]] = {}
    for i, label in enumerate(labels):
        out.setdefault(str(label), []).append(i)
    return out


def groups_of(labels: Sequence[str]) -> dict[str, list[int]] | None:
    """:func:`label_groups`, or None when the data have no groups to compare (fewer than two
    labels, or one observation per label)."""
    out = label_groups(labels)
    if len(out) < 2 or len(out) == len(labels):
        return None
    return out


def _flagged(d: Diagnosis) -> set[str]:
    return {e[len(OUTLIER):] for e in d.after.effects if is_outlier(e)}


def _rows(problem: Problem, members: Sequence[int], skip: set[str]) -> list[int]:
    """Whitened residual indices of these observations (0-based), flagged ones left out."""
    return [i for m in members for i in problem.observations[m][2]
            if problem.observations[m][0] not in skip]


MIN_SCATTER_CELL = 5
"""Fewest values per cell for the scatter test: with two values the deviations from the
median are equal by construction, and small cells make Brown-Forsythe's test degenerate."""


def clustering(d: Diagnosis, groups: Mapping[str, Sequence[int]], kind: str
               ) -> dict[str, Any]:
    """Do the final model's whitened residuals cluster by group? ``groups`` maps a group's
    name to its observations (0-based indices into ``d.problem.observations``), ``kind``
    names them (``"view"``); flagged observations are left out; cells are group x residual
    component. Two one-way analyses of variance, each at alpha / 2 (Bonferroni; the second
    only with :data:`MIN_SCATTER_CELL` values in every cell, the first then at alpha):

    - ``offset``: of the residuals (a per-group offset, the random-effects model);
    - ``scatter``: of their absolute deviations from the cell median (Brown-Forsythe's test of
      equal variances: some groups scatter more than the stated sigma allows).

    ``rms_sigma``: each group's residual RMS [sigma]."""
    skip = _flagged(d)
    values, cells, rms = [], [], {}
    for g, (name, members) in enumerate(groups.items()):
        r = []
        for m in members:
            oid, _, rows = d.problem.observations[m]
            if oid in skip:
                continue
            r += [float(d.after.residual[i]) for i in rows]
            cells += [(g, j) for j in range(len(rows))]
        values += r
        rms[name] = float(np.sqrt(np.mean(np.square(r)))) if r else float("nan")
    x = np.array(values)
    _, labels = np.unique(np.array(cells), axis=0, return_inverse=True)
    labels = labels.reshape(-1)
    offset = one_way_anova(x, labels)
    scatter = None
    if np.bincount(labels).min() >= MIN_SCATTER_CELL:
        medians = np.array([np.median(x[labels == c]) for c in range(labels.max() + 1)])
        scatter = one_way_anova(np.abs(x - medians[labels]), labels)
    tests = [t["p_value"] for t in (offset, scatter) if t is not None]
    return {"offset": offset, "scatter": scatter, "groups": len(groups), "kind": kind,
            "alpha": d.alpha, "rms_sigma": rms, "rejected": min(tests) < d.alpha / len(tests)}


def clustering_by(d: Diagnosis, kind: str, labels: Sequence[str]) -> dict[str, Any] | None:
    """:func:`clustering` with the groups given as each observation's label; None when the
    data have no groups to compare, or too few observations beside the flagged ones."""
    groups = groups_of(labels)
    if groups is None:
        return None
    try:
        return clustering(d, groups, kind)
    except ValueError:
        return None


def format_clustering(c: Mapping[str, Any]) -> str:
    """One line of :func:`clustering`."""
    o, s, kind = c["offset"], c["scatter"], c["kind"]
    rms = c["rms_sigma"].values()
    scatter = (f"scatter F({s['dof1']}, {s['dof2']}) = {s['F']:.3g}, p = {s['p_value']:.3g}"
               if s else f"scatter not tested (fewer than {MIN_SCATTER_CELL} values a cell)")
    stat = (f"offset F({o['dof1']}, {o['dof2']}) = {o['F']:.3g}, p = {o['p_value']:.3g}; "
            f"{scatter}; rms per {kind} {min(rms):.3g} to {max(rms):.3g} sigma")
    if c["rejected"]:
        return (f"residuals cluster by {kind}: {stat}; the stated sigma is too optimistic "
                f"for points of one {kind}: a correlated misfit, not missing physics")
    return f"residuals do not cluster by {kind} (alpha = {c['alpha']}): {stat}"
