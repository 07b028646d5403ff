"""The Markdown report of a study: assumptions, spec verdicts, summary table, plots."""

from __future__ import annotations

import math
from collections import Counter
from typing import Any

import pandas as pd

from montecarlo.engine.runner import StudyResult, workers_text
from montecarlo.output.plots import key_label, plot_metric


def _sampled_max_note(statistic: str, summary: pd.DataFrame) -> str:
    """What 'meets' says of a max over sampled trials (nothing for other statistics)."""
    if statistic != "max" or not (summary["sampling"] == "random").any():
        return ""
    return (" Over sampled trials, `meets` says that the largest trial drawn is within the "
            "limit: it bounds the share of all possible trials in the `bounds` column at the "
            "stated confidence, not every one of them; only enumerated corners give the "
            "worst case itself.")


def _where(result: StudyResult) -> str:
    """Where the trials of a run ran, as recorded (nothing if not recorded or none ran)."""
    n = result.workers
    if n is None or len(result.resumed.get("points", [])) == len(result.points):
        return ""
    return ", " + workers_text(n)


def markdown_table(frame: pd.DataFrame, floatfmt: str = ".4g") -> str:
    """A GitHub-flavoured Markdown table of a small frame."""

    def cell(v: Any) -> str:
        if isinstance(v, float):
            return "–" if math.isnan(v) else format(v, floatfmt)
        return str(v)

    head = "| " + " | ".join(str(c) for c in frame.columns) + " |"
    rule = "|" + "|".join("---" for _ in frame.columns) + "|"
    rows = ["| " + " | ".join(cell(v) for v in row) + " |"
            for row in frame.itertuples(index=False)]
    return "\n".join([head, rule, *rows])


def spec_verdicts(result: StudyResult, summary: pd.DataFrame) -> pd.DataFrame | None:
    """Per grid point and variant: the spec statistic, its interval and the verdict.

    The verdict is judged on the statistic over all trials, a trial without a value counting as
    larger than the limit (``spec_value``, ``spec_lo``, ``spec_hi`` of the summary): 'meets'
    needs the whole confidence interval at or below the limit, 'fails' the whole interval
    above; otherwise the trials do not decide ('undecided'). For max, mean, std and rms no interval
    is computed and the value alone decides; a sampled max comes with the fraction of all
    possible trials it bounds at the study's confidence (Wilks). Where the trials enumerate the
    worst-case corners, the statistic is exact and has no interval.
    """
    study = result.study
    spec = study.spec
    if spec is None:
        return None
    sel = summary[summary["verdict"].notna()] if "verdict" in summary else summary.iloc[:0]
    stat = spec.statistic
    judged = spec.statistic_label(study.metric(spec.metric).signed)
    out = sel[["point", *study.sweep_keys, "variant", "trials", "invalid_fraction"]].copy()
    if stat == "rms":  # sqrt(mean² + population variance) of the valid trials
        valid = (sel["mean"] ** 2 + sel["std"] ** 2 * (sel["count"] - 1) / sel["count"]) ** 0.5
    else:
        valid = sel[stat].abs() if judged != stat else sel[stat]
    out[f"{judged} (valid trials)"] = valid
    out[f"{judged} (all trials)"] = sel["spec_value"]
    if stat.startswith(("p", "cvar")):
        out[f"{stat} CI"] = [f"[{a:.4g}, {b:.4g}]" if sampling == "random" else "exact"
                             for a, b, sampling in zip(sel["spec_lo"], sel["spec_hi"],
                                                       sel["sampling"], strict=True)]
    if stat == "max" and (sel["sampling"] == "random").any():
        out[f"bounds ({study.header.confidence:.0%} conf.)"] = [
            f"≥ {c:.3%} of trials" if sampling == "random" else "all cases"
            for c, sampling in zip(sel["spec_coverage"], sel["sampling"], strict=True)]
    if (sel["sampling"] == "enumerated").any():
        out["trials are"] = sel["sampling"].map({"random": "sampled",
                                                 "enumerated": "all corners"})
    out["verdict"] = sel["verdict"]
    return out.rename(columns={k: key_label(k) for k in study.sweep_keys})


def nominal_table(result: StudyResult, summary: pd.DataFrame) -> pd.DataFrame:
    """One row per grid point and variant: every metric in the nominal case (each error
    source at its centre, one trial), in its display unit."""
    study = result.study
    keys = ["point", *study.sweep_keys, "variant"]
    wide = summary.pivot(index=["point", "variant"], columns="metric", values="nominal")
    units = {m.name: m.unit for _, m in study.metrics}
    names = [c for c in dict.fromkeys(m.name for _, m in study.metrics) if c in wide.columns]
    wide = wide[names].rename(columns={c: f"{c} [{units[c]}]" for c in names})
    table = summary.drop_duplicates(["point", "variant"])[keys].merge(
        wide.reset_index(), on=["point", "variant"])
    return table.rename(columns={k: key_label(k) for k in study.sweep_keys})


