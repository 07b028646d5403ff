"""How a diagnosis is shown: what a report needs of a system, the diagnosis JSON and its text.

Plots and report files are :mod:`montecarlo.output.diagnosis`; the Monte Carlo distribution of
the residual statistic is :func:`montecarlo.systems.discrepancy.monte_carlo_gap`.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from montecarlo.discrepancy.candidate_tests import POWER, CandidateTest, chi2_red_band
from montecarlo.discrepancy.engine import Diagnosis
from montecarlo.discrepancy.noise import format_noise, noise_scale
from montecarlo.discrepancy.noise_estimation import format_components, format_estimates
from montecarlo.discrepancy.problem import OUTLIER, is_outlier
from montecarlo.lsq import LeastSquaresFit

FloatArray = NDArray[np.float64]


@dataclass(frozen=True)
class SystemView:
    """What the report needs to know about a system beyond the engine.

    Attributes
    ----------
    system : ``"ground"`` or ``"collimation"``.
    display_unit : parameter -> (unit, its size in SI).
    rms_unit, rms_scale : unit of residuals in reports and its size in SI.
    components : names of the two residual components (e.g. ``("px", "pz")``).
    raw_residuals : parameters -> (m, 2) residuals [SI].
    axes : (label, values (m,), components) against which residuals are plotted;
        ``components`` is None for the two raw components, or (names, transform) turning the
        (m, 2) residuals into two other components (e.g. radial and tangential).
    study_system : name of the study system that simulates data sets of this layout
        (``discrepancy_ground``, ``discrepancy_collimation``).
    study_params : the ``run_trials`` parameters (SI) of that system for a fit's model.
    shift_unit : parameter -> (unit, size in SI) for small changes of it (influences).
    base_physics : known physics in the base model, fixed, not fitted (ground: earth
        curvature and the standard coefficient of refraction).
    """

    system: str
    display_unit: Callable[[str], tuple[str, float]]
    rms_unit: str
    rms_scale: float
    components: tuple[str, str]
    raw_residuals: Callable[[Mapping[str, float]], FloatArray]
    axes: Sequence[tuple[str, FloatArray, tuple[tuple[str, str], Callable] | None]]
    study_system: str
    study_params: Callable[[LeastSquaresFit], dict[str, Any]]
    shift_unit: Callable[[str], tuple[str, float]] | None = None
    base_physics: Mapping[str, Any] = field(default_factory=dict)

    def unit(self, name: str) -> tuple[str, float]:
        """Display unit of a parameter; an observation's shift is in sigma."""
        return ("sigma", 1.0) if is_outlier(name) else self.display_unit(name)

    def small(self, name: str) -> tuple[str, float]:
        return ("sigma", 1.0) if is_outlier(name) else (self.shift_unit or self.display_unit)(name)


def residual_rms(view: SystemView, fit: LeastSquaresFit) -> float:
    """RMS of a fit's raw residuals, in the view's residual unit."""
    return float(np.sqrt(np.mean(view.raw_residuals(fit.params) ** 2))) / view.rms_scale


def _show(view: SystemView, values: Mapping[str, float]) -> dict[str, float]:
    return {k: v / view.unit(k)[1] for k, v in values.items()}


def _model(view: SystemView, fit: LeastSquaresFit) -> dict[str, Any]:
    return {"effects": list(fit.effects), "parameters": _show(view, fit.params),
            "stderr": _show(view, fit.stderr),
            "units": {k: view.unit(k)[0] for k in fit.names}}


def _outliers(d: Diagnosis, view: SystemView) -> list[dict[str, Any]]:
    """Each flagged observation: its id and data row, its residual under the final model
    (which does not fit it) [view unit], its shift [sigma], Holm-adjusted p-value and MDB."""
    rows = {f"{OUTLIER}{oid}": row for oid, row, _ in d.problem.observations}
    raw = view.raw_residuals(d.after.params) / view.rms_scale
    out = []
    for t in d.outliers:
        row = rows[t.name]
        out.append({"id": t.name[len(OUTLIER):], "observation": row,
                    "size": dict(zip(view.components, raw[row - 1].tolist(), strict=True)),
                    "size_unit": view.rms_unit,
                    "size_sigma": float(np.linalg.norm(list(t.estimate.values()))),
                    "p_value": t.p_adjusted, "statistic": t.statistic, "dof": t.dof,
                    **({} if t.test == "chi2" else {"test": t.test, "dof2": t.dof2}),
                    "mdb_sigma": float(max(t.mdb.values())), "mdb_test": _mdb_test(t)})
    return out


