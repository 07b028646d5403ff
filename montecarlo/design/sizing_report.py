"""What a sizing run writes: the frontier figure, the text and Markdown reports, the CSV tables."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
from matplotlib.figure import Figure

from montecarlo.design.sizing import (
    RelationSizing,
    SizingProblem,
    SizingResult,
    plotted_knobs,
)
from montecarlo.design.sizing_problem import KNOBS, RELATION_TEXT
from montecarlo.io.files import atomic_write_bytes, save_figure
from montecarlo.output.report import markdown_table


def _fmt(v: Any) -> str:
    if isinstance(v, float | np.floating):
        return "–" if not np.isfinite(v) else f"{v:#.4g}"
    return "–" if v is None else str(v)


VERDICT_STYLES = {"meets": ("o", "tab:green"), "undecided": ("s", "tab:orange"),
                  "fails": ("x", "tab:red"), "invalid": ("x", "k")}


def _log_ticks(ax_set: Any, values: np.ndarray) -> None:
    ax_set(values, [f"{v:.3g}" for v in values], fontsize=7)


def _plot_slice(ax: Any, problem: SizingProblem, rs: RelationSizing, unit: str) -> None:
    """Verdicts on the slice through the answer, the boundary of 'meets' and the answer."""
    req = problem.requirement
    a = rs.answer
    sl = rs.slice
    axes = plotted_knobs(problem, a)
    if sl is None or not axes:
        ax.set_axis_off()
        return
    others = [n for n in problem.names if n not in {k.name for k in axes}]
    fixed = ", ".join(f"{n}={sl[n].iloc[0]:.3g}" for n in others)
    where = "through the answer" if a is not None else "through the best design found (no answer)"
    title = RELATION_TEXT[rs.relation].split(" (")[0] + f"\nslice {where}" + (
        f" at {fixed}" if fixed else "")
    if len(axes) == 1:
        k = axes[0]
        sel = sl.sort_values(k.name)
        ax.fill_between(sel[k.name], sel["lo"], sel["hi"], color="0.75",
                        label=f"{req.confidence:.0%} interval")
        ax.plot(sel[k.name], sel["value"], "-", color="0.3", lw=1)
        for v, (m, c) in VERDICT_STYLES.items():
            s = sel[sel["verdict"] == v]
            if len(s):
                ax.plot(s[k.name], s["value"], m, color=c, ls="none", label=v)
        ax.axhline(req.limit, color="k", ls="-.", lw=1, label=f"limit {req.limit:g} {unit}")
        if a is not None:
            ax.plot([a[k.name]], [a["value"]], "*", color="gold", mec="k", ms=15, zorder=5,
                    label="answer")
        ax.set_xscale("log")
        _log_ticks(ax.set_xticks, np.unique(sel[k.name]))
        ax.minorticks_off()
        ax.set_xlabel(f"{KNOBS[k.name].label} (cheaper: {k.info.cheaper})")
        ax.set_ylabel(f"{req.statistic} of {req.metric} [{unit}]")
    else:
        xk, yk = axes
        for v, (m, c) in VERDICT_STYLES.items():
            s = sl[sl["verdict"] == v]
            if len(s):
                ax.plot(s[xk.name], s[yk.name], m, color=c, ls="none", ms=6, label=v)
        table = sl.pivot_table(index=yk.name, columns=xk.name, values="hi")
        z = np.log(table.to_numpy(float))
        if np.nanmin(z) < np.log(req.limit) < np.nanmax(z):
            ax.contour(table.columns, table.index, z, levels=[np.log(req.limit)],
                       colors="tab:green", linewidths=1.5)
            ax.plot([], [], "-", color="tab:green", label="upper bound = limit")
        if a is not None:
            ax.plot([a[xk.name]], [a[yk.name]], "*", color="gold", mec="k", ms=16, zorder=5,
                    label=f"answer (limiting: {a['limiting']})")
        ax.set_xscale("log")
        ax.set_yscale("log")
        _log_ticks(ax.set_xticks, np.unique(sl[xk.name]))
        _log_ticks(ax.set_yticks, np.unique(sl[yk.name]))
        ax.minorticks_off()
        ax.set_xlabel(f"{KNOBS[xk.name].label} (cheaper: {xk.info.cheaper})")
        ax.set_ylabel(f"{KNOBS[yk.name].label} (cheaper: {yk.info.cheaper})")
        ax.grid(alpha=0.3)
    ax.set_title(title, fontsize=8)
    ax.legend(fontsize=7, loc="upper center", bbox_to_anchor=(0.5, -0.14), ncols=3,
              frameon=False)


def _plot_corners(ax: Any, problem: SizingProblem, rs: RelationSizing) -> None:
    """Parallel coordinates of the refined Pareto corners: each knob's position in its bounds."""
    free = [k for k in problem.knobs if k.free]
    corners = rs.corners
    if not len(corners):
        ax.text(0.5, 0.5, "no design within the bounds meets the spec", ha="center",
                va="center", transform=ax.transAxes)
        ax.set_axis_off()
        return
    x = np.arange(len(free))
    span = np.array([k.doublings(k.hi if k.info.cheaper == "smaller" else k.lo)
                     for k in free])
    cost = corners["cost"].to_numpy(float)
    cmin, cmax = cost.min(), max(cost.max(), cost.min() + 1e-9)
    for _, c in corners.sort_values("cheapest").iterrows():
        y = np.array([k.doublings(c[k.name]) for k in free]) / span
        if c["cheapest"]:
            ax.plot(x, y, "-o", color="k", lw=2.5, ms=5, label="answer", zorder=5)
            for xi, yi, k in zip(x, y, free, strict=True):
                ax.annotate(f"{c[k.name]:.3g}", (xi, yi), textcoords="offset points",
                            xytext=(4, 4), fontsize=7)
        else:
            shade = 0.2 + 0.6 * (c["cost"] - cmin) / (cmax - cmin)
            ax.plot(x, y, "-o", color=(shade, shade, 1.0), lw=1, ms=3)
    ax.set_xticks(x, [k.name for k in free], fontsize=8)
    ax.set_ylim(-0.05, 1.05)
    ax.set_ylabel("position in bounds\n(0 = cheapest, 1 = dearest, log)", fontsize=8)
    ax.set_title(f"{len(corners)} Pareto-minimal corners (darker = cheaper)", fontsize=8)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=7, loc="best")


