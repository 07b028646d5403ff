"""Plots of study results: trends against swept parameters, histograms, the L x H map.

All functions build ``matplotlib.figure.Figure`` objects (no pyplot state, no display) and take
the summary frame of :meth:`montecarlo.engine.runner.StudyResult.to_frame`.
"""

from __future__ import annotations

import itertools
import textwrap
from typing import TYPE_CHECKING, Any

import numpy as np
import pandas as pd
from matplotlib.colors import LogNorm, Normalize
from matplotlib.figure import Figure

from montecarlo.engine.runner import StudyResult
from montecarlo.engine.study import Study

if TYPE_CHECKING:
    from matplotlib.axes import Axes

KEY_LABELS = {
    "geometry.L_m": ("L", "range L [m]"),
    "geometry.H_m": ("H", "height difference H [m]"),
    "errors.pixel_px.bound": ("df", "pixel error bound df [px]"),
    "errors.pixel_px.sigma": ("σ_px", "pixel error σ [px]"),
    "errors.dh_m.bound": ("δb", "height-scale error bound δb [m]"),
    "errors.dh_m.sigma": ("σ_δb", "height-scale error σ [m]"),
    "errors.pixel_relation": ("pixel error", "pixel error between targets"),
    "errors.evaluation": ("", "evaluation"),
    "params.ta_time_offset_s": ("time tag", "master time-tag offset [s]"),
    "params.ta_lever_arm_error_m": ("lever arm", "lever-arm knowledge ± [m]"),
    "params.ta_duration_s": ("alignment", "alignment length [s]"),
}
MAX_LINES = 12
UNIT_SUFFIXES = ("deg_per_root_h", "deg_per_h", "deg_per_s", "arcsec", "arcmin", "mrad", "deg",
                 "px", "hz", "m", "s", "g")
DIST_FIELDS = ("bound", "sigma", "value", "center", "mean")
UNIT_DISPLAY = {"deg_per_root_h": "deg/√h", "deg_per_h": "deg/h", "deg_per_s": "deg/s"}


def _split_key(key: str) -> tuple[str, str]:
    """(name, unit) of a sweep key: 'params.pitch_span_deg' -> ('pitch span', 'deg')."""
    parts = key.split(".")
    name = " ".join(parts[-2:]) if parts[-1] in DIST_FIELDS and len(parts) > 2 else parts[-1]
    for unit in UNIT_SUFFIXES:
        stem = name.split(" ")[0]
        if stem.endswith("_" + unit):
            return name.replace("_" + unit, "", 1).replace("_", " "), UNIT_DISPLAY.get(unit, unit)
    return name.replace("_", " "), ""


def key_label(key: str) -> str:
    """Axis label of a sweep key, with unit."""
    if key in KEY_LABELS:
        return KEY_LABELS[key][1]
    name, unit = _split_key(key)
    return f"{name} [{unit}]" if unit else name


def short_label(key: str, value: Any) -> str:
    """Compact 'name=value' of a sweep key for legends and titles."""
    if key == "errors.pixel_relation":  # "common", "independent" or a correlation
        return f"pixel error {value}" if value in ("common", "independent") \
            else f"pixel error ρ={float(value):g}"
    short = KEY_LABELS[key][0] if key in KEY_LABELS else _split_key(key)[0]
    unit = key_label(key).rpartition("[")[2].rstrip("]") if key_label(key).endswith("]") else ""
    text = f"{_fmt(value)} {unit}" if unit and isinstance(value, (int, float)) else _fmt(value)
    return f"{short}={text}" if short else text


def plot_metric(study: Study) -> str:
    """The metric plots show: the spec's, else the true rotation angle, else the study's first."""
    if study.spec:
        return study.spec.metric
    names = [m.name for _, m in study.metrics]
    return "rotation_angle" if "rotation_angle" in names else names[0]


def _zip_partners(study: Study) -> dict[str, tuple[str, ...]]:
    """For each sweep key, the keys zipped with it (including itself), in file order."""
    partners: dict[str, tuple[str, ...]] = {}
    for mode, keys in study.sweep_groups:
        for k in keys:
            partners[k] = keys if mode == "zip" else (k,)
    return partners


