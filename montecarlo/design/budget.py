"""Error-budget allocation at a design point: Sobol variance shares and a split of the spec.

For a ground-calibration design (seed 000, section 1) and one pixel relation, each error source's
share of the variance of the chosen metric is estimated with Sobol indices (SALib, Saltelli's
scheme without second-order terms, bootstrap confidence intervals):

* first order ``S1_i = Var(E[Y | X_i]) / Var(Y)``: the share that source i explains alone;
* total order ``ST_i = E[Var(Y | X_~i)] / Var(Y)``: its share including every interaction.

The sources are the placement errors ``dx_m``, ``dy_m``, ``dh1_m``, the height-scale error
``dh_m`` (the paper's delta_b) and the pixel error ``pixel_px`` (one group: both image axes, and
for independent noise both targets). Fixed sources are not varied; corner (worst-case) sources
have no variance and are refused.

The budget table splits the spec limit among the sources **in proportion to their total-order
variance share, root-sum-square consistent**::

    share_i = ST_i / sum_j ST_j,     allocation_i = limit * sqrt(share_i),
    so that sqrt(sum_i allocation_i**2) = limit.

Beside each allocation stands what the source produces *alone* (every other source switched off),
run through the study runner with the requirement's percentile and its confidence interval, and
the scale of that source that would use exactly its allocation (``scale * allocation / alone``,
first order: a lone small error source moves the metric in proportion to its scale).

The RSS rule is exact for the variances of independent additive contributions; the rotation
angle is the length of the error vector, not a sum, so ``sum S1 < 1`` there (interactions), and a
percentile of a sum is not the RSS of the percentiles. The table is a planning aid for where to
spend money, not a second verdict: the verdict on the whole design is the study's.
"""

from __future__ import annotations

import io
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
from matplotlib.figure import Figure
from SALib.analyze import sobol as sobol_analyze
from SALib.sample import sobol as sobol_sample

from montecarlo.design.sizing import (
    RELATION_TEXT,
    Requirement,
    design_overrides,
    ground_study,
    run_statistic,
    verdicts,
    write_file,
)
from montecarlo.engine.distributions import Distribution
from montecarlo.errors import InputError
from montecarlo.output.report import markdown_table
from montecarlo.seed000 import ground
from montecarlo.systems.ground import MOUNTING_SOURCES, PLACEMENT_SOURCES, PreparedGround

SOURCE_LABELS = {
    "dx_m": "lateral placement δx",
    "dy_m": "range placement δy",
    "dh1_m": "height reference δh1",
    "dh_m": "height scale δb",
    "pixel_px": "pixel error",
}
SOURCE_UNITS = {"dx_m": "m", "dy_m": "m", "dh1_m": "m", "dh_m": "m", "pixel_px": "px"}


def _seeds(rng: int | np.random.Generator | None) -> tuple[np.random.Generator, int]:
    """Independent streams for the Sobol sample (a Generator) and SALib's bootstrap (an int > 0,
    as SALib treats seed 0 as 'unseeded')."""
    if isinstance(rng, np.random.Generator):
        seq = np.random.SeedSequence(int(rng.integers(2**63)))
    else:
        seq = np.random.SeedSequence(rng)
    sample_seq, boot_seq = seq.spawn(2)
    boot = int(boot_seq.generate_state(1, np.uint64)[0] % np.uint64(2**62)) + 1
    return np.random.Generator(np.random.PCG64(sample_seq)), boot


def sobol_indices(problem: Mapping[str, Any], model: Callable[[np.ndarray], np.ndarray], n: int,
                  rng: int | np.random.Generator | None = None, confidence: float = 0.95,
                  resamples: int = 200) -> pd.DataFrame:
    """First- and total-order Sobol indices with SALib, with bootstrap confidence intervals.

    Parameters
    ----------
    problem : mapping
        SALib problem: ``num_vars``, ``names``, ``bounds``, optional ``dists`` and ``groups``.
    model : callable
        ``model(X)`` for the sample matrix ``X`` of shape (m, num_vars) returns shape (m,).
    n : int
        Base sample size, a power of 2; the model is evaluated ``n (G + 2)`` times for G
        variables or groups.
    rng : int, Generator or None
        Seeds the scrambled Sobol sequence and the bootstrap.
    confidence : float
        Level of the intervals; ``S1_conf``, ``ST_conf`` are their half-widths.
    resamples : int
        Bootstrap resamples.

    Returns
    -------
    DataFrame indexed by variable (or group) name, columns S1, S1_conf, ST, ST_conf.
    """
    if n < 2 or n & (n - 1):
        raise InputError(f"samples: the Sobol base sample size must be a power of 2 (got {n})")
    sample_rng, boot_seed = _seeds(rng)
    problem = dict(problem)
    x = sobol_sample.sample(problem, n, calc_second_order=False, seed=sample_rng)
    y = np.asarray(model(x), float)
    bad = np.count_nonzero(~np.isfinite(y))
    if bad:
        raise InputError(f"{bad} of {y.size} model evaluations have no valid solution; Sobol "
                         f"indices need the design to be solvable everywhere in its error bounds")
    si = sobol_analyze.analyze(problem, y, calc_second_order=False, conf_level=confidence,
                               num_resamples=resamples, seed=boot_seed)
    names = list(dict.fromkeys(problem.get("groups") or problem["names"]))
    return pd.DataFrame({k: np.asarray(si[k], float) for k in ("S1", "S1_conf", "ST", "ST_conf")},
                        index=pd.Index(names, name="source"))