def frontier_figure(result: SizingResult) -> Figure:
    """Per relation: the grid verdicts on a 2-D slice through the answer with the Pareto
    frontier (top) and the refined Pareto corners in every knob (bottom)."""
    rels = list(result.relations)
    fig = Figure(figsize=(5.6 * len(rels), 8.2), layout="constrained")
    axes = fig.subplots(2, len(rels), squeeze=False)
    for c, rel in enumerate(rels):
        _plot_slice(axes[0, c], result.problem, result.relations[rel], result.unit)
        _plot_corners(axes[1, c], result.problem, result.relations[rel])
    fig.suptitle(f"Sizing: {result.problem.requirement.describe(result.unit)}", fontsize=10)
    return fig


def format_result(result: SizingResult) -> str:
    """Plain-text summary for the terminal."""
    p, o = result.problem, result.options
    req = p.requirement
    lines = [f"requirement: {req.describe(result.unit)} (upper order-statistic bound)",
             "knobs: " + "; ".join(
                 f"{k.name} {k.lo:g}..{k.hi:g} (cheaper: {k.info.cheaper}, weight {k.weight:g})"
                 for k in p.knobs),
             "cost: " + (f"lexicographic in {', '.join(o.order)}" if o.order
                         else "weighted doublings")
             + f"; grid {o.levels} levels per knob, {o.trials} trials per point, seed {o.seed}, "
             f"bisection to {o.tolerance:.0%}, replication margin "
             f"{'on' if o.replication_margin else 'off'}, certification seed "
             f"{o.certification_seed}"]
    for rel, rs in result.relations.items():
        counts = rs.grid["verdict"].value_counts()
        lines += ["", f"== {RELATION_TEXT[rel]} ==",
                  f"grid: {len(rs.grid)} points: " + ", ".join(
                      f"{counts.get(v, 0)} {v}" for v in ("meets", "undecided", "fails",
                                                          "invalid"))
                  + f"; {rs.evaluations} evaluations in all"
                  + (f"; {rs.uncertified} corner(s) failed certification and were dropped"
                     if rs.uncertified else "")]
        a = rs.answer
        if a is None:
            grid_best = rs.grid.loc[rs.grid["hi"].fillna(np.inf).idxmin()]
            lines.append("no design within the bounds meets the spec; the best grid point: "
                         + ", ".join(f"{n}={grid_best[n]:.4g}" for n in p.names)
                         + f", {req.statistic} {_fmt(grid_best['value'])} "
                         f"[{_fmt(grid_best['lo'])}, {_fmt(grid_best['hi'])}] {result.unit}")
            if rs.best is not None:
                b = rs.best
                lines.append("  the best design found (coordinate search from it, lowest upper "
                             "bound): " + ", ".join(f"{n}={b[n]:.4g}" for n in p.names)
                             + f", {req.statistic} {_fmt(b['value'])} [{_fmt(b['lo'])}, "
                             f"{_fmt(b['hi'])}] {result.unit} (certification seed; search "
                             f"upper bound {_fmt(b['search_hi'])})")
            continue
        lines.append(f"{len(rs.corners)} Pareto-minimal corners; the cheapest:")
        lines.append("  " + ", ".join(f"{n} = {a[n]:.4g}" for n in p.names)
                     + f"  (cost {a['cost']:.3g})")
        lines.append(f"  certification: {req.statistic} = {_fmt(a['value'])} {result.unit}, "
                     f"{req.confidence:.0%} interval [{_fmt(a['lo'])}, {_fmt(a['hi'])}]: "
                     f"{a['verdict']} (search seed: {_fmt(a['search_value'])}, upper bound "
                     f"{_fmt(a['search_hi'])})")
        if isinstance(a["limiting"], str):
            lines.append(f"  limiting parameter: {a['limiting']} (its 10 % cheapening raises "
                         f"{req.statistic} most; {a['status']}; in the search "
                         f"{a['limiting']} = {a['bracket_bad']:.4g} did not pass)")
        else:
            lines.append(f"  limiting parameter: none ({a['status']})")
        if rs.confirmation is not None:
            for _, c in rs.confirmation.iterrows():
                what = "at the answer" if c["role"] == "answer" else (
                    f"10 % cheaper, {a['limiting']} = {c[a['limiting']]:.4g}")
                lines.append(f"  confirmation (seed {c['seed']}, {c['count']} trials) {what}: "
                             f"{req.statistic} = "
                             f"{_fmt(c['value'])} [{_fmt(c['lo'])}, {_fmt(c['hi'])}] "
                             f"{result.unit}: {c['verdict']}")
    return "\n".join(lines)


