"""What a budget run writes: the variance-share figure, text and Markdown reports, CSV tables."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import numpy as np
import pandas as pd
from matplotlib.figure import Figure

from montecarlo.design.budget import SOURCE_LABELS, SOURCE_UNITS, BudgetResult
from montecarlo.design.sizing_problem import RELATION_TEXT
from montecarlo.io.files import atomic_write_bytes, save_figure
from montecarlo.output.report import markdown_table


def budget_figure(results: Sequence[BudgetResult]) -> Figure:
    """Per relation: Sobol S1 and ST with their intervals (top); allocation beside what each
    source produces alone, with its interval (bottom)."""
    fig = Figure(figsize=(5.4 * len(results), 7.0), layout="constrained")
    axes = fig.subplots(2, len(results), squeeze=False)
    for c, r in enumerate(results):
        t = r.table
        x = np.arange(len(t))
        labels = [SOURCE_LABELS.get(s, s) for s in t.index]
        ax = axes[0, c]
        ax.bar(x - 0.2, t["S1"], 0.4, yerr=t["S1_conf"], capsize=3, label="first order S1")
        ax.bar(x + 0.2, t["ST"], 0.4, yerr=t["ST_conf"], capsize=3, label="total order ST")
        ax.set_xticks(x, labels, rotation=25, ha="right", fontsize=8)
        ax.set_ylabel(f"share of Var({r.requirement.metric})")
        ax.set_ylim(min(0.0, float((t["S1"] - t["S1_conf"]).min())) - 0.02, 1.05)
        ax.axhline(0.0, color="k", lw=0.6)
        ax.set_title(f"{RELATION_TEXT[r.relation].split(' (')[0]}\nSobol indices, "
                     f"{r.requirement.confidence:.0%} intervals (N = {r.samples})", fontsize=9)
        ax.legend(fontsize=7)
        ax.grid(alpha=0.3, axis="y")
        ax = axes[1, c]
        ax.bar(x - 0.2, t["allocation"], 0.4, color="0.6", label="allocation")
        err = np.vstack([(t["alone"] - t["alone_lo"]).fillna(0.0),
                         (t["alone_hi"] - t["alone"]).fillna(0.0)])
        ax.bar(x + 0.2, t["alone"], 0.4, yerr=err, capsize=3, color="tab:red",
               label=f"{r.requirement.statistic} alone")
        ax.set_xticks(x, labels, rotation=25, ha="right", fontsize=8)
        ax.set_ylabel(f"{r.requirement.statistic} of {r.requirement.metric} [{r.unit}]")
        ax.set_title(f"budget: limit {r.requirement.limit:g} {r.unit} split RSS by ST; design "
                     f"total {r.total['value']:.3g} {r.unit}", fontsize=9)
        ax.legend(fontsize=7)
        ax.grid(alpha=0.3, axis="y")
    return fig


def format_budget(result: BudgetResult) -> str:
    """Text table of one budget."""
    r = result
    t = r.table
    req = r.requirement
    point = ", ".join(f"{k} = {v:.4g}" for k, v in r.point.items()) or "base study"
    lines = [f"== {RELATION_TEXT[r.relation]} ==", f"design point: {point}",
             f"design total: {req.statistic} = {r.total['value']:.4g} {r.unit} "
             f"[{r.total['lo']:.4g}, {r.total['hi']:.4g}] vs limit {req.limit:g}: "
             f"{r.total['verdict']}",
             f"{'source':<22}{'distribution':<20}{'S1':>14}{'ST':>14}{'share':>7}"
             f"{'alloc':>8}{'alone':>8}  {'alone vs alloc':<15}{'scale for alloc':>15}"]
    for s, row in t.iterrows():
        lines.append(
            f"{SOURCE_LABELS.get(s, s):<22}{row['distribution']:<20}"
            f"{row['S1']:>7.3f}±{row['S1_conf']:<6.3f}{row['ST']:>7.3f}±{row['ST_conf']:<6.3f}"
            f"{row['share']:>7.3f}{row['allocation']:>8.3g}{row['alone']:>8.3g}  "
            f"{row['alone_verdict']:<15}{row['allowed_scale']:>11.3g} {SOURCE_UNITS[s]}")
    lines.append(f"sum S1 = {t['S1'].sum():.3f}, sum ST = {t['ST'].sum():.3f}; allocation "
                 f"RSS = {np.sqrt((t['allocation'] ** 2).sum()):.4g} {r.unit}; sources alone "
                 f"RSS = {np.sqrt((t['alone'] ** 2).sum()):.4g} {r.unit}")
    return "\n".join(lines)


def _explain(r: BudgetResult) -> list[str]:
    """Sentences read off the numbers of one budget."""
    t = r.table.sort_values("ST", ascending=False)
    top = t.index[0]
    s1, st = r.table["S1"].sum(), r.table["ST"].sum()
    over = [SOURCE_LABELS[s] for s, v in r.table["alone_verdict"].items() if v == "fails"]
    lines = [f"- Largest total-order share: {SOURCE_LABELS[top]} (ST = {t['ST'].iloc[0]:.3f} ± "
             f"{t['ST_conf'].iloc[0]:.3f}), then "
             + ", ".join(f"{SOURCE_LABELS[s]} ({v:.3f})" for s, v in t["ST"].iloc[1:].items())
             + ".",
             f"- Σ S1 = {s1:.3f} and Σ ST = {st:.3f}: "
             + ("the metric is close to additive in the sources."
                if abs(st - s1) < 0.05 else
                f"{1 - s1:.0%} of the variance comes from interactions (the rotation angle is "
                "the length of the error vector, not a sum of per-source terms).")]
    lines.append("- Sources whose output alone exceeds their allocation: "
                 + (", ".join(over) if over else "none") + ".")
    rss = float(np.sqrt((r.table["alone"] ** 2).sum()))
    lines.append(f"- Root-sum-square of the sources alone: {rss:.3g} {r.unit}, against the "
                 f"design total {r.total['value']:.3g} {r.unit}.")
    if r.total["verdict"] != "meets":
        lines.append(f"- The design does not meet the spec ({r.total['verdict']}): the rule "
                     "keeps today's proportions, so a dominant source takes nearly the whole "
                     "limit and the others are squeezed towards zero. Size the design first "
                     "(`montecarlo size`) and budget at its answer.")
    return lines


def render_budget_report(results: Sequence[BudgetResult], figure_name: str = "budget.png"
                         ) -> str:
    """Markdown report with the allocation rule, per-relation tables, explanations and plot."""
    r0 = results[0]
    req = r0.requirement
    lines = ["# Error budget", "",
             f"Metric: {req.statistic} of `{req.metric}` ({req.variant} solver), limit "
             f"{req.limit:g} {r0.unit}. Sobol indices from SALib (Saltelli scheme, N = "
             f"{r0.samples} base samples, "
             f"{req.confidence:.0%} bootstrap intervals, seed {r0.seed}); sources alone from the "
             f"study runner ({r0.trials} trials, {req.confidence:.0%} order-statistic intervals).",
             "",
             "Allocation rule: the limit is split in proportion to the total-order variance "
             "shares, RSS-consistent: share_i = ST_i / Σ ST, allocation_i = limit · √share_i, so "
             "√(Σ allocation_i²) = limit. *alone* is the statistic with every other source "
             "switched off; *scale for alloc* is the source's scale (σ or bound) that would use "
             "exactly its allocation (first order: scale · allocation / alone).", ""]
    for r in results:
        t = r.table.reset_index()
        t.insert(1, "label", [SOURCE_LABELS.get(s, s) for s in t["source"]])
        t["alone CI"] = [f"[{a:.3g}, {b:.3g}]" for a, b in zip(t["alone_lo"], t["alone_hi"],
                                                                strict=True)]
        cols = ["source", "label", "distribution", "S1", "S1_conf", "ST", "ST_conf", "share",
                "allocation", "alone", "alone CI", "alone_verdict", "allowed_scale"]
        point = ", ".join(f"{k} = {v:.4g}" for k, v in r.point.items()) or \
            "the base study's values"
        lines += [f"## {RELATION_TEXT[r.relation]}", "", f"Design point: {point}.", "",
                  f"Design total: {req.statistic} = {r.total['value']:.4g} {r.unit}, interval "
                  f"[{r.total['lo']:.4g}, {r.total['hi']:.4g}]: **{r.total['verdict']}**.", "",
                  markdown_table(t[cols]), "", *_explain(r), ""]
    lines += [f"![budget]({figure_name})", ""]
    return "\n".join(lines)


def write_budget(results: Sequence[BudgetResult], out_dir: Path) -> list[Path]:
    """budget-<relation>.csv, budget.png and report.md, each written atomically."""
    out_dir = Path(out_dir)
    written = []
    for name, data in [*((f"budget-{r.relation}.csv", r.table.to_csv().encode())
                         for r in results),
                       ("report.md", render_budget_report(results).encode())]:
        atomic_write_bytes(out_dir / name, data)
        written.append(out_dir / name)
    written.append(save_figure(budget_figure(results), out_dir / "budget.png", dpi=90))
    return written


def write_html_report(results: Sequence[BudgetResult], out_dir: Path) -> Path:
    """``report.html`` beside ``report.md``: a verdict table first, the budget plot inline as
    with its caption (the PNG :func:`write_budget` saved in ``out_dir``)."""
    from montecarlo.output.html_report import saved_figure, write_html

    req = results[0].requirement
    unit = results[0].unit
    verdicts = pd.DataFrame({
        "pixel relation": [r.relation for r in results],
        f"{req.statistic} [{unit}]": [r.total["value"] for r in results],
        "lo": [r.total["lo"] for r in results], "hi": [r.total["hi"] for r in results],
        "limit": [req.limit for _ in results],
        "verdict": [r.total["verdict"] for r in results]})
    md = render_budget_report(results)
    title, _, rest = md.partition("\n")
    md = "\n".join([title, "", "## Verdict of the design", "", markdown_table(verdicts), "",
                    rest])
    relations = ", ".join(r.relation for r in results)
    caption = (f"Top: first-order S1 and total-order ST Sobol indices of each error source's "
               f"share of Var(`{req.metric}`) (unitless), {req.confidence:.0%} bootstrap "
               f"intervals. Bottom: each source's allocation of the limit {req.limit:g} {unit} "
               f"beside the {req.statistic} of `{req.metric}` ({req.variant} solver) [{unit}] "
               f"that the source produces alone, with its {req.confidence:.0%} order-statistic "
               f"interval. Pixel relation between targets A and B: {relations} (one column "
               "each).")
    return write_html(out_dir, {"budget.png": saved_figure(out_dir / "budget.png", caption)},
                      "Error budget", md)
