"""Plots of study results: trends against swept parameters, histograms, the L x H map.

All functions build ``matplotlib.figure.Figure`` objects (no pyplot state, no display) and take
the summary frame of :meth:`montecarlo.runner.StudyResult.to_frame`.
"""

from __future__ import annotations

import itertools
from typing import Any

import numpy as np
import pandas as pd
from matplotlib.figure import Figure

from montecarlo import aggregate as agg
from montecarlo.runner import StudyResult
from montecarlo.study import Study

KEY_LABELS = {
    "geometry.L_m": ("L", "range L [m]"),
    "geometry.H_m": ("H", "height difference H [m]"),
    "errors.pixel_px.bound": ("df", "pixel error bound df [px]"),
    "errors.pixel_px.sigma": ("σ_px", "pixel error σ [px]"),
    "errors.dh_m.bound": ("δb", "height-scale error bound δb [m]"),
    "errors.dh_m.sigma": ("σ_δb", "height-scale error σ [m]"),
    "errors.pixel_relation": ("pixel", "pixel error between targets"),
    "errors.evaluation": ("", "evaluation"),
}
MAX_LINES = 8


def key_label(key: str) -> str:
    """Axis label of a sweep key, with unit."""
    return KEY_LABELS.get(key, (key, key))[1]


def short_label(key: str, value: Any) -> str:
    """Compact 'name=value' of a sweep key for legends and titles."""
    short = KEY_LABELS.get(key, (key.split(".")[-1], ""))[0]
    return f"{short}={_fmt(value)}" if short else _fmt(value)


def plot_metric(study: Study) -> str:
    """The metric plots show: the spec's, else the true rotation angle."""
    return study.spec.metric if study.spec else "rotation_angle"


def _zip_partners(study: Study) -> dict[str, tuple[str, ...]]:
    """For each sweep key, the keys zipped with it (including itself), in file order."""
    partners: dict[str, tuple[str, ...]] = {}
    for mode, keys in study.sweep_groups:
        for k in keys:
            partners[k] = keys if mode == "zip" else (k,)
    return partners


def _fmt(v: Any) -> str:
    return f"{v:g}" if isinstance(v, float) else str(v)


def _spec_text(study: Study) -> str:
    s = study.spec
    assert s is not None
    return f"spec: {s.statistic} ≤ {s.limit:g} {study.metric(s.metric).unit}"


