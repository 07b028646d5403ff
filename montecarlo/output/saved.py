"""What a result directory keeps so that its plots and report can be drawn again.

``histograms.parquet`` holds the coarse histogram of every (grid point, variant, metric) [SI
units, radians]; ``provenance.json`` holds the study as given (``study_source``). With
``summary.parquet`` they rebuild the :class:`StudyResult` the plots and the report read, without
running a trial: ``montecarlo report DIR``.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from montecarlo.engine.aggregate import SPEC_COLUMNS, VALUE_COLUMNS, PointResult
from montecarlo.engine.runner import StudyResult
from montecarlo.errors import InputError
from montecarlo.io.files import PROVENANCE
from montecarlo.systems import study_from_dict

HISTOGRAMS = "histograms.parquet"


def histogram_table(result: StudyResult) -> pd.DataFrame:
    """One row per occupied bin: ``point``, ``variant``, ``metric``, ``lower``, ``upper``
    [SI units], ``count``."""
    frames = [pd.DataFrame({"point": p, "variant": variant, "metric": metric,
                            "lower": lower, "upper": upper, "count": counts})
              for p, pr in enumerate(result.points)
              for (variant, metric), (lower, upper, counts) in pr.histograms.items()]
    columns = ["point", "variant", "metric", "lower", "upper", "count"]
    return pd.concat(frames, ignore_index=True) if frames else pd.DataFrame(columns=columns)


def load_result(path: str | Path) -> tuple[StudyResult, pd.DataFrame, dict[str, Any]]:
    """The study result, summary (display units) and provenance saved in a result directory.

    Raises
    ------
    InputError
        Not a result of ``montecarlo run``, or one written before histograms were saved.
    """
    path = Path(path)
    try:
        prov = json.loads((path / PROVENANCE).read_text())
    except (OSError, ValueError):
        raise InputError(f"{path}: no readable {PROVENANCE}; not a result of "
                         "`montecarlo run`") from None
    if not isinstance(prov, dict) or prov.get("kind") != "run":
        raise InputError(f"{path}: not a result of `montecarlo run`")
    if "study_source" not in prov or not (path / HISTOGRAMS).exists():
        raise InputError(f"{path}: written by an older montecarlo without {HISTOGRAMS}; "
                         "run the study again")
    try:
        summary = pd.read_parquet(path / "summary.parquet")
        bins = pd.read_parquet(path / HISTOGRAMS)
    except (OSError, ValueError) as exc:
        raise InputError(f"{path}: unreadable results ({exc})") from None
    study = study_from_dict(prov["study_source"], prov.get("study_path", "<study>"))
    if prov.get("point_trials"):  # grown by --until-decided
        study = study.with_trials(dict(enumerate(prov["point_trials"])))
    if study.hash() != prov.get("study_hash"):
        raise InputError(f"{path}: its study no longer builds the same grid with this version "
                         "of montecarlo; run the study again")
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