def _pixel_columns(relation: str) -> tuple[str, ...]:
    return ("pixel_x", "pixel_z") if relation == "common" else \
        ("pixel_a_x", "pixel_a_z", "pixel_b_x", "pixel_b_z")


def _salib_dist(name: str, d: Distribution) -> tuple[str, list[float]]:
    if d.kind == "uniform":
        return "unif", [d.location - d.scale, d.location + d.scale]
    if d.kind == "normal":
        return "norm", [d.location, d.scale]
    raise InputError(f"{name}: a budget needs uniform or normal error sources (got {d.kind}); "
                     f"corners are a worst case and have no variance")


@dataclass(frozen=True)
class GroundBudgetModel:
    """The ground calibration as a function of its random error sources, for SALib.

    ``columns`` are the sample-matrix columns: placement sources by name, pixel errors as
    ``pixel_x``/``pixel_z`` (common to both targets) or ``pixel_a_x`` ... ``pixel_b_z``
    (independent); ``groups`` maps each column to its source.
    """

    prepared: PreparedGround
    relation: str
    metric: str
    variant: str
    columns: tuple[str, ...]
    groups: tuple[str, ...]
    dists: tuple[str, ...]
    bounds: tuple[tuple[float, float], ...]

    @classmethod
    def from_prepared(cls, prepared: PreparedGround, relation: str, metric: str, variant: str
                      ) -> GroundBudgetModel:
        for name, d in zip(MOUNTING_SOURCES, prepared.mounting, strict=True):
            if d.kind != "fixed":
                raise InputError(f"mounting.{name}: a budget needs fixed true mounting angles "
                                 f"(got {d.kind})")
        columns, groups, dists, bounds = [], [], [], []
        for name in PLACEMENT_SOURCES:
            d = prepared.placement[name]
            if d.kind == "fixed" or d.scale == 0.0:
                continue
            dist, b = _salib_dist(f"errors.{name}", d)
            columns.append(name)
            groups.append(name)
            dists.append(dist)
            bounds.append(tuple(b))
        if prepared.pixel.kind != "fixed" and prepared.pixel.scale != 0.0:
            dist, b = _salib_dist("errors.pixel_px", prepared.pixel)
            for col in _pixel_columns(relation):
                columns.append(col)
                groups.append("pixel_px")
                dists.append(dist)
                bounds.append(tuple(b))
        if len(set(groups)) < 2:
            raise InputError("errors: a budget needs at least two random error sources "
                             f"(got {', '.join(dict.fromkeys(groups)) or 'none'})")
        return cls(prepared, relation, metric, variant, tuple(columns), tuple(groups),
                   tuple(dists), tuple(bounds))  # type: ignore[arg-type]

    def salib_problem(self) -> dict[str, Any]:
        return {"num_vars": len(self.columns), "names": list(self.columns),
                "groups": list(self.groups), "dists": list(self.dists),
                "bounds": [list(b) for b in self.bounds]}

    def __call__(self, x: np.ndarray) -> np.ndarray:
        """Metric [rad] of each row of the sample matrix ``x``, shape (m,); NaN if invalid."""
        p = self.prepared
        col = {name: x[:, i] for i, name in enumerate(self.columns)}

        def value(name: str, fallback: float) -> Any:
            return col.get(name, fallback)

        px0 = p.pixel.location
        if self.relation == "common":
            pix_a = np.stack([value("pixel_x", px0) * np.ones(len(x)),
                              value("pixel_z", px0) * np.ones(len(x))], -1)
            pix_b = pix_a
        else:
            pix_a = np.stack([value("pixel_a_x", px0) * np.ones(len(x)),
                              value("pixel_a_z", px0) * np.ones(len(x))], -1)
            pix_b = np.stack([value("pixel_b_x", px0) * np.ones(len(x)),
                              value("pixel_b_z", px0) * np.ones(len(x))], -1)
        place = {n: value(n, p.placement[n].location) for n in PLACEMENT_SOURCES}
        true = tuple(d.location for d in p.mounting)
        sol = ground.simulate(p.camera, true, p.L, p.H, dx=place["dx_m"], dy=place["dy_m"],
                              dh1=place["dh1_m"], dh=place["dh_m"], pixel_error_a=pix_a,
                              pixel_error_b=pix_b, solvers=(self.variant,))[self.variant]
        return ground.solution_metrics(sol, true)[self.metric]