def _at_base_except(study: Study, data: pd.DataFrame, key: str) -> pd.DataFrame:
    """Rows where the other keys of ``key``'s one_at_a_time group are at their base values."""
    base = study.points[0].values  # point 0 is the base of every one_at_a_time group
    for mode, keys in study.sweep_groups:
        if mode == "one_at_a_time" and key in keys:
            for other in keys:
                if other != key:
                    data = data[data[other] == base[other]]
    return data


def _oat_keys(study: Study) -> set[str]:
    return {k for mode, keys in study.sweep_groups if mode == "one_at_a_time" for k in keys}


def _fmt(v: Any) -> str:
    return f"{v:g}" if isinstance(v, float) else str(v)


def _spec_text(study: Study) -> str:
    s = study.spec
    assert s is not None
    m = study.metric(s.metric)
    return f"spec: {s.statistic_label(m.signed)} ≤ {s.limit:g} {m.unit}"


def p95_interval(ax: Any, x: np.ndarray, rows: pd.DataFrame, color: str,
                 label: str | None = None) -> None:
    """The confidence interval of p95 as error bars (none over enumerated corners). Where the
    trials are too few for an upper bound (``p95_hi`` NaN: fewer than about 60 at 95 %), the bar
    ends in an arrow up: the interval is open above."""
    ci = rows["p95_lo"].notna().to_numpy()
    if not ci.any():
        return
    sel, xs = rows[ci], np.asarray(x)[ci]
    open_above = sel["p95_hi"].isna().to_numpy()
    p95, lo = sel["p95"].to_numpy(float), sel["p95_lo"].to_numpy(float)
    # an open bar: an arrow a fifth of the estimate long (its length means nothing)
    hi = np.where(open_above, 0.2 * np.abs(p95), sel["p95_hi"].to_numpy(float) - p95)
    ax.errorbar(xs, p95, yerr=[p95 - lo, hi], lolims=open_above, fmt="none", ecolor=color,
                capsize=2, lw=0.8, label=label)


def _select(data: pd.DataFrame, keys: list[str], values: tuple) -> pd.DataFrame:
    for k, v in zip(keys, values, strict=True):
        data = data[data[k] == v]
    return data


def _combos(data: pd.DataFrame, keys: list[str], limit: int) -> tuple[list[tuple], bool]:
    """Distinct value combinations of ``keys`` (evenly thinned to ``limit``; True if thinned)."""
    combos = list(data[keys].drop_duplicates().itertuples(index=False, name=None)) if keys \
        else [()]
    if len(combos) <= limit:
        return combos, False
    return [combos[i] for i in np.linspace(0, len(combos) - 1, limit).round().astype(int)], True


def _is_categorical(data: pd.DataFrame, key: str) -> bool:
    return not pd.api.types.is_numeric_dtype(data[key])


