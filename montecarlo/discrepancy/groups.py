"""Groups of observations (camera views, mirror pointings, targets): correlated misfit.

An additive check of a diagnosis whose data come in groups; it does not change what it names
(the out-of-sample check by group is :mod:`montecarlo.discrepancy.out_of_sample`).

- :func:`clustering`: do the final model's whitened residuals cluster by group? A shift of
  each group's points (one per residual component: u and v, say) added to the final model and
  tested by its partial F test, and a test of equal scatter. Rejected, the stated sigma is too
  optimistic for points of one group: a correlated misfit, not missing physics. Group
  parameters (a view's pose) absorb what they can of a per-group shift; the test sees what
  they leave, and needs no sigma.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np
from numpy.typing import NDArray
from scipy import stats

from montecarlo.discrepancy.engine import Diagnosis
from montecarlo.discrepancy.problem import OUTLIER, Problem, is_outlier
from montecarlo.lsq import LeastSquaresFit

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.intp]


def one_way_anova(values: FloatArray, cells: IntArray) -> dict[str, float]:
    """One-way analysis of variance of ``values`` in ``cells`` (integer labels).

    Returns F = MS_between / MS_within, its degrees of freedom and p-value (F distribution).
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
    return {"F": F, "dof1": k - 1, "dof2": n - k, "p_value": float(stats.f.sf(F, k - 1, n - k))}


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


MIN_SCATTER_CELL = 5
"""Fewest values per cell for the scatter test: with two values the deviations from the
median are equal by construction, and small cells make Brown-Forsythe's test degenerate."""


SHIFT_LEFT = 1e-3
"""Smallest share of a group shift's norm that the fitted model must leave for the shift test
to use it; a direction left less is taken as the model's. A camera view facing the target
leaves 3e-5 to 7e-5 of a shift of its corners in noisy data (its fitted pose tilts by the
noise, where the exact design leaves none): directions with no power to speak of, which
would only dilute the test; a tilted view leaves about 2e-2."""


def left_shifts(fit: LeastSquaresFit, cells: Sequence[Sequence[int]]
                ) -> tuple[FloatArray, FloatArray, FloatArray]:
    """What the fitted model leaves of a shift of each cell's residuals (``cells``: whitened
    residual indices): with ``X`` the cells' indicator columns and ``Q`` the model's column
    basis, ``B = Q' X`` and the eigenvalues ``w`` and eigenvectors ``V`` of the Gram matrix of
    ``(I - Q Q') X`` that it leaves more than :data:`SHIFT_LEFT` of (``len(w)``: the rank of
    what a shift test can see)."""
    q = fit.column_basis
    counts = np.array([len(rows) for rows in cells], float)
    B = np.column_stack([q[list(rows)].sum(axis=0) for rows in cells])
    w, V = np.linalg.eigh(np.diag(counts) - B.T @ B)
    keep = w > SHIFT_LEFT ** 2 * counts.max()
    return B, w[keep], V[:, keep]


def group_shift(fit: LeastSquaresFit, cells: Sequence[Sequence[int]]
                ) -> dict[str, Any] | None:
    """Partial F test of a shift of each cell's residuals added to the fitted model: ``T``
    the squared norm of the residual's projection on what the model leaves of the shifts
    (:func:`left_shifts`), ``F = (T / q) / ((|r|^2 - T) / (dof - q))`` on (q, dof - q)
    degrees of freedom, q that rank and dof the model's. None when the model takes up every
    shift. Without a model but a common mean this is the one-way analysis of variance of the
    cells."""
    B, w, V = left_shifts(fit, cells)
    r = fit.residual
    rank, dof = w.size, int(fit.dof)
    if rank == 0 or dof <= rank:
        return None
    b = np.array([r[list(rows)].sum() for rows in cells]) - B.T @ (fit.column_basis.T @ r)
    z = (V.T @ b) / np.sqrt(w)
    T = float(z @ z)
    F = (T / rank) / ((float(r @ r) - T) / (dof - rank))
    return {"F": F, "dof1": rank, "dof2": dof - rank,
            "p_value": float(stats.f.sf(F, rank, dof - rank))}


def group_cells(problem: Problem, groups: Mapping[str, Sequence[int]], skip: set[str]
                ) -> dict[tuple[int, int], list[int]]:
    """Whitened residual indices of each (group number, residual component) cell; ``groups``
    maps a group's name to its observations (0-based), ``skip`` the ids left out."""
    cells: dict[tuple[int, int], list[int]] = {}
    for g, members in enumerate(groups.values()):
        for m in members:
            oid, _, rows = problem.observations[m]
            if oid not in skip:
                for j, i in enumerate(rows):
                    cells.setdefault((g, j), []).append(i)
    return cells


def clustering(d: Diagnosis, groups: Mapping[str, Sequence[int]], kind: str
               ) -> dict[str, Any]:
    """Do the final model's whitened residuals cluster by group? ``groups`` maps a group's
    name to its observations (0-based indices into ``d.problem.observations``), ``kind``
    names them (``"view"``); flagged observations are left out; cells are group x residual
    component. Two tests, each at alpha / 2 (Bonferroni; a test that cannot be made leaves
    the other at alpha):

    - ``offset``: a shift of each cell added to the final model (:func:`group_shift`);
    - ``scatter``: one-way analysis of variance of the residuals' absolute deviations from
      their cell's median (Brown-Forsythe's test of equal variances: some groups scatter more
      than the stated sigma allows), with :data:`MIN_SCATTER_CELL` values in every cell.

    ``rms_sigma``: each group's residual RMS [sigma]."""
    cells = group_cells(d.problem, groups, _flagged(d))
    if len(cells) < 2:
        raise ValueError(f"{len(cells)} cells of residuals: no groups to compare")
    sizes = [len(c) for c in cells.values()]
    x = d.after.residual[np.concatenate([np.asarray(c, np.intp) for c in cells.values()])]
    labels = np.repeat(np.arange(len(cells)), sizes)
    group = np.repeat([g for g, _ in cells], sizes)
    rms = {name: float(np.sqrt(np.mean(np.square(x[group == g])))) if np.any(group == g)
           else float("nan") for g, name in enumerate(groups)}
    offset = group_shift(d.after, list(cells.values()))
    scatter = None
    if np.bincount(labels).min() >= MIN_SCATTER_CELL:
        medians = np.array([np.median(x[labels == c]) for c in range(labels.max() + 1)])
        scatter = one_way_anova(np.abs(x - medians[labels]), labels)
    tests = [t["p_value"] for t in (offset, scatter) if t is not None]
    return {"offset": offset, "scatter": scatter, "groups": len(groups), "kind": kind,
            "alpha": d.alpha, "rms_sigma": rms,
            "rejected": bool(tests) and min(tests) < d.alpha / len(tests)}


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
    offset = (f"offset F({o['dof1']}, {o['dof2']}) = {o['F']:.3g}, p = {o['p_value']:.3g}"
              if o else f"offset not tested (each {kind}'s own parameters take up its shift)")
    stat = f"{offset}; {scatter}; rms per {kind} {min(rms):.3g} to {max(rms):.3g} sigma"
    if c["rejected"]:
        return (f"residuals cluster by {kind}: {stat}; the stated sigma is too optimistic "
                f"for points of one {kind}: a correlated misfit, not missing physics")
    return f"residuals do not cluster by {kind} (alpha = {c['alpha']}): {stat}"