def nominal_section(result: StudyResult, summary: pd.DataFrame) -> list[str]:
    """The report's nominal-case section (the ``nominal`` column of the summary)."""
    table = nominal_table(result, summary)
    if table.drop(columns=table.columns[:len(result.study.sweep_keys) + 2]).isna().all().all():
        return ["## Nominal case", "",
                f"The {result.study.header.system} system draws quantities that have no centre "
                "(random signs or choices): it has no nominal case.", ""]
    return ["## Nominal case", "",
            "Every error source at its centre (the centre of a bounded or corner source, the "
            "mean of a normal, the median of a lognormal), one trial, no sampling: what the "
            "design gives without error (column `nominal` of the summary). With every error "
            "centred on zero it is zero; anything else points at the geometry.", "",
            markdown_table(table, ".4g"), ""]


def render_report(result: StudyResult, summary: pd.DataFrame, provenance: dict[str, Any],
                  plot_files: list[str]) -> str:
    study = result.study
    h = study.header
    metric = plot_metric(study)
    m = study.metric(metric)
    trials = sorted({p.trials for p in study.points})
    lines = [
        f"# Study `{h.name}`", "",
        h.description or "(no description)", "",
        f"- system: `{h.system}`; grid points: {len(study.points)}; trials per point: "
        f"{', '.join(str(t) for t in trials)}",
        f"- seed {h.seed}; common random numbers: {'yes' if h.common_random_numbers else 'no'}; "
        f"block size {study.block_size}; percentile intervals at {h.confidence:.0%} confidence",
        "- trials computed by the " + ("fast path (tested equal to the literal one)"
                                       if result.kernel == "fast" else
                                       "literal reference implementation") + _where(result),
        f"- study hash `{provenance['study_hash'][:16]}`; montecarlo "
        f"{provenance['package_version']}; commit `{provenance['git_commit']}`",
        "", "## Assumptions", "",
    ]
    described = Counter(line for p in study.points for line in study.system.describe(p.prepared))
    for line, count in described.items():
        suffix = "" if count == len(study.points) else f" ({count} of {len(study.points)} points)"
        lines.append(f"- {line}{suffix}")
    lines += ["", "Metrics (all in the outputs, each under its own name):", ""]
    for name, mm in dict.fromkeys((mm.name, mm) for _, mm in study.metrics):
        note = " (percentiles and max of the magnitude)" if mm.signed else ""
        lines.append(f"- `{name}`: {mm.label} [{mm.unit}]{note}")

    verdicts = spec_verdicts(result, summary)
    if verdicts is not None:
        spec = study.spec
        assert spec is not None
        lines += ["", "## Spec", "",
                  f"Requirement: {spec.statistic_label(study.metric(spec.metric).signed)} of "
                  f"`{spec.metric}`"
                  f"{' (' + spec.variant + ')' if spec.variant else ''} ≤ {spec.limit:g} "
                  f"{study.metric(spec.metric).unit}, judged over all trials: a trial "
                  "without a solution counts as exceeding the limit." + _sampled_max_note(
                      spec.statistic, summary), "",
                  markdown_table(verdicts), ""]

    cols = ["point", *study.sweep_keys, "variant", "count", "invalid", "sampling", "mean", "std",
            "p50", "p95", "p95_lo", "p95_hi", "p99", "cvar95", "max"]
    cols = [c for c in cols if c in summary]
    if (summary["invalid_fraction"] > 0).any():
        cols.insert(cols.index("invalid") + 1, "invalid_fraction")
    table = summary.loc[summary["metric"] == metric, cols].rename(
        columns={k: key_label(k) for k in study.sweep_keys})
    lines += ["", f"## Summary: {m.label} [{m.unit}]", "",
              "All metrics are in `summary.csv` / `summary.parquet`. Moments, percentiles and "
              "max are over the trials with a solution (`percentiles_over = valid`). Where the "
              "trials enumerate the worst-case corners (`sampling = enumerated`) the statistics "
              "are exact and have no confidence interval.", "",
              markdown_table(table), ""]

    if "nominal" in summary:
        lines += nominal_section(result, summary)

    inv = summary[summary["invalid"] > 0]
    if len(inv):
        reason_cols = [c for c in summary.columns if c.startswith("invalid_")]
        per = inv.drop_duplicates(["point", "variant"])[["point", "variant", "invalid",
                                                          *reason_cols]]
        lines += ["## Invalid trials", "",
                  "Trials whose geometry has no solution are counted here, never turned "
                  "into numbers.", "", markdown_table(per), ""]

    lines += ["## Plots", ""]
    for f in plot_files:
        lines += [f"![{f}](plots/{f})", ""]
    return "\n".join(lines)
