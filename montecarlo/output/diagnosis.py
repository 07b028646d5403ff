"""Files of a diagnosis report: residual plots, the gap plot, diagnosis.json and report.md."""

from __future__ import annotations

import json
import math
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from montecarlo.discrepancy.candidate_tests import chi2_red_band
from montecarlo.discrepancy.engine import Diagnosis
from montecarlo.discrepancy.problem import OUTLIER
from montecarlo.discrepancy.view import SystemView, format_text, residual_rms
from montecarlo.io.files import atomic_write_bytes, save_figure

FloatArray = NDArray[np.float64]


def plot_residuals(d: Diagnosis, view: SystemView, path: Path) -> None:
    """Residuals before (grey) and after (colour) against each of ``view.axes``."""
    from matplotlib.figure import Figure

    before = view.raw_residuals(d.before.params) / view.rms_scale
    after = view.raw_residuals(d.after.params) / view.rms_scale
    n = len(view.axes)
    flagged = {f"{OUTLIER}{oid}": row for oid, row, _ in d.problem.observations}
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
            for t in d.outliers if i == 1 else ():  # point the flagged observations out
                row = flagged[t.name] - 1
                y = shown[row, int(np.argmax(np.abs(shown[row])))]
                ax.annotate(t.name[len(OUTLIER):], (np.asarray(x)[row], y), fontsize=7,
                            color="C3", xytext=(4, 4), textcoords="offset points")
                ax.plot(np.asarray(x)[row], y, "o", ms=9, mfc="none", color="C3")
            if j == 0:
                ax.set_ylabel(f"{title}: residual [{view.rms_unit}]")
            if i == 1:
                ax.legend(fontsize=7)
    names = ", ".join(d.named) or "none"
    flagged_text = f"; outliers (circled, left out of the fit): {len(d.outliers)}" \
        if d.outliers else ""
    fig.suptitle(f"{view.system}: residuals (measured − model); named: {names}{flagged_text}")
    save_figure(fig, path, dpi=90)


def residual_table(d: Diagnosis, view: SystemView) -> Any:
    """One row per observation: the plotted quantities (image radius, range, ...) and every
    residual component before and after adaptation [``view.rms_unit``]."""
    import pandas as pd

    before = view.raw_residuals(d.before.params) / view.rms_scale
    after = view.raw_residuals(d.after.params) / view.rms_scale
    table = pd.DataFrame({label: np.asarray(x, float) for label, x, _ in view.axes})
    for k, name in enumerate(view.components):
        table[f"{name} before [{view.rms_unit}]"] = before[:, k]
        table[f"{name} after [{view.rms_unit}]"] = after[:, k]
    table.insert(0, "observation", np.arange(len(table)))
    return table


def _log_ticks(axis) -> None:
    """Plain numbers at 1, 2, 5 x 10^k on a logarithmic axis."""
    from matplotlib.ticker import LogLocator, NullFormatter, ScalarFormatter

    axis.set_major_locator(LogLocator(subs=(1.0, 2.0, 5.0)))
    axis.set_major_formatter(ScalarFormatter())
    axis.set_minor_formatter(NullFormatter())


def plot_gap(d: Diagnosis, view: SystemView, mc: Mapping[str, FloatArray] | None,
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
        lo, hi = chi2_red_band(f.dof)
        axes[0].plot([i - 0.4, i + 0.4], [hi, hi], "k--", lw=1)
        axes[0].plot([i - 0.4, i + 0.4], [lo, lo], "k:", lw=1)
    axes[0].set_yscale("log")
    _log_ticks(axes[0].yaxis)
    axes[0].set_xticks(x, ["base", "adapted"])
    axes[0].set_ylabel("χ²_red (dashed/dotted: 99 % band)")
    for i, (_, f) in enumerate(fits):
        axes[0].annotate(f"{f.chi2_red:.3g}", (i, f.chi2_red), ha="center", va="bottom")
    axes[1].bar(x, [residual_rms(view, f) for _, f in fits], color=["0.55", "C0"])
    for i, (_, f) in enumerate(fits):
        rms = residual_rms(view, f)
        axes[1].annotate(f"{rms:.3g}", (i, rms), ha="center", va="bottom")
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
    save_figure(fig, path, dpi=90)


def write_report(outdir: str | Path, d: Diagnosis, view: SystemView,
                 report: Mapping[str, Any], mc: Mapping[str, FloatArray] | None = None,
                 trials: int = 0, seed: int = 0, sections: Sequence[str] = ()) -> list[Path]:
    """Write ``diagnosis.json``, ``report.md``, ``residuals.csv`` (what the residual plot
    shows), ``residuals.png`` and ``gap.png``; ``sections``: Markdown lines report.md adds
    before the figures.

    ``mc`` holds the Monte Carlo chi2_red of the models before and after (``trials`` data sets
    each from ``seed``), or None. Every file is written under a temporary name and renamed.
    """
    outdir = Path(outdir)
    outdir.mkdir(parents=True, exist_ok=True)
    written = [outdir / "residuals.png", outdir / "gap.png"]
    plot_residuals(d, view, written[0])
    plot_gap(d, view, mc, written[1])
    full = dict(report)
    if mc is not None:
        full["monte_carlo"] = {
            "trials": trials, "seed": seed,
            **{k: {"chi2_red_mean": float(np.nanmean(v)),
                   "chi2_red_p99": float(np.nanpercentile(v, 99)),
                   "fraction_at_least_measured": float(np.nanmean(
                       v >= report["gap"][k]["chi2_red"]))} for k, v in mc.items()}}
    atomic_write_bytes(outdir / "diagnosis.json", (json.dumps(full, indent=2) + "\n").encode())
    atomic_write_bytes(outdir / "residuals.csv",
                       residual_table(d, view).to_csv(index=False).encode())
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
    text += [*sections, "![residuals](residuals.png)", "", "![gap](gap.png)", ""]
    atomic_write_bytes(outdir / "report.md", "\n".join(text).encode())
    return [*written, outdir / "diagnosis.json", outdir / "residuals.csv", outdir / "report.md"]


def write_html_report(outdir: str | Path, d: Diagnosis, view: SystemView,
                      mc: Mapping[str, FloatArray] | None = None,
                      extra: Mapping[str, Any] | None = None) -> Path:
    """``report.html`` beside ``report.md`` (:mod:`montecarlo.output.html_report`): the residual
    and gap plots :func:`write_report` saved in ``outdir`` (``mc`` as given to it), with
    captions, and the ``extra`` figures (file name in report.md -> ``HtmlFigure``) that
    report.md shows."""
    from montecarlo.output.html_report import saved_figure, write_html

    outdir = Path(outdir)
    pixel = ("Pixel relation: not modelled here (measured data, one residual per "
             "observation).")
    unit = view.rms_unit
    figures = {
        "residuals.png": saved_figure(
            outdir / "residuals.png",
            f"Residuals (measured − model) of every {view.system} observation [{unit}] against "
            f"each of its axes, base model (top) and adapted model (bottom); statistic: each "
            f"observation's own residual, no aggregate. {pixel}"),
        "gap.png": saved_figure(
            outdir / "gap.png",
            f"The gap before and after adaptation: reduced chi-square χ²_red (unitless, log "
            f"scale) with its 99 % band, and the residual RMS [{unit}]"
            + ("; the Monte Carlo distribution of χ²_red beside the measured value"
               if mc is not None else "") + f". {pixel}"),
        **(extra or {}),
    }
    return write_html(outdir, figures, f"Diagnosis: {view.system}")