def trend_figures(result: StudyResult, summary: pd.DataFrame) -> list[tuple[str, Figure]]:
    """One figure per swept parameter: the metric's percentiles against it.

    Columns of panels are solver variants; rows are the values of other categorical sweep keys
    (e.g. common vs independent pixel error); other numeric sweep keys are lines. Each line is
    the median (p50) with p95 above it (band for up to three lines, dashed otherwise) and the
    confidence interval of p95 as error bars; with up to three lines also p99 (dotted) and max
    (crosses). Zipped keys share one figure whose ticks show every zipped value.
    """
    study = result.study
    metric = plot_metric(study)
    m = study.metric(metric)
    data = summary[summary["metric"] == metric]
    variants = list(dict.fromkeys(data["variant"]))
    partners = _zip_partners(study)
    figures = []
    for key in study.sweep_keys:
        group = list(partners[key])
        if group[0] != key or (len(group) == 1 and _is_categorical(data, key)):
            continue  # zipped keys share their group's figure; categories become panels
        oat = _oat_keys(study)
        rest = [k for k in study.sweep_keys if k not in group and k not in oat]
        row_keys = [k for k in rest if _is_categorical(data, k)]
        line_keys = [k for k in rest if k not in row_keys]
        # a zipped group moves together: its first key names the line
        named = [k for k in line_keys if partners[k][0] == k]
        rows, _ = _combos(data, row_keys, 4)
        lines, thinned = _combos(data, line_keys, MAX_LINES)
        few = len(lines) <= 3
        data_k = _at_base_except(study, data, key)
        xs = data_k[group].drop_duplicates().reset_index(drop=True)
        # a numeric axis: one key, or zipped keys led by a strictly monotone one
        lead = xs[key]
        numeric = pd.api.types.is_numeric_dtype(lead) and (
            len(group) == 1
            or (lead.is_unique and (lead.is_monotonic_increasing or lead.is_monotonic_decreasing)))
        if numeric:
            xs = xs.sort_values(key).reset_index(drop=True)
        fig = Figure(figsize=(max(6.5, 5.0 * len(variants)), 3.6 * len(rows) + 0.8),
                     layout="constrained")
        axes = fig.subplots(len(rows), len(variants), squeeze=False, sharex=True, sharey="row")
        for (r, row), (c, variant) in itertools.product(enumerate(rows), enumerate(variants)):
            ax = axes[r, c]
            panel = _select(data_k[data_k["variant"] == variant], row_keys, row)
            for i, line in enumerate(lines):
                sel = _select(panel, line_keys, line).merge(xs.reset_index(), on=group)
                sel = sel.sort_values(key if numeric else "index")
                x = sel[key].to_numpy(float) if numeric else sel["index"].to_numpy()
                color = f"C{i % 10}"
                label = ", ".join(short_label(k, v) for k, v in zip(line_keys, line,
                                                                     strict=True)
                                  if k in named) or None
                ax.plot(x, sel["p50"], "-o" if numeric else "o", color=color, ms=3, label=label)
                if not numeric:  # separate cases (zipped rows): no lines between them
                    ax.vlines(x, sel["p50"], sel["p95"], color=color, alpha=0.5)
                    ax.plot(x, sel["p95"], "_", color=color, ms=10)
                    ax.plot(x, sel["max"], "x", color=color, ms=5)
                elif few:
                    ax.fill_between(x, sel["p50"], sel["p95"], color=color, alpha=0.2, lw=0)
                    ax.plot(x, sel["p99"], ":", color=color, lw=1)
                    ax.plot(x, sel["max"], "x", color=color, ms=5)
                else:
                    ax.plot(x, sel["p95"], "--", color=color, lw=1)
                for xi, yi, bad in zip(x, sel["p50"], sel["invalid_fraction"], strict=True):
                    if bad >= 0.005:  # trials without a solution: say how many
                        ax.annotate(f"{bad:.0%} no sol.", (xi, yi), xytext=(3, -9),
                                    textcoords="offset points", fontsize=6, color="C3")
                p95_interval(ax, x, sel, color)
            if study.spec and study.spec.variant in (None, variant):
                ax.axhline(study.spec.limit, color="k", lw=1, ls="-.", label=_spec_text(study))
            title = ", ".join(short_label(k, v) for k, v in zip(row_keys, row, strict=True))
            name = "" if variants == ["default"] else variant
            ax.set_title(" — ".join(t for t in (name, title) if t), fontsize=9)
            ax.grid(alpha=0.3, which="both")
            if r == len(rows) - 1:
                if numeric:
                    others = [_split_key(k)[0] for k in group[1:]]
                    ax.set_xlabel(key_label(key) + (f"\n(moving with {', '.join(others)})"
                                                     if others else ""), fontsize=8)
                else:
                    ax.set_xlabel("\n".join(key_label(k) for k in group), fontsize=8)
            if c == 0:
                ax.set_ylabel(f"{m.label} [{m.unit}]", fontsize=8)
        ax0 = axes[0, 0]
        if numeric:
            vals = xs[key].to_numpy(float)
            if vals.min() > 0 and vals.max() / vals.min() >= 8:
                ax0.set_xscale("log")
            ax0.set_xticks(vals, [_fmt(v) for v in vals], fontsize=7)
            ax0.minorticks_off()
        else:
            ax0.set_xticks(xs.index, ["\n".join(_fmt(v) for v in row)
                                      for row in xs.itertuples(index=False)], fontsize=7)
        for ax in axes.ravel():  # the shared axis: one tick size in every panel
            ax.tick_params(axis="x", labelsize=7)
        for r, row in enumerate(rows):  # each row its own scale: log if it spans decades
            shown = _select(data_k, row_keys, row)
            lo, hi = np.nanmin(shown["p50"]), np.nanmax(shown["p99" if few else "p95"])
            if lo > 0 and hi / lo > 30:
                axes[r, 0].set_yscale("log")
            else:
                axes[r, 0].set_ylim(bottom=0)
        n_labels = len(ax0.get_legend_handles_labels()[1])
        if n_labels:
            zipped = [k for k in line_keys if k not in named]
            notes = ([f"thinned to {MAX_LINES} lines"] if thinned else []) + \
                    ([f"{len(zipped)} zipped keys move with them"] if zipped else [])
            ax0.legend(fontsize=6, loc="best", ncols=2 if n_labels > 6 else 1,
                       title="; ".join(notes) or None, title_fontsize=6)
        ci = f"{study.header.confidence:.0%}"
        style = ("cases: dot p50, bar to p95 (—), × max" if not numeric
                 else "line p50, band to p95, dotted p99, × max" if few
                 else "solid p50, dashed p95")
        exact = "" if all(gp.sampled for gp in study.points) \
            else " (none where the trials enumerate the corners)"
        fig.suptitle(f"{study.header.name}: {m.label}\n{style}; bars: {ci} CI of p95{exact}",
                     fontsize=9)
        figures.append((f"trend_{key.replace('.', '_')}.png", fig))
    return figures