def test_name(t: CandidateTest | Mapping[str, Any]) -> str:
    """The distribution of a candidate's own test: chi2(q), F(q, d) or Pope's tau(d, q)."""
    kind, q, d = (t.test, t.dof, t.dof2) if isinstance(t, CandidateTest) else (
        t.get("test", "chi2"), t["dof"], t.get("dof2", 0))
    return {"chi2": f"chi2({q})", "F": f"F({q}, {d})", "tau": f"tau({d}, {q})"}[kind]


def _mdb_test(t: CandidateTest) -> dict[str, Any] | None:
    """The test an MDB belongs to: the candidate's own test (chi2(dof) with the noise known;
    F or Pope's tau with it estimated), its size (its share of alpha at the first step of
    Holm's procedure over the detection family) and power."""
    if not t.mdb:
        return None
    out = {"test": "own", "statistic": test_name(t), "dof": t.dof, "size": t.level,
           "power": POWER, "lambda0": t.lambda0}
    if t.test != "chi2":
        out["sigma"] = "estimated"
    return out


def largest_residuals(d: Diagnosis, view: SystemView, k: int = 5) -> list[dict[str, Any]]:
    """The ``k`` observations with the largest standardised residuals under the final model
    and where they sit (the values of the view's plot axes)."""
    if not d.problem.observations:
        return []
    r = d.after.residual
    norms = [(float(np.linalg.norm(r[list(rows)])), oid, row)
             for oid, row, rows in d.problem.observations]
    out = []
    for norm, oid, row in sorted(norms, reverse=True)[:k]:
        where = {label: float(np.asarray(x)[row - 1]) for label, x, _ in view.axes}
        out.append({"id": oid, "observation": row, "standardised": norm, "where": where})
    return out


GENERIC_SEPARATION = "data on which their signatures differ"
"""What separates two members of a group when the problem does not say."""


def _groups(d: Diagnosis, view: SystemView) -> list[dict[str, Any]]:
    """Each confounded group of two or more: its members, the member fitted (the minimal
    parametrisation) with its parameters, and what it cannot separate and which data would."""
    out = []
    for g in d.confounded:
        if len(g.members) < 2:
            continue
        params = {p: d.after.params[p] for p in d.problem.effect(g.fitted).parameters
                  if p in d.after.params}
        out.append({"members": list(g.members), "fitted": g.fitted,
                    "parameters": _show(view, params),
                    "stderr": _show(view, {p: d.after.stderr[p] for p in params}),
                    "units": {k: view.unit(k)[0] for k in params},
                    "cannot_separate": [
                        {"member": m, "from": g.fitted, "correlation": g.correlation[m],
                         "separating_data": g.separating_data.get(m) or GENERIC_SEPARATION}
                        for m in g.members[1:]]})
    return out


def _gap(view: SystemView, fit: LeastSquaresFit) -> dict[str, float]:
    return {"chi2_red": fit.chi2_red, "rms": residual_rms(view, fit), "p_value": fit.p_value,
            "chi2": fit.chi2, "dof": fit.dof}


def to_json(d: Diagnosis, view: SystemView, source: str) -> dict[str, Any]:
    """The JSON of a diagnosis, parameters in display units (``units`` says which).

    Fixed keys: ``system, detected, named_effects[{name, parameters, stderr, p_value}],
    confounded_groups, absorbed, gap{before, after}{chi2_red, rms, p_value}, rms_unit``;
    ``p_value`` of a named effect is Holm-adjusted over the detection family (global test,
    candidate effects, observations); each MDB says its test (``mdb_test``). Extra keys: the
    models before and after, every candidate's statistics at the base model and each step.
    """
    named = []
    for name in d.named:
        r = d.effect_result(name)
        step = next((s for s in d.steps if s.winner == name), None)
        test = None if step is None else next(t for t in step.tests if t.name == name)
        if test is not None and test.test != "chi2":
            r = {**r, "test": test.test, "dof2": test.dof2}
        named.append({**r, "parameters": _show(view, r["parameters"]),
                      "stderr": _show(view, r["stderr"]),
                      "units": {k: view.display_unit(k)[0] for k in r["parameters"]},
                      "absorbed_parameters": {} if test is None else test.absorbed_by})

    def candidate(t: CandidateTest) -> dict[str, Any]:
        return {"name": t.name, "status": t.status, "statistic": t.statistic, "dof": t.dof,
                **({} if t.test == "chi2" else {"test": t.test, "dof2": t.dof2}),
                "p_value": t.p_value, "p_adjusted": t.p_adjusted,
                "mdb": _show(view, t.mdb), "units": {k: view.unit(k)[0] for k in t.mdb},
                "influence": {k: v / view.small(k)[1] for k, v in t.influence.items()
                              if not is_outlier(k)},
                "influence_units": {k: view.small(k)[0] for k in t.influence
                                    if not is_outlier(k)},
                "mdb_test": _mdb_test(t),
                "retained": t.retained, "absorbed_by": t.absorbed_by, "reason": t.reason}

    return {
        "system": d.problem.system,
        "file": source,
        "detected": d.detected,
        "unexplained": d.unexplained,
        "named_effects": named,
        "confounded_groups": [list(g) for g in d.groups if len(g) > 1],
        "groups": _groups(d, view),
        "absorbed": d.absorbed,
        "outliers": _outliers(d, view),
        "dropped_effects": [{"name": n, "p_value": p} for n, p in d.dropped.items()],
        "swapped_effects": [{"out": o, "in": i, "aic_before": a, "aic_after": b}
                            for o, i, a, b in d.swaps],
        "largest_residuals": largest_residuals(d, view),
        "gap": {"before": _gap(view, d.before), "after": _gap(view, d.after)},
        "noise_scale": noise_scale(d.after),
        "rms_unit": view.rms_unit,
        "base_physics": dict(view.base_physics),
        "alpha": d.alpha,
        "chi2_red_band_99": {"before": chi2_red_band(d.before.dof),
                             "after": chi2_red_band(d.after.dof)},
        "model_before": _model(view, d.before),
        "model_after": _model(view, d.after),
        "candidates": [candidate(t) for t in d.steps[0].tests],
        "candidates_after": [candidate(t) for t in d.steps[-1].tests],
        "steps": [{"model": list(s.fit.effects), "chi2_red": s.fit.chi2_red,
                   "p_value": s.fit.p_value, "global_p_adjusted": s.global_p,
                   "winner": s.winner, "group": list(s.group),
                   "dropped": s.dropped} for s in d.steps],
    }


