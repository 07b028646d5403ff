"""Reports of a diagnosis: the JSON of issue 5, text, residual plots and the Monte Carlo gap.

The Monte Carlo distribution of the residual statistic comes from the study framework: a study
of the system ``discrepancy_ground`` or ``discrepancy_collimation`` with two grid points, the
model before (base fit) and after (adapted fit), each simulating data sets on the measured
layout from its fitted values with the stated noise and fitting the same model again.
"""

from __future__ import annotations

import json
import math
import tempfile
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from montecarlo.discrepancy import engine as dia
from montecarlo.systems.params import UNITS, ParamSystem

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
    study : the study system and a function giving its ``[params]`` (SI) for a fit.
    shift_unit : parameter -> (unit, size in SI) for small changes of it (influences).
    """

    system: str
    display_unit: Callable[[str], tuple[str, float]]
    rms_unit: str
    rms_scale: float
    components: tuple[str, str]
    raw_residuals: Callable[[Mapping[str, float]], FloatArray]
    axes: Sequence[tuple[str, FloatArray, tuple[tuple[str, str], Callable] | None]]
    study: ParamSystem
    study_params: Callable[[dia.ModelFit], dict[str, Any]]
    shift_unit: Callable[[str], tuple[str, float]] | None = None

    def small(self, name: str) -> tuple[str, float]:
        return (self.shift_unit or self.display_unit)(name)


def _rms(view: SystemView, fit: dia.ModelFit) -> float:
    return float(np.sqrt(np.mean(view.raw_residuals(fit.params) ** 2))) / view.rms_scale


def _show(view: SystemView, values: Mapping[str, float]) -> dict[str, float]:
    return {k: v / view.display_unit(k)[1] for k, v in values.items()}


def _model(view: SystemView, fit: dia.ModelFit) -> dict[str, Any]:
    return {"effects": list(fit.effects), "parameters": _show(view, fit.params),
            "stderr": _show(view, fit.stderr),
            "units": {k: view.display_unit(k)[0] for k in fit.names}}


def _gap(view: SystemView, fit: dia.ModelFit) -> dict[str, float]:
    return {"chi2_red": fit.chi2_red, "rms": _rms(view, fit), "p_value": fit.p_value,
            "chi2": fit.chi2, "dof": fit.dof}


def to_json(d: dia.Diagnosis, view: SystemView, source: str) -> dict[str, Any]:
    """The issue-5 JSON of a diagnosis, parameters in display units (``units`` says which).

    Fixed keys: ``system, detected, named_effects[{name, parameters, stderr, p_value}],
    confounded_groups, absorbed, gap{before, after}{chi2_red, rms, p_value}, rms_unit``;
    ``p_value`` of a named effect is Holm-adjusted. Extra keys: the models before and after,
    every candidate's statistics at the base model and each step.
    """
    named = []
    for name in d.named:
        r = d.effect_result(name)
        step = next(s for s in d.steps if s.winner == name)
        test = next(t for t in step.tests if t.name == name)
        named.append({**r, "parameters": _show(view, r["parameters"]),
                      "stderr": _show(view, r["stderr"]),
                      "units": {k: view.display_unit(k)[0] for k in r["parameters"]},
                      "absorbed_parameters": test.absorbed_by})

    def candidate(t: dia.CandidateTest) -> dict[str, Any]:
        return {"name": t.name, "status": t.status, "statistic": t.statistic, "dof": t.dof,
                "p_value": t.p_value, "p_adjusted": t.p_adjusted,
                "mdb": _show(view, t.mdb), "units": {k: view.display_unit(k)[0] for k in t.mdb},
                "influence": {k: v / view.small(k)[1] for k, v in t.influence.items()},
                "influence_units": {k: view.small(k)[0] for k in t.influence},
                "retained": t.retained, "absorbed_by": t.absorbed_by, "reason": t.reason}

    return {
        "system": d.problem.system,
        "file": source,
        "detected": d.detected,
        "unexplained": d.unexplained,
        "named_effects": named,
        "confounded_groups": [list(g) for g in d.groups if len(g) > 1],
        "absorbed": d.absorbed,
        "gap": {"before": _gap(view, d.before), "after": _gap(view, d.after)},
        "rms_unit": view.rms_unit,
        "alpha": d.alpha,
        "chi2_red_band_99": {"before": dia.chi2_red_band(d.before.dof),
                             "after": dia.chi2_red_band(d.after.dof)},
        "model_before": _model(view, d.before),
        "model_after": _model(view, d.after),
        "candidates": [candidate(t) for t in d.steps[0].tests],
        "candidates_after": [candidate(t) for t in d.steps[-1].tests],
        "steps": [{"model": list(s.fit.effects), "chi2_red": s.fit.chi2_red,
                   "p_value": s.fit.p_value, "winner": s.winner, "group": list(s.group)}
                  for s in d.steps],
    }


def _unit(unit: str) -> str:
    return "" if unit == "1" else f" {unit}"


def _p(p: float) -> str:
    return "< 1e-300" if p == 0.0 else f"{p:.3g}"


def format_text(report: Mapping[str, Any]) -> str:
    """Human-readable summary of :func:`to_json`."""
    g, unit = report["gap"], report["rms_unit"]
    lines = [f"{report['system']} diagnosis of {report['file']} (alpha = {report['alpha']})"]
    b, a = g["before"], g["after"]
    lines.append(f"base model: chi2_red = {b['chi2_red']:.3f} (dof {b['dof']}), "
                 f"p = {_p(b['p_value'])}, rms = {b['rms']:.4g} {unit}")
    if not report["detected"]:
        lines.append("global test passes: no missing effect")
    for e in report["named_effects"]:
        values = ", ".join(f"{k} = {v:.4g} ± {e['stderr'][k]:.2g}{_unit(e['units'][k])}"
                           for k, v in e["parameters"].items())
        lines.append(f"named: {e['name']} ({values}); identification p = "
                     f"{_p(e['p_value'])} (Holm), T = {e['statistic']:.1f} on {e['dof']} dof")
    for group in report["confounded_groups"]:
        lines.append(f"confounded group (the data cannot tell these apart): "
                     f"{', '.join(group)}")
    if report["absorbed"]:
        lines.append(f"absorbed by the model (never named): {', '.join(report['absorbed'])}")
    if report["detected"]:
        lines.append(f"adapted model: chi2_red = {a['chi2_red']:.3f} (dof {a['dof']}), "
                     f"p = {a['p_value']:.3g}, rms = {a['rms']:.4g} {unit}")
    if report["unexplained"]:
        lines.append("a misfit remains that no candidate explains")
    lines.append("")
    lines.append(f"{'candidate (base model)':<24} {'status':<12} {'T':>9} {'dof':>3} "
                 f"{'p (Holm)':>9}  MDB")
    for c in report["candidates"]:
        mdb = ", ".join(f"{k} {v:.3g}{_unit(c['units'][k])}" for k, v in c["mdb"].items())
        stat = f"{c['statistic']:9.2f}" if math.isfinite(c["statistic"]) else f"{'-':>9}"
        p = f"{c['p_adjusted']:9.3g}" if math.isfinite(c["p_adjusted"]) else f"{'-':>9}"
        lines.append(f"{c['name']:<24} {c['status']:<12} {stat} {c['dof']:>3} {p}  "
                     f"{mdb or c['reason']}")
    lines.append("")
    lines.append("what the final model could still miss: MDB of each candidate and the largest "
                 "shift it would cause, undetected at its MDB, in the fitted parameters")
    for c in report["candidates_after"]:
        if c["status"] not in ("testable", "undetectable"):
            continue
        mdb = ", ".join(f"{k} {v:.3g}{_unit(c['units'][k])}" for k, v in c["mdb"].items())
        worst = sorted(c["influence"].items(), key=lambda kv: -abs(kv[1]))[:3]
        shift = ", ".join(f"{k} {v:.3g}{_unit(c['influence_units'][k])}" for k, v in worst)
        lines.append(f"  {c['name']:<24} MDB {mdb}; shifts {shift}")
    return "\n".join(lines)


# --------------------------------------------------------------------------- Monte Carlo gap


def study_params_si(system: ParamSystem, si: Mapping[str, Any]) -> dict[str, Any]:
    """``[params]`` keys and values of a ParamSystem study from SI/radian values."""
    out = {}
    for k, v in si.items():
        unit = system.units.get(k, "")
        key = f"{k}_{unit}" if unit else k
        out[key] = float(v) / UNITS[unit] if isinstance(v, float) else v
    return out


def monte_carlo_gap(d: dia.Diagnosis, view: SystemView, trials: int = 200, seed: int = 0,
                    n_jobs: int = 1) -> dict[str, FloatArray]:
    """Simulated chi2_red of the model before and after, through the study runner.

    Returns ``{"before": (trials,), "after": (trials,)}``: each data set is simulated on the
    measured layout from that model's fitted values and refitted with the same model.
    """
    from montecarlo.engine.runner import RunOptions, run_study
    from montecarlo.engine.study import study_from_dict

    before = study_params_si(view.study, view.study_params(d.before))
    after = study_params_si(view.study, view.study_params(d.after))
    keys = sorted(set(before) | set(after))
    common = {k: before[k] for k in keys if before.get(k) == after.get(k)}
    sweep = {f"params.{k}": [before[k], after[k]] for k in keys if k not in common}
    raw: dict[str, Any] = {
        "study": {"name": f"diagnose_{view.system}", "system": view.study.name,
                  "trials": trials, "seed": seed, "per_trial": True},
        "params": common,
    }
    if sweep:
        raw["sweep"] = {"mode": "zip", **sweep}
    study = study_from_dict(raw, f"<diagnose {view.system}>")
    with tempfile.TemporaryDirectory() as tmp:
        result = run_study(study, RunOptions(n_jobs=n_jobs, progress=False,
                                             checkpoint_dir=Path(tmp)))
    column = "default/chi2_red"
    values = [result.trials[p.index][column].to_numpy(float) for p in study.points]
    return {"before": values[0], "after": values[-1]}


# --------------------------------------------------------------------------- plots


def plot_residuals(d: dia.Diagnosis, view: SystemView, path: Path) -> None:
    """Residuals before (grey) and after (colour) against each of ``view.axes``."""
    from matplotlib.figure import Figure

    before = view.raw_residuals(d.before.params) / view.rms_scale
    after = view.raw_residuals(d.after.params) / view.rms_scale
    n = len(view.axes)
    fig = Figure(figsize=(3.4 * n, 5.6), layout="constrained")
    axes = fig.subplots(2, n, squeeze=False, sharey="row")
    for j, (label, x, components) in enumerate(view.axes):
        names, transform = components or (view.components, None)
        for i, (title, res) in enumerate((("base model", before), ("adapted model", after))):
            ax = axes[i, j]
            ax.axhline(0.0, color="0.6", lw=0.8)
            shown = res if transform is None else transform(res)
            for k, (name, marker) in enumerate(zip(names, ("o", "^"), strict=True)):
                ax.plot(x, shown[:, k], marker, ms=4, alpha=0.75, mfc="none" if k else None,
                        color=f"C{k}" if i else ("0.3" if k == 0 else "0.6"), label=name)
            ax.set_xlabel(label)
            ax.grid(alpha=0.3)
            if j == 0:
                ax.set_ylabel(f"{title}: residual [{view.rms_unit}]")
            if i == 1:
                ax.legend(fontsize=7)
    names = ", ".join(d.named) or "none"
    fig.suptitle(f"{view.system}: residuals (measured − model); named: {names}")
    fig.savefig(path, dpi=90)


def _log_ticks(axis) -> None:
    """Plain numbers at 1, 2, 5 x 10^k on a logarithmic axis."""
    from matplotlib.ticker import LogLocator, NullFormatter, ScalarFormatter

    axis.set_major_locator(LogLocator(subs=(1.0, 2.0, 5.0)))
    axis.set_major_formatter(ScalarFormatter())
    axis.set_minor_formatter(NullFormatter())


def plot_gap(d: dia.Diagnosis, view: SystemView, mc: Mapping[str, FloatArray] | None,
             path: Path) -> None:
    """Gap before and after: chi2_red with its 99 % band, rms, and the Monte Carlo histograms.
    """
    from matplotlib.figure import Figure

    fits = (("before", d.before), ("after", d.after))
    ncols = 4 if mc is not None else 2
    fig = Figure(figsize=(3.6 * ncols, 3.6), layout="constrained")
    axes = fig.subplots(1, ncols)
    x = np.arange(2)
    axes[0].bar(x, [f.chi2_red for _, f in fits], color=["0.55", "C0"])
    for i, (_, f) in enumerate(fits):
        lo, hi = dia.chi2_red_band(f.dof)
        axes[0].plot([i - 0.4, i + 0.4], [hi, hi], "k--", lw=1)
        axes[0].plot([i - 0.4, i + 0.4], [lo, lo], "k:", lw=1)
    axes[0].set_yscale("log")
    _log_ticks(axes[0].yaxis)
    axes[0].set_xticks(x, ["base", "adapted"])
    axes[0].set_ylabel("χ²_red (dashed/dotted: 99 % band)")
    for i, (_, f) in enumerate(fits):
        axes[0].annotate(f"{f.chi2_red:.3g}", (i, f.chi2_red), ha="center", va="bottom")
    axes[1].bar(x, [_rms(view, f) for _, f in fits], color=["0.55", "C0"])
    for i, (_, f) in enumerate(fits):
        axes[1].annotate(f"{_rms(view, f):.3g}", (i, _rms(view, f)), ha="center", va="bottom")
    axes[1].set_xticks(x, ["base", "adapted"])
    axes[1].set_ylabel(f"residual RMS [{view.rms_unit}]")
    if mc is not None:
        for ax, (key, f) in zip(axes[2:], fits, strict=True):
            values = mc[key][np.isfinite(mc[key]) & (mc[key] > 0)]
            top = max(float(np.max(values, initial=1.0)), f.chi2_red)
            bottom = min(float(np.min(values, initial=1.0)), f.chi2_red)
            far = f.chi2_red > 3.0 * float(np.max(values, initial=0.0))
            bins = np.geomspace(bottom / 1.05, top * 1.05, 40) if far else 30
            ax.hist(values, bins=bins, color="0.7", label=f"Monte Carlo ({values.size})")
            ax.axvline(f.chi2_red, color="C3", lw=2, label="measured")
            frac = float(np.mean(values >= f.chi2_red)) if values.size else math.nan
            ax.set_title(f"{'base' if key == 'before' else 'adapted'} model: "
                         f"P(MC ≥ measured) = {frac:.3f}", fontsize=9)
            ax.set_xlabel("χ²_red" + (" (log scale)" if far else ""))
            if far:
                ax.set_xscale("log")
                _log_ticks(ax.xaxis)
            ax.legend(fontsize=7)
    fig.suptitle(f"{view.system}: the gap before and after adaptation")
    fig.savefig(path, dpi=90)


def write_report(outdir: str | Path, d: dia.Diagnosis, view: SystemView,
                 report: Mapping[str, Any], trials: int = 200, seed: int = 0, n_jobs: int = 1
                 ) -> list[Path]:
    """Write ``diagnosis.json``, ``report.md``, ``residuals.png`` and ``gap.png``.

    Every file is written under a temporary name and renamed.
    """
    from montecarlo.io.files import atomic_write_bytes

    outdir = Path(outdir)
    outdir.mkdir(parents=True, exist_ok=True)
    mc = monte_carlo_gap(d, view, trials, seed, n_jobs) if trials > 0 else None
    written = []
    for name, plot in (("residuals.png", lambda p: plot_residuals(d, view, p)),
                       ("gap.png", lambda p: plot_gap(d, view, mc, p))):
        tmp = outdir / f".{name}.tmp.png"
        plot(tmp)
        tmp.replace(outdir / name)
        written.append(outdir / name)
    full = dict(report)
    if mc is not None:
        full["monte_carlo"] = {
            "trials": trials, "seed": seed,
            **{k: {"chi2_red_mean": float(np.nanmean(v)),
                   "chi2_red_p99": float(np.nanpercentile(v, 99)),
                   "fraction_at_least_measured": float(np.nanmean(
                       v >= report["gap"][k]["chi2_red"]))} for k, v in mc.items()}}
    atomic_write_bytes(outdir / "diagnosis.json", (json.dumps(full, indent=2) + "\n").encode())
    text = ["# Diagnosis", "", "```", format_text(report), "```", ""]
    if mc is not None:
        text += ["## Monte Carlo of the residual statistic (study runner)", "",
                 f"{trials} simulated data sets per model on the measured layout, seed {seed}.",
                 "", "| model | measured χ²_red | MC mean | MC 99th percentile | "
                 "P(MC ≥ measured) |", "|---|---|---|---|---|"]
        for k in ("before", "after"):
            m = full["monte_carlo"][k]
            text.append(f"| {k} | {report['gap'][k]['chi2_red']:.3f} | "
                        f"{m['chi2_red_mean']:.3f} | {m['chi2_red_p99']:.3f} | "
                        f"{m['fraction_at_least_measured']:.3f} |")
        text.append("")
    text += ["![residuals](residuals.png)", "", "![gap](gap.png)", ""]
    atomic_write_bytes(outdir / "report.md", "\n".join(text).encode())
    return [*written, outdir / "diagnosis.json", outdir / "report.md"]