def _rebin(lower: np.ndarray, upper: np.ndarray, counts: np.ndarray, scale: float,
           edges: np.ndarray) -> np.ndarray:
    """Counts of occupied log-spaced bins spread evenly over their widths into ``edges`` (by
    interpolating the cumulative count), so that no linear bin is left empty or doubled."""
    upper = np.where(np.isfinite(upper), upper, 2.0 * lower)  # the overflow bin
    cum = np.cumsum(counts)
    xp = np.column_stack([lower, upper]).ravel() * scale
    fp = np.column_stack([cum - counts, cum]).ravel()
    return np.diff(np.interp(edges, xp, fp, right=cum[-1]))


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
    sel = summary[summary["metric"] == metric]
    ncols = min(4, len(points))
    nrows = int(np.ceil(len(points) / ncols))
    fig = Figure(figsize=(3.3 * ncols, 2.5 * nrows + 0.5), layout="constrained")
    axes = fig.subplots(nrows, ncols, squeeze=False).ravel()
    spec = study.spec if study.spec and study.spec.metric == metric else None
    # panel titles name the keys that differ between the points shown
    varying = [k for k in study.sweep_keys
               if len({_fmt(study.points[p].values[k]) for p in points}) > 1]
    for ax, p in zip(axes, points, strict=False):
        # each panel its own range (grid points may differ by orders of magnitude): to 1.5 p99
        rows = sel[sel["point"] == p]
        p99 = rows["p99"].to_numpy(float)
        xmax = float(np.max(p99[np.isfinite(p99)], initial=0.0)) * 1.5
        if spec is not None and spec.limit < 3.0 * xmax:
            xmax = max(xmax, 1.1 * spec.limit)
        if not xmax > 0.0:
            xmax = 1.0
        edges = np.linspace(0.0, xmax, 51)
        for i, v in enumerate(variants):
            hist = result.points[p].histograms.get((v, metric))
            if hist is None or hist[2].sum() == 0:
                continue
            h = _rebin(*hist, m.scale, edges)
            # fractions of all trials: those without a value are not in any bin
            ax.stairs(h / result.points[p].summary["trials"].iloc[0], edges, color=f"C{i}",
                      label=v if v != "default" else "trials", fill=i == 0,
                      alpha=0.35 if i == 0 else 1.0)
            p95 = rows.loc[rows["variant"] == v, "p95"]
            if len(p95) and np.isfinite(p95.iloc[0]) and p95.iloc[0] <= xmax:
                ax.axvline(p95.iloc[0], color=f"C{i}", ls="--", lw=0.8,
                           label="p95" if i == 0 else None)
        if spec is not None and spec.limit <= xmax:
            ax.axvline(spec.limit, color="k", ls="-.", lw=1, label=_spec_text(study))
        gp = study.points[p]
        # no line break inside one key's label (non-breaking spaces)
        title = ", ".join(short_label(k, gp.values[k]).replace(" ", "\u00a0")
                          for k in varying) or f"point {p}"
        shares = rows.set_index("variant")["invalid_fraction"].reindex(variants).dropna()
        invalid = shares.max() if len(shares) else 0.0
        if invalid > 0:  # by variant where they differ (one solver may fail where another not)
            title += "; no\u00a0solution: " + (f"{invalid:.1%}" if shares.nunique() == 1 else
                                          ", ".join(f"{v} {x:.1%}" for v, x in shares.items()))
        ax.set_title(textwrap.fill(f"{p}: {title}", 52), fontsize=7,
                     color="C3" if invalid > 0 else "k")
        ax.tick_params(labelsize=7)
    for ax in axes[len(points):]:
        ax.set_visible(False)
    labels = axes[0].get_legend_handles_labels()[1]
    if variants != ["default"] or len(labels) > 1:
        axes[0].legend(fontsize=6)
    fig.supxlabel(f"{'|' if m.signed else ''}{m.label}{'|' if m.signed else ''} [{m.unit}]",
                  fontsize=9)
    fig.supylabel("fraction of trials", fontsize=9)
    fig.suptitle(f"{study.header.name}: distribution per grid point (each to 1.5 × its p99; "
                 "dashed: p95)", fontsize=10)
    return fig


