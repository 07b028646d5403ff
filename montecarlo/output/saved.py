"""What a result directory keeps so that its plots and report can be drawn again.

``histograms.parquet`` holds the coarse histogram of every (grid point, variant, metric) [SI
units, radians]; ``provenance.json`` holds the study as given (``study_source``). With
``summary.parquet`` they rebuild the :class:`StudyResult` the plots and the report read, without
running a trial: ``montecarlo report DIR``.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from montecarlo.engine.aggregate import SPEC_COLUMNS, VALUE_COLUMNS, PointResult
from montecarlo.engine.runner import StudyResult
from montecarlo.errors import InputError
from montecarlo.io.files import PROVENANCE
from montecarlo.io.results import check_unchanged, read_parquet_table, read_provenance
from montecarlo.systems import study_from_dict

HISTOGRAMS = "histograms.parquet"
REDRAWN = ("plots", "report.md", "report.html")
"""What ``montecarlo report`` draws again: may be missing from a result it reads."""


def histogram_table(result: StudyResult) -> pd.DataFrame:
    """One row per occupied bin: ``point``, ``variant``, ``metric``, ``lower``, ``upper``
    [SI units], ``count``."""
    frames = [pd.DataFrame({"point": p, "variant": variant, "metric": metric,
                            "lower": lower, "upper": upper, "count": counts})
              for p, pr in enumerate(result.points)
              for (variant, metric), (lower, upper, counts) in pr.histograms.items()]
    columns = ["point", "variant", "metric", "lower", "upper", "count"]
    return pd.concat(frames, ignore_index=True) if frames else pd.DataFrame(columns=columns)


def load_result(path: str | Path, command: str = "report"
                ) -> tuple[StudyResult, pd.DataFrame, dict[str, Any]]:
    """The study result, summary (display units) and provenance saved in a result directory,
    every part checked before anything is drawn or written: the directory matches the list of
    files its run recorded (:func:`montecarlo.io.results.check_unchanged`), the study it saved
    builds the same grid, and the summary and histograms hold one row set per grid point with
    that study's variants and metrics.

    Raises
    ------
    InputError
        Not a result of ``montecarlo run``, one written before histograms were saved, one that
        was changed since it was written, or one whose files do not fit together.
    """
    path = Path(path)
    prov = read_provenance(path, "run", command)
    if "study_source" not in prov or not (path / HISTOGRAMS).exists():
        raise InputError(f"{path}: written by an older montecarlo without {HISTOGRAMS}; "
                         "run the study again")
    check_unchanged(path, prov, command, None if command == "report" else
                    ("summary.parquet", HISTOGRAMS), redrawn=REDRAWN)
    marker = path / PROVENANCE
    if not isinstance(prov["study_source"], dict):
        raise InputError(f"{marker}: study_source: not a table (got "
                         f"{type(prov['study_source']).__name__})")
    trials = prov.get("point_trials")
    if trials is not None and not (isinstance(trials, list) and all(
            isinstance(t, int) and not isinstance(t, bool) and t > 0 for t in trials)):
        raise InputError(f"{marker}: point_trials: not a list of positive whole numbers")
    try:
        study = study_from_dict(prov["study_source"], prov.get("study_path", "<study>"))
    except InputError as exc:
        raise InputError(f"{marker}: study_source: the saved study no longer reads ({exc})"
                         ) from None
    if trials:
        if len(trials) != len(study.points):
            raise InputError(f"{marker}: point_trials: {len(trials)} entries for "
                             f"{len(study.points)} grid points")
        study = study.with_trials(dict(enumerate(trials)))
    if study.hash() != prov.get("study_hash"):
        raise InputError(f"{path}: its study no longer builds the same grid with this version "
                         "of montecarlo; run the study again")
    summary = read_parquet_table(path / "summary.parquet",
                                 ["point", *study.sweep_keys, "variant", "metric", "unit"],
                                 numeric=[c for c in (*VALUE_COLUMNS, *SPEC_COLUMNS)],
                                 integer=["point"])
    bins = read_parquet_table(path / HISTOGRAMS,
                              ["point", "variant", "metric", "lower", "upper", "count"],
                              numeric=["lower", "upper"], integer=["point", "count"])
    expected = {(v, m.name) for v, m in study.metrics}
    for name, table in (("summary.parquet", summary), (HISTOGRAMS, bins)):
        outside = sorted(set(table["point"].astype(int)) - set(range(len(study.points))))
        if outside:
            raise InputError(f"{path / name}: point {outside[0]}: the study has "
                             f"{len(study.points)} grid points (0 to {len(study.points) - 1})")
    for p in range(len(study.points)):
        rows = summary[summary["point"] == p]
        found = list(zip(rows["variant"].astype(str), rows["metric"].astype(str), strict=True))
        if sorted(found) != sorted(expected):
            missing = sorted(expected - set(found)) or sorted(set(found) - expected) or \
                [next(r for r in found if found.count(r) > 1)]
            raise InputError(f"{path / 'summary.parquet'}: point {p}: rows do not match the "
                             f"study's variants and metrics (first {missing[0][0]}/"
                             f"{missing[0][1]}); the result was edited")
    unknown = set(zip(bins["variant"].astype(str), bins["metric"].astype(str), strict=True)) \
        - expected
    if unknown:
        v, m = sorted(unknown)[0]
        raise InputError(f"{path / HISTOGRAMS}: variant {v!r}, metric {m!r} is not one the "
                         "study computes; the result was edited")
    scale = {m.name: m.scale for _, m in study.metrics}
    values = [c for c in (*VALUE_COLUMNS, *SPEC_COLUMNS) if c in summary.columns]
    points = []
    for p in range(len(study.points)):
        rows = summary[summary["point"] == p].drop(columns=["point", *study.sweep_keys,
                                                            "unit"]).reset_index(drop=True)
        rows[values] = rows[values].div(rows["metric"].map(scale), axis=0)
        hist = {(v, m): (g["lower"].to_numpy(float), g["upper"].to_numpy(float),
                         g["count"].to_numpy(np.int64))
                for (v, m), g in bins[bins["point"] == p].groupby(["variant", "metric"],
                                                                   sort=False)}
        points.append(PointResult(rows, hist))
    result = StudyResult(study, points, resumed=prov.get("resumed") or {},
                         kernel=prov.get("kernel", "reference"),
                         workers=prov.get("workers"))
    return result, summary, prov
