"""Captions of a study's plots for the HTML report: metric, statistic, unit, pixel relation."""

from __future__ import annotations

from pathlib import Path

from montecarlo.engine.runner import StudyResult
from montecarlo.engine.study import Study
from montecarlo.output.plots import key_label, plot_metric

RELATION_KEY = "errors.pixel_relation"


def pixel_relation_text(study: Study) -> str:
    """How the pixel errors of the two targets relate in this study (or why it does not say)."""
    relations = [getattr(gp.prepared, "relation", None) for gp in study.points]
    if any(r is None for r in relations):
        return (f"Pixel relation: not applicable (the {study.header.system} system has no "
                "pair of target images).")
    names = list(dict.fromkeys("correlation ρ = " + format(r, "g") if isinstance(r, float)
                               else str(r) for r in relations))
    if RELATION_KEY in study.sweep_keys or len(names) > 1:
        return "Pixel relation between targets A and B: swept (" + ", ".join(names) + ")."
    return f"Pixel relation between targets A and B: {names[0]}."


def _metric_text(study: Study) -> tuple[str, str]:
    metric = plot_metric(study)
    m = study.metric(metric)
    of = " (percentiles and max of its magnitude)" if m.signed else ""
    return f"{m.label} (`{metric}`) [{m.unit}]{of}", m.unit


def _spec_text(study: Study) -> str:
    s = study.spec
    if s is None:
        return ""
    m = study.metric(s.metric)
    return (f" Spec: {s.statistic_label(m.signed)} of `{s.metric}`"
            f"{' (' + s.variant + ')' if s.variant else ''} ≤ {s.limit:g} {m.unit}.")


def figure_caption(result: StudyResult, name: str) -> str:
    """The caption of one of :func:`montecarlo.output.plots.all_figures`' figures by name."""
    study = result.study
    what, unit = _metric_text(study)
    ci = f"{study.header.confidence:.0%}"
    pixel = pixel_relation_text(study)
    stem = Path(name).stem
    if stem.startswith("trend_"):
        key = next((k for k in study.sweep_keys if stem == "trend_" + k.replace(".", "_")),
                   stem[6:])
        return (f"{what} against {key_label(key)}. Statistics over the trials with a "
                f"solution: p50 (line or dot), p95 (band, dashed line or bar end), p99 (dotted), "
                f"max (×); error bars: the {ci} distribution-free confidence interval of p95 "
                f"(an arrow up where the trials are too few to bound it above), in {unit}. "
                f"{pixel}{_spec_text(study)}")
    if stem == "histograms":
        return (f"Distribution of {what} at each grid point: the fraction of all trials per "
                f"bin (trials without a solution are in no bin), x axis in {unit}; dashed: "
                f"p95 of each solver variant. {pixel}{_spec_text(study)}")
    if stem == "map_L_H":
        stat = study.spec.statistic if study.spec else "p95"
        over = " over all trials (no solution counted as ∞)" if study.spec else ""
        return (f"{stat} of {what}{over}, over range L [m] × height difference H [m]; colour "
                f"and numbers in {unit}, red contour at the spec limit. {pixel}"
                f"{_spec_text(study)}")
    if stem == "map_sync_survey":
        stat = study.spec.statistic if study.spec else "p95"
        return (f"{stat} of {what} over lever-arm knowledge [m] × master time-tag offset [s], "
                f"one panel per value of the other swept keys; colour and numbers in {unit}, "
                f"red contour at the spec limit. {_spec_text(study)}")
    return f"{what}. {pixel}{_spec_text(study)}"