MAPS = (("geometry.L_m", "geometry.H_m", "map_L_H.png"),
        ("params.ta_lever_arm_error_m", "params.ta_time_offset_s", "map_sync_survey.png"))
"""Sweep-key pairs drawn as a map when both are swept: (x key, y key, file name)."""


def lh_map_figure(result: StudyResult, summary: pd.DataFrame, L: str = "geometry.L_m",
                  H: str = "geometry.H_m") -> Figure | None:
    """Map of the spec statistic over two swept keys (by default range L x height difference
    H), with the spec contour; one panel per value of the other keys (up to 4)."""
    study = result.study
    keys = study.sweep_keys
    partners = _zip_partners(study)
    if L not in keys or H not in keys or partners[L] != (L,) or partners[H] != (H,) \
            or {L, H} & _oat_keys(study):
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
        # with a spec: its statistic over all trials, as judged (no solution = +inf)
        grids.append((sel.pivot_table(index=H, columns=L,
                                      values="spec_value" if study.spec else stat),
                      sel.pivot_table(index=H, columns=L, values="invalid_fraction")))
    finite = [g.to_numpy()[np.isfinite(g.to_numpy())] for g, _ in grids]
    vmin = min(float(f.min(initial=np.inf)) for f in finite)
    vmax = max(float(f.max(initial=-np.inf)) for f in finite)
    norm = LogNorm(vmin, vmax) if vmin > 0 and vmax / vmin > 10 else Normalize(0, vmax)
    for ax, combo, (grid, invalid) in zip(axes, combos, grids, strict=True):
        z = grid.to_numpy()
        mesh = ax.pcolormesh(np.arange(z.shape[1] + 1), np.arange(z.shape[0] + 1), z,
                             cmap="viridis", norm=norm)
        for (i, j), val in np.ndenumerate(z):
            text = "∞" if val == np.inf else f"{val:.0f}" if val >= 100 else f"{val:.3g}"
            bad = invalid.to_numpy()[i, j]
            if bad >= 0.005:
                text += f"\n{bad:.0%} no sol."
            ax.text(j + 0.5, i + 0.5, text, ha="center", va="center", fontsize=7,
                    color="w" if np.isfinite(val) and norm(val) < 0.6 else "k")
        if study.spec is not None:
            limit = study.spec.limit
            if np.nanmin(z) < limit < np.nanmax(z):
                cs = ax.contour(np.arange(z.shape[1]) + 0.5, np.arange(z.shape[0]) + 0.5, z,
                                levels=[limit], colors="r", linewidths=2)
                ax.clabel(cs, fmt=lambda _: _spec_text(study), fontsize=7)
            elif not (z <= limit).any():
                ax.text(0.5, 1.01, "no grid point meets the spec", transform=ax.transAxes,
                        ha="center", va="bottom", fontsize=8, color="r")
            elif (z <= limit).all():
                ax.text(0.5, 1.01, "every grid point meets the spec", transform=ax.transAxes,
                        ha="center", va="bottom", fontsize=8, color="g")
        ax.set_xticks(np.arange(z.shape[1]) + 0.5, [_fmt(v) for v in grid.columns], fontsize=7)
        ax.set_yticks(np.arange(z.shape[0]) + 0.5, [_fmt(v) for v in grid.index], fontsize=7)
        ax.set_xlabel(key_label(L))
        ax.set_ylabel(key_label(H))
        ax.set_title(", ".join(short_label(k, v) for k, v in zip(others, combo, strict=True)),
                     fontsize=9, pad=14)
    over = "\nover all trials (no solution = ∞)" if study.spec else ""
    fig.colorbar(mesh, ax=list(axes), label=f"{stat} of {m.label}, {variant} [{m.unit}]{over}")
    x_name, y_name = ((KEY_LABELS[k][0] if k in KEY_LABELS else _split_key(k)[0]) for k in (L, H))
    fig.suptitle(f"{study.header.name}: {stat} over {x_name} × {y_name}"
                 + (f" (red: {_spec_text(study)})" if study.spec else ""), fontsize=10)
    return fig