def render_report(result: SizingResult, figure_name: str = "frontier.png") -> str:
    """Markdown report: requirement, method, answers with confirmation, corners, plot."""
    p, o = result.problem, result.options
    req = p.requirement
    cols = [*p.names, "value", "lo", "hi", "verdict", "cost", "limiting", "status"]
    lines = ["# Sizing", "", f"Requirement: **{req.describe(result.unit)}**, judged on the upper "
             f"end of the {req.confidence:.0%} order-statistic interval of {req.statistic}.", "",
             "Knobs and cost directions:", ""]
    lines += [f"- `{k.name}` ({KNOBS[k.name].label}): {k.lo:g} .. {k.hi:g}, cheaper "
              f"{k.info.cheaper}, weight {k.weight:g}" for k in p.knobs]
    lines += ["", f"Search: {o.levels} geometric levels per knob, {o.trials} trials per point, "
              f"seed {o.seed}, common random numbers; every Pareto-minimal meeting grid point "
              f"bisected knob by knob to {o.tolerance:.0%}; limiting knob = the one whose 10 % "
              f"cheapening raises {req.statistic} most; replication margin "
              f"{'on' if o.replication_margin else 'off'}; every corner re-evaluated (certified) "
              f"with seed {o.certification_seed}; answers confirmed with an independent seed at "
              f"{o.confirm_trials or 4 * o.trials} trials; cost "
              + (f"lexicographic in {', '.join(o.order)}" if o.order else "weighted doublings")
              + ".", "", "## Answers", "", "```", format_result(result), "```", ""]
    for rel, rs in result.relations.items():
        lines += [f"## {RELATION_TEXT[rel]}", ""]
        if len(rs.corners):
            lines += [markdown_table(rs.corners[[*cols, "cheapest"]]), ""]
        else:
            lines += ["No design within the bounds meets the spec (after certification).", ""]
    lines += [f"![frontier]({figure_name})", ""]
    return "\n".join(lines)


def write_outputs(result: SizingResult, out_dir: Path) -> list[Path]:
    """grid-<relation>.csv, corners-<relation>.csv, answers.csv, frontier.png, report.md; each
    file written under a temporary name and renamed."""
    out_dir = Path(out_dir)
    written = []

    def put(name: str, data: bytes) -> None:
        atomic_write_bytes(out_dir / name, data)
        written.append(out_dir / name)

    for rel, rs in result.relations.items():
        put(f"grid-{rel}.csv", rs.grid.to_csv(index=False).encode())
        put(f"corners-{rel}.csv", rs.corners.to_csv(index=False).encode())
        if rs.confirmation is not None:
            put(f"confirmation-{rel}.csv", rs.confirmation.to_csv(index=False).encode())
    put("answers.csv", result.answers().to_csv(index=False).encode())
    written.append(save_figure(frontier_figure(result), out_dir / "frontier.png", dpi=90))
    put("report.md", render_report(result).encode())
    return written


def write_html_report(result: SizingResult, out_dir: Path) -> Path:
    """``report.html`` beside ``report.md``, the frontier plot inline with its caption (the PNG
    :func:`write_outputs` saved in ``out_dir``)."""
    from montecarlo.output.html_report import saved_figure, write_html

    req = result.problem.requirement
    relations = ", ".join(result.relations)
    caption = (f"{req.statistic} of `{req.metric}` ({req.variant} solver) [{result.unit}]: "
               f"top, each grid design's verdict ({req.confidence:.0%} order-statistic "
               f"interval of {req.statistic} against the limit {req.limit:g} {result.unit}) on "
               "a slice through the answer, with the boundary of 'meets'; bottom, the "
               "Pareto-minimal corners, each knob's position in its bounds (log, unitless). "
               f"Pixel relation between targets A and B: {relations} (one column each).")
    return write_html(out_dir, {"frontier.png": saved_figure(out_dir / "frontier.png", caption)},
                      "Sizing")