def trend_figures(result: StudyResult, summary: pd.DataFrame) -> list[tuple[str, Figure]]:
    """One figure per swept parameter: the metric's percentiles against it, a panel per variant.

    Solid line and shaded band: median (p50) to p95; error bars: the 95 % (study confidence)
    interval of p95; dashed: p99; crosses: max. Zipped keys share one figure whose ticks show
    every zipped value. Other swept keys become separate lines.
    """
    study = result.study
    metric = plot_metric(study)
    m = study.metric(metric)
    data = summary[summary["metric"] == metric]
    variants = list(dict.fromkeys(data["variant"]))
    partners = _zip_partners(study)
    figures = []
    for key in study.sweep_keys:
        group = partners[key]
        categorical = len(group) == 1 and not pd.api.types.is_numeric_dtype(data[key])
        if group[0] != key or categorical:
            continue  # zipped keys share their group's figure; categories become lines
        line_keys = [k for k in study.sweep_keys if k not in group]
        combos = list(data[line_keys].drop_duplicates().itertuples(index=False)) \
            if line_keys else [()]
        combos = combos[:: max(1, int(np.ceil(len(combos) / MAX_LINES)))]
        xs = data[list(group)].drop_duplicates().reset_index(drop=True)
        numeric = len(group) == 1 and pd.api.types.is_numeric_dtype(xs[key])
        fig = Figure(figsize=(5.2 * len(variants), 4.2), layout="constrained")
        axes = fig.subplots(1, len(variants), squeeze=False, sharey=True)[0]
        colors = [f"C{i}" for i in range(10)]
        for ax, variant in zip(axes, variants, strict=True):
            for combo, color in zip(combos, itertools.cycle(colors)):
                sel = data[data["variant"] == variant]
                for k, v in zip(line_keys, combo, strict=True):
                    sel = sel[sel[k] == v]
                sel = sel.merge(xs.reset_index(), on=list(group)).sort_values(
                    key if numeric else "index")
                x = sel[key].to_numpy(float) if numeric else sel["index"].to_numpy()
                label = ", ".join(short_label(k, v)
                                  for k, v in zip(line_keys, combo, strict=True)) or None
                ax.plot(x, sel["p50"], "-o", color=color, ms=3, label=label)
                ax.fill_between(x, sel["p50"], sel["p95"], color=color, alpha=0.18, lw=0)
                ax.errorbar(x, sel["p95"], yerr=[sel["p95"] - sel["p95_lo"].fillna(sel["p95"]),
                                                 sel["p95_hi"].fillna(sel["p95"]) - sel["p95"]],
                            fmt="none", ecolor=color, capsize=2, lw=0.8)
                ax.plot(x, sel["p99"], "--", color=color, lw=0.9)
                ax.plot(x, sel["max"], "x", color=color, ms=5)
            if study.spec and (study.spec.variant in (None, variant)):
                ax.axhline(study.spec.limit, color="k", lw=1, ls=":", label=_spec_text(study))
            if numeric:
                vals = xs[key].to_numpy(float)
                if vals.min() > 0 and vals.max() / vals.min() >= 8:
                    ax.set_xscale("log")
                ax.set_xlabel(key_label(key))
            else:
                ax.set_xticks(xs.index, ["\n".join(_fmt(v) for v in row)
                                         for row in xs.itertuples(index=False)], fontsize=7)
                ax.set_xlabel("\n".join(key_label(k) for k in group), fontsize=8)
            ax.set_title(f"{variant}", fontsize=10)
            ax.grid(alpha=0.3)
        axes[0].set_ylim(bottom=0)
        axes[0].set_ylabel(f"{m.label} [{m.unit}]")
        if axes[0].get_legend_handles_labels()[1]:
            axes[0].legend(fontsize=7, loc="upper left")
        ci = f"{study.header.confidence:.0%}"
        fig.suptitle(f"{study.header.name}: line p50, band p50–p95 (bars: {ci} CI of p95), "
                     "dashed p99, × max", fontsize=9)
        figures.append((f"trend_{key.replace('.', '_')}.png", fig))
    return figures


def histogram_figure(result: StudyResult, summary: pd.DataFrame, max_panels: int = 12
                     ) -> Figure:
    """Distribution of the plotted metric at each grid point (up to ``max_panels`` points)."""
    study = result.study
    metric = plot_metric(study)
    m = study.metric(metric)
    points = list(range(len(study.points)))
    if len(points) > max_panels:
        points = [points[i] for i in np.linspace(0, len(points) - 1, max_panels).astype(int)]
    variants = list(dict.fromkeys(v for v, mm in study.metrics if mm.name == metric))
    sel = summary[(summary["metric"] == metric) & summary["point"].isin(points)]
    xmax = float(np.nanmax(sel["p99"])) * 1.5 or 1.0
    edges = np.linspace(0.0, xmax, 51)
    mid = 0.5 * (agg.ABS_LOWER + np.minimum(agg.ABS_UPPER, 1e300)) * m.scale
    ncols = min(4, len(points))
    nrows = int(np.ceil(len(points) / ncols))
    fig = Figure(figsize=(3.3 * ncols, 2.5 * nrows + 0.5), layout="constrained")
    axes = fig.subplots(nrows, ncols, squeeze=False).ravel()
    for ax, p in zip(axes, points, strict=False):
        for i, v in enumerate(variants):
            stats = result.points[p].metrics.get((v, metric))
            if stats is None or stats.count == 0:
                continue
            counts = agg.abs_histogram(stats.hist) if m.signed else stats.hist[agg.ZERO_BIN:]
            centres = mid if m.signed else mid[: len(counts)]
            h, _ = np.histogram(np.minimum(centres, xmax * 0.999), bins=edges, weights=counts)
            ax.stairs(h / stats.count, edges, color=f"C{i}", label=v, fill=i == 0,
                      alpha=0.35 if i == 0 else 1.0)
        gp = study.points[p]
        ax.set_title(", ".join(short_label(k, v) for k, v in gp.overrides.items())
                     or f"point {p}", fontsize=7)
        ax.tick_params(labelsize=7)
    for ax in axes[len(points):]:
        ax.set_visible(False)
    axes[0].legend(fontsize=7)
    fig.supxlabel(f"{'|' if m.signed else ''}{m.label}{'|' if m.signed else ''} [{m.unit}]",
                  fontsize=9)
    fig.supylabel("fraction of trials", fontsize=9)
    fig.suptitle(f"{study.header.name}: distribution per grid point", fontsize=10)
    return fig