def allocate(total_order: pd.Series, limit: float) -> pd.DataFrame:
    """Split ``limit`` in proportion to the total-order shares, RSS-consistent.

    Negative estimates (noise around 0) count as 0. Returns columns ``share`` (sums to 1) and
    ``allocation`` (``limit * sqrt(share)``, whose root-sum-square is ``limit``).
    """
    st = total_order.clip(lower=0.0)
    if not st.sum() > 0:
        raise ValueError("no source has a positive total-order index")
    share = st / st.sum()
    return pd.DataFrame({"share": share, "allocation": limit * np.sqrt(share)})


def _describe_source(raw: Mapping[str, Any], unit: str) -> str:
    match raw.get("dist"):
        case "uniform":
            return f"uniform ±{raw['bound']:.3g} {unit}"
        case "normal":
            return f"normal σ {raw['sigma']:.3g} {unit}"
        case "corners":
            return f"corners ±{raw['bound']:.3g} {unit}"
    return f"fixed {raw.get('value', 0.0):.3g} {unit}"


def _scale_of(raw: Mapping[str, Any]) -> float:
    return float(raw.get("sigma", raw.get("bound", raw.get("value", 0.0))))


@dataclass
class BudgetResult:
    """Sobol indices and the budget table of one design point and pixel relation.

    ``table`` has one row per source (index) with: distribution, S1, S1_conf, ST, ST_conf,
    share, allocation, alone, alone_lo, alone_hi, alone_verdict (alone vs allocation), scale,
    allowed_scale; ``total`` holds the whole design's statistic, interval and verdict.
    """

    relation: str
    requirement: Requirement
    point: dict[str, float]
    unit: str
    table: pd.DataFrame
    total: pd.Series
    samples: int
    evaluations: int
    seed: int
    trials: int


def budget(base: Mapping[str, Any], requirement: Requirement, relation: str,
           point: Mapping[str, float] | None = None, *, samples: int = 8192, seed: int = 0,
           trials: int = 20000, resamples: int = 200, n_jobs: int = 2,
           block_size: int = 4096) -> BudgetResult:
    """Sobol indices of every random error source and the budget table at a design point.

    Parameters
    ----------
    base : mapping
        Ground study (parsed TOML, sweeps ignored).
    requirement : Requirement
        Metric, solver variant, percentile, limit [display unit] and confidence (used for the
        Sobol intervals and the percentile intervals).
    relation : {"common", "independent"}
    point : mapping, optional
        Sizing knobs (``L_m``, ``H_m``, ``pixel_px``, ``survey_m``, ``scale_m``) to set.
    samples : int
        Sobol base sample size (power of 2).
    seed : int
        Seeds the Sobol sample, the bootstrap and the study runs.
    trials : int
        Trials of each study run (the design and each source alone).
    """
    point = dict(point or {})
    req = requirement
    design = design_overrides(base, point)

    def study(overrides: Sequence[Mapping[str, Any]], name: str) -> Any:
        return ground_study(base, req, overrides, relation, trials=trials, seed=seed,
                            block_size=block_size, name=name)

    one = study([design], "budget-design")
    metric = one.metric(req.metric)
    gp = one.points[0]
    model = GroundBudgetModel.from_prepared(gp.prepared, relation, req.metric, req.variant)
    indices = sobol_indices(model.salib_problem(), model, samples, rng=seed,
                            confidence=req.confidence, resamples=resamples)
    sources = list(indices.index)
    raw = {s: gp.config.errors.model_dump(mode="json")[s] for s in sources}
    keys = [f"errors.{s}" for s in sources]
    rows = [{**design, **{k: raw[s] for k, s in zip(keys, sources, strict=True)}}]
    for s in sources:
        rows.append({**design, **{k: raw[t] if t == s else 0.0
                                  for k, t in zip(keys, sources, strict=True)}})
    stats = run_statistic(study(rows, "budget-alone"), req, n_jobs)
    table = indices.join(allocate(indices["ST"], req.limit))
    table.insert(0, "distribution", [_describe_source(raw[s], SOURCE_UNITS[s]) for s in sources])
    alone = stats.iloc[1:].set_index(pd.Index(sources))
    table["alone"] = alone["value"]
    table["alone_lo"] = alone["lo"]
    table["alone_hi"] = alone["hi"]
    table["alone_verdict"] = [verdicts(a["value"], a["lo"], a["hi"], a["invalid"], lim)[()]
                              for (_, a), lim in zip(alone.iterrows(), table["allocation"],
                                                     strict=True)]
    table["scale"] = [_scale_of(raw[s]) for s in sources]
    table["allowed_scale"] = table["scale"] * table["allocation"] / table["alone"]
    total = stats.iloc[0].copy()
    evaluations = samples * (len(sources) + 2)
    return BudgetResult(relation, req, point, metric.unit, table, total, samples, evaluations,
                        seed, trials)


# --- report and plot ---------------------------------------------------------------------------


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
    out_dir.mkdir(parents=True, exist_ok=True)
    written = [write_file(out_dir / f"budget-{r.relation}.csv", r.table.to_csv().encode())
               for r in results]
    buf = io.BytesIO()
    budget_figure(results).savefig(buf, format="png", dpi=90)
    written.append(write_file(out_dir / "budget.png", buf.getvalue()))
    written.append(write_file(out_dir / "report.md", render_budget_report(results).encode()))
    return written
