"""Groups of observations (camera views, mirror pointings, targets): correlated misfit and
out-of-sample evidence.

Two additive checks of a diagnosis whose data come in groups; neither changes what it names.

- :func:`clustering`: do the final model's whitened residuals cluster by group? One-way
  analysis of variance (the random-effects model ``r = b_group + e``): the ratio of the
  between-group to the within-group mean square, F(k - 1, N - k) under independent noise, with
  each residual component (u and v, say) a cell of its own. Rejected, the stated sigma is too
  optimistic for points of one group: a correlated misfit, not missing physics. Residuals of a
  fit are not exactly independent (n - p of n degrees of freedom); with a few parameters per
  group against many points the F distribution holds closely. Group parameters (a view's pose)
  absorb what they can of a per-group offset: the test sees what they leave.
- :func:`leave_one_group_out`: for each group, the final model (and the final model without
  each named effect) refitted by :func:`~montecarlo.discrepancy.fit.fit_model` on all other
  groups, then only the left-out group's own parameters (those no other group's residuals
  depend on, e.g. its pose) fitted to it with everything else held: the prediction RMS of the
  left-out groups, whitened and in the data's unit. An effect whose removal does not worsen
  the out-of-sample RMS "does not predict".
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np
from numpy.typing import NDArray
from scipy import stats

from montecarlo.discrepancy.engine import Diagnosis
from montecarlo.discrepancy.fit import FitError, fit_model, jacobian
from montecarlo.discrepancy.problem import OUTLIER, Effect, Problem, is_outlier
from montecarlo.discrepancy.view import SystemView

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


def groups_of(labels: Sequence[str]) -> dict[str, list[int]] | None:
    """Observations (0-based) of each label, in order of first appearance; None when the data
    have no groups to compare (fewer than two labels, or one observation per label)."""
    out: dict[str, list[int]] = {}
    for i, label in enumerate(labels):
        out.setdefault(str(label), []).append(i)
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


def _held(problem: Problem, fixed: Mapping[str, float], base: Effect,
          rows: Sequence[int]) -> Problem:
    """``problem`` restricted to whitened ``rows`` with the ``fixed`` parameters held and
    ``base`` as its base model."""
    full = problem.residuals
    index = np.asarray(rows)

    def residuals(values: Mapping[str, FloatArray]) -> FloatArray:
        arrays = [np.asarray(v) for v in values.values()]
        batch = max((a.shape[0] for a in arrays if a.ndim), default=0)
        held: dict[str, Any] = {k: (np.full((batch, 1), v) if batch else v)
                                for k, v in fixed.items() if k not in values}
        return np.asarray(full({**held, **values}), dtype=np.float64)[..., index]

    return Problem(problem.system, base, problem.candidates, residuals,
                   {k: v for k, v in problem.start.items() if k in base.parameters},
                   requires=problem.requires)


def _sub_effect(effect: Effect, names: Sequence[str], label: str) -> Effect:
    keep = [effect.parameters.index(n) for n in names]
    return Effect(label, tuple(names), tuple(effect.bounds[i] for i in keep),
                  tuple(effect.steps[i] for i in keep))


def _predict(d: Diagnosis, view: SystemView, effects: Sequence[str], members: Sequence[int],
             others: Sequence[int], local: Sequence[str], skip: set[str]
             ) -> tuple[FloatArray, FloatArray]:
    """Whitened and raw (view unit) residuals of the left-out observations ``members``
    predicted by ``effects`` fitted on ``others``, the left-out group's ``local`` parameters
    fitted to it alone."""
    problem, after = d.problem, d.after.params
    base = problem.base
    shared = [p for p in base.parameters if p not in local]
    train = _held(problem, {p: after[p] for p in local}, _sub_effect(base, shared, base.name),
                  _rows(problem, others, skip))
    fit = fit_model(train, effects, {k: v for k, v in after.items()
                                     if not is_outlier(k) and k not in local})
    params = dict(fit.params)
    test_rows = _rows(problem, members, skip)
    if local:
        test = _held(problem, params, _sub_effect(base, local, "local"), test_rows)
        params.update(fit_model(test, [], {p: after[p] for p in local}).params)
    given: dict[str, Any] = params
    r = np.asarray(problem.residuals(given), dtype=np.float64)[test_rows]
    kept = [m for m in members if problem.observations[m][0] not in skip]
    raw = view.raw_residuals(params)[kept] / view.rms_scale
    return r, raw


def _local(d: Diagnosis, A: FloatArray, members: Sequence[int]) -> list[str]:
    """Base parameters that no residual outside the group ``members`` depends on (``A``: the
    base parameters' Jacobian)."""
    names = d.problem.base.parameters
    inside = np.zeros(A.shape[0], bool)
    inside[_rows(d.problem, members, set())] = True
    return [n for j, n in enumerate(names) if not np.any(A[~inside, j])]


def _rms(x: Sequence[FloatArray]) -> float:
    return float(np.sqrt(np.mean(np.concatenate([np.ravel(v) for v in x]) ** 2)))


def leave_one_group_out(d: Diagnosis, view: SystemView, groups: Mapping[str, Sequence[int]],
                        kind: str) -> dict[str, Any]:
    """Prediction RMS of each left-out group under the final model and under the final model
    without each named effect (see the module docstring); flagged observations are left out
    of fits and predictions. ``verdict`` of an effect: ``"predicts"`` when the pooled whitened
    prediction RMS without it is larger than with it."""
    skip = _flagged(d)
    final = [e for e in d.after.effects[1:] if not is_outlier(e)]
    models = {"final model": final, **{f"without {e}": [x for x in final if x != e]
                                       for e in final}}
    everyone = [m for ms in groups.values() for m in ms]
    A = jacobian(d.problem, {k: v for k, v in d.after.params.items() if not is_outlier(k)},
                 d.problem.base.parameters)
    locals_ = {g: _local(d, A, ms) for g, ms in groups.items()}
    out: dict[str, Any] = {"kind": kind, "groups": list(groups), "rms_unit": view.rms_unit,
                           "models": {}}
    for label, effects in models.items():
        whitened, raw, per_group, failed = [], [], {}, None
        for g, ms in groups.items():
            others = [m for m in everyone if m not in set(ms)]
            try:
                r, x = _predict(d, view, effects, ms, others, locals_[g], skip)
            except FitError as exc:
                failed = f"{kind} {g} left out: {exc}"
                break
            whitened.append(r)
            raw.append(x)
            per_group[g] = {"rms_sigma": _rms([r]), "rms": _rms([x])}
        out["models"][label] = ({"effects": effects, "failed": failed} if failed else
                                {"effects": effects, "rms_sigma": _rms(whitened),
                                 "rms": _rms(raw), "per_group": per_group})
    best = out["models"]["final model"]
    for e in final:
        m = out["models"][f"without {e}"]
        if "rms_sigma" in best and "rms_sigma" in m:
            m["verdict"] = "predicts" if m["rms_sigma"] > best["rms_sigma"] else \
                "does not predict"
    return out


def format_leave_one_out(loo: Mapping[str, Any], significance: Sequence[Mapping[str, Any]]
                         = ()) -> str:
    """The table of :func:`leave_one_group_out`, the in-sample label beside each effect."""
    kind, unit = loo["kind"], loo["rms_unit"]
    in_sample = {e["name"]: e["label"] for e in significance}
    lines = [f"out-of-sample evidence: leave one {kind} out (refit on the others, predict it); "
             f"prediction rms pooled over the {len(loo['groups'])} {kind}s",
             f"  {'model':<28} {'rms [sigma]':>12} {'rms [' + unit + ']':>12}  "
             "out of sample / in sample"]
    for label, m in loo["models"].items():
        name = label.removeprefix("without ")
        if m.get("failed"):
            lines.append(f"  {label:<28} cannot refit ({m['failed']})")
            continue
        verdict = m.get("verdict", "")
        if verdict and name in in_sample:
            verdict += f" / {in_sample[name]}"
        lines.append(f"  {label:<28} {m['rms_sigma']:12.4g} {m['rms']:12.4g}  {verdict}")
    return "\n".join(lines)