def _unit(unit: str) -> str:
    return "" if unit == "1" else f" {unit}"


def _p(p: float) -> str:
    return "< 1e-300" if p == 0.0 else f"{p:.3g}"


def _why_dropped(e: Mapping[str, Any]) -> str:
    """Why the diagnosis left out an effect or observation it had taken up (the engine records
    no p-value for the last two reasons)."""
    if not math.isnan(e["p_value"]):
        return f"named earlier, not significant given the others: p = {_p(e['p_value'])}, Holm"
    if is_outlier(e["name"]):
        return "flagged earlier; one effect named instead explains it"
    return "its adapted model is singular with these data: not fitted"


FEW_DOF = 10
"""Below this many degrees of freedom left to estimate the noise beside a candidate, its F
test under ``auto`` is weak (the F(q, d) critical value grows fast as d falls)."""


def d_estimated(report: Mapping[str, Any]) -> bool:
    """The diagnosis took the noise as estimated from the data."""
    return bool(report.get("noise_estimate"))


def format_text(report: Mapping[str, Any]) -> str:
    """Human-readable summary of :func:`to_json`."""
    g, unit = report["gap"], report["rms_unit"]
    lines = [f"{report['system']} diagnosis of {report['file']} (alpha = {report['alpha']})"]
    b, a = g["before"], g["after"]
    lines.append(f"base model: chi2_red = {b['chi2_red']:.3f} (dof {b['dof']}), "
                 f"p = {_p(b['p_value'])}, rms = {b['rms']:.4g} {unit}")
    physics = report.get("base_physics", {})
    if physics:
        lines.append("known physics in the base model: " + ", ".join(
            k.replace("_", " ") + ("" if v is True else f" = {v:g}") for k, v in physics.items()))
    if not report["detected"]:
        lines.append("nothing rejected (global test, candidates, observations; Holm): "
                     "no missing effect")
    for e in report["named_effects"]:
        values = ", ".join(f"{k} = {v:.4g} ± {e['stderr'][k]:.2g}{_unit(e['units'][k])}"
                           for k, v in e["parameters"].items())
        how = "Wald test in the final model, swapped in at the end" if e.get("swapped_in") \
            else "Holm"
        stat = (f"T = {e['statistic']:.1f} on {e['dof']} dof" if e.get("test", "chi2") == "chi2"
                else f"{test_name(e)} = {e['statistic']:.1f}")
        if e.get("swapped_in") and d_estimated(report):
            stat = f"F({e['dof']}, {report['gap']['after']['dof']}) = {e['statistic']:.1f}"
        lines.append(f"named: {e['name']} ({values}); identification p = "
                     f"{_p(e['p_value'])} ({how}), {stat}")
    for g in report.get("groups", []):
        values = ", ".join(f"{k} = {v:.4g} ± {g['stderr'][k]:.2g}{_unit(g['units'][k])}"
                           for k, v in g["parameters"].items())
        lines.append(f"group [{', '.join(g['members'])}]: fitted as {g['fitted']} ({values}), "
                     "its minimal parametrisation")
        for c in g["cannot_separate"]:
            lines.append(f"  cannot separate {c['member']} from {c['from']} (correlation "
                         f"{c['correlation']:.3f}); would separate them: "
                         f"{c['separating_data']}")
    for o in report["outliers"]:
        size = ", ".join(f"{k} {v:+.3g}" for k, v in o["size"].items())
        lines.append(f"outlier: observation {o['id']} (row {o['observation']}): {size} "
                     f"{o['size_unit']} off the model ({o['size_sigma']:.1f} sigma; MDB "
                     f"{o['mdb_sigma']:.1f} sigma), p = {_p(o['p_value'])} (Holm); left out "
                     "of the fit")
    for e in report.get("swapped_effects", []):
        lines.append(f"swapped: {e['in']} fits better than {e['out']} with the others "
                     f"(AIC {e['aic_before']:.1f} -> {e['aic_after']:.1f})")
    for e in report["dropped_effects"]:
        lines.append(f"dropped: {e['name']} ({_why_dropped(e)})")
    if report["absorbed"]:
        lines.append(f"absorbed by the model (never named): {', '.join(report['absorbed'])}")
    if report["detected"]:
        test = ("the noise estimated from it" if d_estimated(report)
                else f"p = {a['p_value']:.3g}")
        lines.append(f"adapted model: chi2_red = {a['chi2_red']:.3f} (dof {a['dof']}), "
                     f"{test}, rms = {a['rms']:.4g} {unit}")
    if report.get("noise_estimate"):
        lines.append(format_estimates(report["noise_estimate"]["estimates"],
                                      report["noise_estimate"]["used"]))
        weak = [f"{c['name']} {test_name(c)}" for c in report["candidates"]
                if c["status"] == "testable" and c.get("test") == "F"
                and c["dof2"] < FEW_DOF]
        if weak:
            lines.append("warning: with the noise estimated, fewer than "
                         f"{FEW_DOF} degrees of freedom are left beside " + ", ".join(weak)
                         + ": their tests have little power; state the noise if it is known")
    elif "noise_scale" in report:
        stated = report.get("stated_noise") or {
            k.replace("_", " "): v for k, v in physics.items()
            if "sigma" in k and isinstance(v, int | float) and not isinstance(v, bool)}
        lines.append(format_noise(report["noise_scale"], stated))
        if report.get("noise_components"):
            lines.append(format_components(report["noise_components"]))
    if report["unexplained"]:
        lines.append("a misfit remains that no candidate explains; the largest standardised "
                     "residuals are at:")
        for r in report["largest_residuals"]:
            where = ", ".join(f"{k} {v:.4g}" for k, v in r["where"].items())
            lines.append(f"  {r['id']} (row {r['observation']}): {r['standardised']:.1f} "
                         f"sigma; {where}")
    lines.append("")
    lines.append(f"{'candidate (base model)':<24} {'status':<12} "
                 f"{'F' if d_estimated(report) else 'T':>9} {'dof':>3} "
                 f"{'p (Holm)':>9}  MDB (its own test at size a, power {POWER:g})")
    for c in report["candidates"]:
        mdb = ", ".join(f"{k} {v:.3g}{_unit(c['units'][k])}" for k, v in c["mdb"].items())
        if c.get("mdb_test"):
            mdb += f" ({test_name(c)}, a = {c['mdb_test']['size']:.3g})"
        stat = f"{c['statistic']:9.2f}" if math.isfinite(c["statistic"]) else f"{'-':>9}"
        p = f"{c['p_adjusted']:9.3g}" if math.isfinite(c["p_adjusted"]) else f"{'-':>9}"
        lines.append(f"{c['name']:<24} {c['status']:<12} {stat} {c['dof']:>3} {p}  "
                     f"{mdb or c['reason']}")
    lines.append("")
    lines.append("what the final model could still miss: MDB of each candidate (its own test "
                 "at size a) and the largest shift it would cause, undetected at its MDB, in "
                 "the fitted parameters")
    dropped = {e["name"] for e in report["dropped_effects"]}
    for c in report["candidates_after"]:
        if c["status"] not in ("testable", "undetectable") or c["name"] in dropped:
            continue
        mdb = ", ".join(f"{k} {v:.3g}{_unit(c['units'][k])}" for k, v in c["mdb"].items())
        if c.get("mdb_test"):
            mdb += f" ({test_name(c)}, a = {c['mdb_test']['size']:.3g})"
        worst = sorted(c["influence"].items(), key=lambda kv: -abs(kv[1]))[:3]
        shift = ", ".join(f"{k} {v:.3g}{_unit(c['influence_units'][k])}" for k, v in worst)
        lines.append(f"  {c['name']:<24} MDB {mdb}; shifts {shift}")
    return "\n".join(lines)