def all_figures(result: StudyResult, summary: pd.DataFrame) -> list[tuple[str, Figure]]:
    """Every plot of a study, as (file name, figure)."""
    figures = trend_figures(result, summary)
    figures.append(("histograms.png", histogram_figure(result, summary)))
    for x, y, name in MAPS:
        fig = lh_map_figure(result, summary, x, y)
        if fig is not None:
            figures.append((name, fig))
    return figures


def metric_axes(result: StudyResult, summary: pd.DataFrame, metric: str | None = None,
                variant: str | None = None, ax: Axes | None = None) -> Axes:
    """One metric at every grid point on one axes: p50 with a band to p95, p99 dotted, the
    confidence interval of p95 as bars and the spec limit.

    The x axis is the swept key if there is exactly one numeric sweep key, else the grid point
    number (ticks name the point). ``metric`` defaults to the plotted one (the spec's, else the
    true rotation angle), ``variant`` to the spec's (else the last), ``ax`` to a new figure.
    """
    study = result.study
    metric = metric or plot_metric(study)
    names = [mm.name for _, mm in study.metrics]
    if metric not in names:
        raise ValueError(f"metric {metric!r} is not in this study (it has "
                         f"{', '.join(dict.fromkeys(names))})")
    variants = [v for v, mm in study.metrics if mm.name == metric]
    if variant is None:
        variant = study.spec.variant if study.spec and study.spec.variant else variants[-1]
    if variant not in variants:
        raise ValueError(f"variant {variant!r} has no metric {metric!r} (variants: "
                         f"{', '.join(variants)})")
    m = study.metric(metric)
    data = summary[(summary["metric"] == metric) & (summary["variant"] == variant)]
    data = data.sort_values("point")
    if ax is None:
        ax = Figure(figsize=(6.5, 4.0), layout="constrained").subplots()
    keys = study.sweep_keys
    if len(keys) == 1 and not _is_categorical(data, keys[0]):
        data = data.sort_values(keys[0])
        x = data[keys[0]].to_numpy(float)
        ax.set_xlabel(key_label(keys[0]))
    else:
        x = np.arange(len(data), dtype=float)
        if len(data) <= 6:
            ax.set_xticks(x, [textwrap.fill(", ".join(short_label(k, study.points[p].values[k])
                                                      for k in keys), 24) or f"point {p}"
                              for p in data["point"]], fontsize=6)
            ax.set_xlabel("grid point")
        else:
            ax.set_xticks(x, [str(p) for p in data["point"]], fontsize=7)
            ax.set_xlabel("grid point (the summary's point column)")
    ax.plot(x, data["p50"], "-o", ms=3, color="C0", label="p50")
    ax.fill_between(x, data["p50"], data["p95"], color="C0", alpha=0.2, lw=0, label="to p95")
    ax.plot(x, data["p99"], ":", color="C0", lw=1, label="p99")
    p95_interval(ax, x, data, "C0", f"{study.header.confidence:.0%} CI of p95")
    if study.spec and study.spec.metric == metric and study.spec.variant in (None, variant):
        if study.spec.statistic not in ("p50", "p95", "p99"):
            stat = study.spec.statistic
            ax.plot(x, data["spec_value" if stat == "rms" else stat], "x", color="C3",
                    label=stat)
        ax.axhline(study.spec.limit, color="k", lw=1, ls="-.", label=_spec_text(study))
    ax.set_ylabel(f"{m.label} [{m.unit}]")
    ax.set_ylim(bottom=0)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=7)
    ax.set_title(f"{study.header.name}: {m.label}"
                 + ("" if variant == "default" else f" ({variant})"), fontsize=9)
    return ax