def lh_map_figure(result: StudyResult, summary: pd.DataFrame) -> Figure | None:
    """Map of the spec statistic over range L x height difference H, with the spec contour."""
    study = result.study
    keys = study.sweep_keys
    partners = _zip_partners(study)
    L, H = "geometry.L_m", "geometry.H_m"
    if L not in keys or H not in keys or partners[L] != (L,) or partners[H] != (H,):
        return None
    metric = plot_metric(study)
    m = study.metric(metric)
    stat = study.spec.statistic if study.spec else "p95"
    variant = (study.spec.variant if study.spec else None) or \
        [v for v, mm in study.metrics if mm.name == metric][-1]
    data = summary[(summary["metric"] == metric) & (summary["variant"] == variant)]
    others = [k for k in keys if k not in (L, H)]
    combos = list(data[others].drop_duplicates().itertuples(index=False)) if others else [()]
    combos = combos[:4]
    fig = Figure(figsize=(5.0 * len(combos), 4.4), layout="constrained")
    axes = fig.subplots(1, len(combos), squeeze=False)[0]
    grids = []
    for combo in combos:
        sel = data
        for k, v in zip(others, combo, strict=True):
            sel = sel[sel[k] == v]
        grids.append(sel.pivot_table(index=H, columns=L, values=stat))
    vmax = max(float(np.nanmax(g.to_numpy())) for g in grids)
    for ax, combo, grid in zip(axes, combos, grids, strict=True):
        z = grid.to_numpy()
        mesh = ax.pcolormesh(np.arange(z.shape[1] + 1), np.arange(z.shape[0] + 1), z,
                             cmap="viridis", vmin=0, vmax=vmax)
        for (i, j), val in np.ndenumerate(z):
            ax.text(j + 0.5, i + 0.5, f"{val:.2g}", ha="center", va="center", fontsize=6,
                    color="w" if val < 0.6 * vmax else "k")
        if study.spec is not None and np.nanmin(z) < study.spec.limit < np.nanmax(z):
            cs = ax.contour(np.arange(z.shape[1]) + 0.5, np.arange(z.shape[0]) + 0.5, z,
                            levels=[study.spec.limit], colors="r", linewidths=2)
            ax.clabel(cs, fmt=lambda _: _spec_text(study), fontsize=7)
        ax.set_xticks(np.arange(z.shape[1]) + 0.5, [_fmt(v) for v in grid.columns], fontsize=7)
        ax.set_yticks(np.arange(z.shape[0]) + 0.5, [_fmt(v) for v in grid.index], fontsize=7)
        ax.set_xlabel(key_label(L))
        ax.set_ylabel(key_label(H))
        ax.set_title(", ".join(short_label(k, v) for k, v in zip(others, combo, strict=True)),
                     fontsize=9)
    fig.colorbar(mesh, ax=list(axes), label=f"{stat} of {m.label}, {variant} [{m.unit}]")
    fig.suptitle(f"{study.header.name}: {stat} over L × H"
                 + (f" (red: {_spec_text(study)})" if study.spec else ""), fontsize=10)
    return fig


def all_figures(result: StudyResult, summary: pd.DataFrame) -> list[tuple[str, Figure]]:
    """Every plot of a study, as (file name, figure)."""
    figures = trend_figures(result, summary)
    figures.append(("histograms.png", histogram_figure(result, summary)))
    lh = lh_map_figure(result, summary)
    if lh is not None:
        figures.append(("map_L_H.png", lh))
    return figures
