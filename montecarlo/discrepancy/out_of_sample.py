"""Out-of-sample evidence for each named effect: leave one group out, predict it.

For each group of observations (a camera view, a mirror, a target), the final model, and the
final model without each named effect, is refitted by
:func:`~montecarlo.discrepancy.fit.fit_model` on every other group; then only the left-out
group's own parameters (those no other group's residual depends on, found from the Jacobian:
a camera view's pose) are fitted to the left-out group alone, everything else held at the
values fitted on the others. Its residuals are the prediction errors. For a camera this is the
standard cross-validation of a calibration: the intrinsics and distortion come from the other
views, the left-out view's pose from that view itself (a pose is not predictable from other
views).

**Rule.** Per left-out group ``g`` the mean square whitened prediction error ``MS_g`` [σ²] of
each model; for a named effect ``E`` the increase ``d_g = MS_g(without E) - MS_g(final)``.
``E`` *predicts* when the one-sided paired t test of ``mean(d) > 0`` over the ``K`` groups
(``t = mean(d) / (sd(d) / sqrt(K))``, Student's t on ``K - 1`` degrees of freedom) rejects at
the diagnosis's alpha; otherwise it *does not predict*. Groups are the unit (their
prediction errors are independent given the training fits; points of one view share its
fitted pose). An effect the data do not carry costs out-of-sample accuracy in expectation
(it is fitted to noise), so its ``d_g`` centre at or below zero. A group whose observations are
all flagged is not a group here; with fewer than :data:`MIN_GROUPS` groups left, or no named
effect, there is no table (:func:`no_table` says why).
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

RULE = ("an effect predicts when leaving it out raises the left-out {kind}s' mean square "
        "prediction error: one-sided paired t test over the {k} {kind}s (t on {dof} dof) at "
        "alpha = {alpha:g}")
FINAL = "final model"
MIN_GROUPS = 3
"""Fewest groups for a table: the paired t test then has at least 2 degrees of freedom."""


def _flagged(d: Diagnosis) -> set[str]:
    return {e[len(OUTLIER):] for e in d.after.effects if is_outlier(e)}


def _rows(problem: Problem, members: Sequence[int], skip: set[str]) -> list[int]:
    """Whitened residual indices of these observations (0-based), flagged ones left out."""
    return [i for m in members for i in problem.observations[m][2]
            if problem.observations[m][0] not in skip]


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


def _named(d: Diagnosis) -> list[str]:
    return [e for e in d.after.effects[1:] if not is_outlier(e)]


def _usable(d: Diagnosis, groups: Mapping[str, Sequence[int]]) -> dict[str, Sequence[int]]:
    """The groups with an observation not flagged."""
    skip = _flagged(d)
    return {g: ms for g, ms in groups.items() if _rows(d.problem, ms, skip)}


def no_table(d: Diagnosis, groups: Mapping[str, Sequence[int]], kind: str) -> str | None:
    """Why :func:`leave_one_group_out` gives no table for these groups (None: it does)."""
    usable = len(_usable(d, groups))
    if usable < MIN_GROUPS:
        flagged = " not flagged" if usable < len(groups) else ""
        return (f"leave one {kind} out: no table: {usable} {kind}s{flagged}, at least "
                f"{MIN_GROUPS} needed (the paired t test over {kind}s needs 2 degrees of "
                "freedom)")
    if not _named(d):
        return (f"leave one {kind} out: no table: the diagnosis named no effect, so none is "
                "left out")
    return None


def prediction_test(increase: Sequence[float], alpha: float) -> dict[str, Any]:
    """The rule of the module docstring on the per-group increases ``d_g`` of the mean square
    prediction error [σ²]: mean, standard deviation, how many groups are predicted worse
    without the effect, t, degrees of freedom, one-sided p-value and the verdict."""
    d = np.asarray(increase, float)
    k = d.size
    mean = float(d.mean())
    sd = float(d.std(ddof=1)) if k > 1 else float("nan")
    if k < 2:
        t, p = float("nan"), float("nan")
    elif sd > 0:
        t = mean / (sd / np.sqrt(k))
        p = float(stats.t.sf(t, k - 1))
    else:  # every group changed by the same amount
        t = float(np.sign(mean)) * np.inf if mean else 0.0
        p = 0.0 if mean > 0 else 1.0
    predicts = bool(p < alpha)
    return {"mean_increase_sigma2": mean, "sd_sigma2": sd, "worse_without": int(np.sum(d > 0)),
            "groups": k, "t": float(t), "dof": k - 1,
            "p_value": p, "alpha": alpha,
            "verdict": "predicts" if predicts else "does not predict"}


def leave_one_group_out(d: Diagnosis, view: SystemView, groups: Mapping[str, Sequence[int]],
                        kind: str, held_out: str = "") -> dict[str, Any]:
    """Prediction RMS of each left-out group under the final model and under the final model
    without each named effect, and each effect's verdict by :func:`prediction_test` (see the
    module docstring); flagged observations are left out of fits and predictions.
    ``held_out`` says in words how the left-out group is predicted (for the reports)."""
    skip = _flagged(d)
    groups = _usable(d, groups)
    final = _named(d)
    models = {FINAL: final, **{f"without {e}": [x for x in final if x != e] for e in final}}
    everyone = [m for ms in groups.values() for m in ms]
    A = jacobian(d.problem, {k: v for k, v in d.after.params.items() if not is_outlier(k)},
                 d.problem.base.parameters)
    locals_ = {g: _local(d, A, ms) for g, ms in groups.items()}
    out: dict[str, Any] = {
        "kind": kind, "groups": list(groups), "rms_unit": view.rms_unit,
        "held_out": held_out or (
            f"the left-out {kind}'s own parameters (those no other {kind}'s residual depends "
            "on) fitted to it alone, everything else held at the values fitted on the others"
            if any(locals_.values()) else f"every parameter fitted on the other {kind}s, none "
            f"being the left-out {kind}'s own"),
        "own_parameters": locals_,
        "rule": RULE.format(kind=kind, k=len(groups), dof=len(groups) - 1, alpha=d.alpha),
        "alpha": d.alpha, "models": {}}
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
            per_group[g] = {"rms_sigma": _rms([r]), "rms": _rms([x]),
                            "mean_square_sigma2": float(np.mean(np.square(r)))}
        out["models"][label] = ({"effects": effects, "failed": failed} if failed else
                                {"effects": effects, "rms_sigma": _rms(whitened),
                                 "rms": _rms(raw), "per_group": per_group})
    best = out["models"][FINAL]
    for e in final:
        m = out["models"][f"without {e}"]
        if "per_group" in best and "per_group" in m:
            m["test"] = prediction_test(
                [m["per_group"][g]["mean_square_sigma2"]
                 - best["per_group"][g]["mean_square_sigma2"] for g in groups], d.alpha)
            m["verdict"] = m["test"]["verdict"]
    return out


def _columns(loo: Mapping[str, Any]) -> list[str]:
    return [label for label, m in loo["models"].items() if "per_group" in m]


def format_leave_one_out(loo: Mapping[str, Any], significance: Sequence[Mapping[str, Any]]
                         = ()) -> str:
    """The text table of :func:`leave_one_group_out`: the prediction RMS of each left-out
    group under each model, then each effect's test and verdict beside its in-sample label
    (``significance``: :func:`~montecarlo.discrepancy.significance.practical_significance`)."""
    kind, unit, models = loo["kind"], loo["rms_unit"], loo["models"]
    columns = _columns(loo)
    width = max(12, *(len(c) for c in columns)) + 2
    names = [str(g) for g in loo["groups"]]
    first = max(len(f"all {kind}s [sigma]"), *(len(g) for g in names)) + 2
    lines = [f"out-of-sample evidence: leave one {kind} out, refit on the others, predict it "
             f"({loo['held_out']})",
             f"  prediction rms [{unit}] of the left-out {kind}",
             "  " + f"{kind}".ljust(first) + "".join(c.rjust(width) for c in columns)]
    for g in names:
        lines.append("  " + g.ljust(first) + "".join(
            f"{models[c]['per_group'][g]['rms']:{width}.4g}" for c in columns))
    lines.append("  " + f"all {kind}s".ljust(first)
                 + "".join(f"{models[c]['rms']:{width}.4g}" for c in columns))
    lines.append("  " + f"all {kind}s [sigma]".ljust(first)
                 + "".join(f"{models[c]['rms_sigma']:{width}.4g}" for c in columns))
    for label, m in models.items():
        if m.get("failed"):
            lines.append(f"  {label}: cannot refit ({m['failed']})")
    in_sample = {e["name"]: e["label"] for e in significance}
    tests = [(label.removeprefix("without "), m["test"]) for label, m in models.items()
             if "test" in m]
    if tests:
        lines.append(f"  rule: {loo['rule']}")
        lines.append(f"  {'effect':<18} {'mean increase [sigma^2]':>24} {'worse without':>14} "
                     f"{'t':>8} {'p':>9}  out of sample / in sample")
        for name, t in tests:
            label = t["verdict"] + (f" / {in_sample[name]}" if name in in_sample else "")
            worse = f"{t['worse_without']} of {t['groups']}"
            lines.append(f"  {name:<18} {t['mean_increase_sigma2']:24.4g} {worse:>14} "
                         f"{t['t']:8.3g} {t['p_value']:9.3g}  {label}")
    return "\n".join(lines)


def markdown_leave_one_out(loo: Mapping[str, Any], significance: Sequence[Mapping[str, Any]]
                           = ()) -> list[str]:
    """The same tables as :func:`format_leave_one_out`, as a Markdown section (report.md and
    report.html)."""
    kind, unit, models = loo["kind"], loo["rms_unit"], loo["models"]
    columns = _columns(loo)
    md = [f"## Out-of-sample evidence: leave one {kind} out", "",
          f"Each {kind} in turn is left out, the model refitted on the others, and the left-out "
          f"{kind} predicted: {loo['held_out']}. Prediction RMS [{unit}] of the left-out "
          f"{kind}:", "",
          f"| {kind} | " + " | ".join(columns) + " |", "|---" * (len(columns) + 1) + "|"]
    for g in loo["groups"]:
        md.append(f"| {g} | " + " | ".join(f"{models[c]['per_group'][str(g)]['rms']:.4g}"
                                           for c in columns) + " |")
    md.append(f"| all {kind}s | " + " | ".join(f"{models[c]['rms']:.4g}" for c in columns)
              + " |")
    md.append(f"| all {kind}s [σ] | " + " | ".join(f"{models[c]['rms_sigma']:.4g}"
                                                   for c in columns) + " |")
    md.append("")
    failed = [f"{label}: cannot refit ({m['failed']})" for label, m in models.items()
              if m.get("failed")]
    md += [*(f"- {f}" for f in failed), *([""] if failed else [])]
    in_sample = {e["name"]: e["label"] for e in significance}
    tests = [(label.removeprefix("without "), m["test"]) for label, m in models.items()
             if "test" in m]
    if tests:
        md += [f"Rule: {loo['rule']}.", "",
               f"| effect | mean increase of the mean square [σ²] | {kind}s predicted worse "
               "without it | t | p | out of sample | in sample |",
               "|---|---|---|---|---|---|---|"]
        md += [f"| {name} | {t['mean_increase_sigma2']:.4g} | {t['worse_without']} of "
               f"{t['groups']} | {t['t']:.3g} | {t['p_value']:.3g} | {t['verdict']} | "
               f"{in_sample.get(name, '')} |" for name, t in tests]
        md.append("")
    return md
