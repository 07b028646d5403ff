"""Compare two results of a study: per grid point, variant and metric, the difference of a
statistic, its confidence interval, and a verdict.

Two runs of the same study with the same seed and trials drew the same random numbers
(*paired*): any difference is the code's, so it is exact and judged against a relative
tolerance (default 1e-9, well above the 1e-12 by which the reference and fast paths differ).
Runs with different seeds or trials are *independent* samples: the difference's interval
combines the two runs' intervals as independent normal errors, so 'better' and 'worse' mean
the interval excludes zero. The intervals are simultaneous over the rows compared (Bonferroni:
each at confidence ``1 - (1 - c) / m`` for m rows), so that among many grid points and metrics
a 'worse' is not a chance finding at the study's confidence c. Every metric is an error:
smaller (in magnitude) is better.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
from scipy.special import ndtri

from montecarlo.engine.superquantile import CVAR_DEFAULT
from montecarlo.errors import InputError
from montecarlo.io.files import PROVENANCE

STATISTICS = ("mean", "std", "p50", "p90", "p95", "p99", CVAR_DEFAULT, "max")
"""What ``compare`` can compare: the summary columns; the percentiles and the superquantile
carry their own interval (``_lo``, ``_hi``)."""
VERDICTS = ("same", "better", "worse", "undecided")
"""'undecided': independent runs of a statistic that has no interval (max)."""
RTOL = 1e-9
"""Default relative tolerance of a paired comparison."""


@dataclass(frozen=True)
class Run:
    """A result directory of ``montecarlo run``: its summary and provenance."""

    path: Path
    summary: pd.DataFrame
    provenance: dict[str, Any]

    @property
    def name(self) -> str:
        return str(self.provenance.get("study"))

    @property
    def sweep_keys(self) -> list[str]:
        cols = list(self.summary.columns)
        return cols[cols.index("point") + 1: cols.index("variant")]


def load_run(path: str | Path) -> Run:
    """Read a result directory; a missing or foreign one is one line naming it."""
    path = Path(path)
    if not path.is_dir():
        raise InputError(f"{path}: no such result directory")
    try:
        prov = json.loads((path / PROVENANCE).read_text())
    except (OSError, ValueError):
        raise InputError(f"{path}: no readable {PROVENANCE}; not a result of "
                         "`montecarlo run`") from None
    kind = prov.get("kind") if isinstance(prov, dict) else None
    if kind != "run":
        raise InputError(f"{path}: a result of `montecarlo {kind}`, not of `montecarlo run`")
    try:
        summary = pd.read_parquet(path / "summary.parquet")
    except (OSError, ValueError):
        raise InputError(f"{path}: no readable summary.parquet") from None
    return Run(path, summary, prov)


def paired(a: Run, b: Run) -> bool:
    """True if both runs drew the same random numbers (same resolved study and seed)."""
    return a.provenance.get("study_hash") == b.provenance.get("study_hash")


def compare_runs(a: Run, b: Run, statistic: str = "p95", rtol: float = RTOL,
                 allow_different: bool = False) -> pd.DataFrame:
    """One row per grid point, variant and metric found in both runs: ``a``, ``b``, ``diff``
    (b - a), its interval ``diff_lo``, ``diff_hi``, ``rel_diff`` and ``verdict``.

    Raises
    ------
    InputError
        Different studies (name or grid) unless ``allow_different``; then rows are matched on
        the sweep values, variant and metric.
    """
    if statistic not in STATISTICS:
        raise InputError(f"--statistic: {statistic!r} is not one of {', '.join(STATISTICS)}")
    keys = a.sweep_keys
    if not allow_different and (a.name != b.name or keys != b.sweep_keys
                                or not a.summary[keys].equals(b.summary[keys])):
        raise InputError(f"{a.path} and {b.path} are results of different studies "
                         f"({a.name} and {b.name}, or different grids); add "
                         "--allow-different to match their common grid points")
    on = [*[k for k in keys if k in b.sweep_keys], "variant", "metric"]
    cols = list(dict.fromkeys(["unit", "sampling", "count", statistic, "std",
                               *([f"{statistic}_lo", f"{statistic}_hi"]
                                 if statistic not in ("mean", "std", "max") else [])]))
    left = a.summary[["point", *on, *[c for c in cols if c in a.summary]]]
    right = b.summary[[*on, *[c for c in cols if c in b.summary]]]
    rows = left.merge(right, on=on, suffixes=("_a", "_b"))
    if rows.empty:
        raise InputError(f"{a.path} and {b.path} have no grid point in common")
    same_draws = paired(a, b)
    confidence = confidence_of(a)
    z = float(ndtri(0.5 + confidence / 2.0))  # of each run's own intervals
    va, vb = rows[f"{statistic}_a"].to_numpy(float), rows[f"{statistic}_b"].to_numpy(float)
    diff = vb - va
    exact = same_draws | ((rows["sampling_a"] == "enumerated")
                          & (rows["sampling_b"] == "enumerated")).to_numpy()
    se = np.sqrt(_se(rows, statistic, "a", z) ** 2 + _se(rows, statistic, "b", z) ** 2)
    z_all = simultaneous_z(confidence, int((~exact).sum()))
    lo = np.where(exact, diff, diff - z_all * se)
    hi = np.where(exact, diff, diff + z_all * se)
    tolerance = rtol * np.maximum(np.abs(va), np.abs(vb))
    smaller = np.abs(vb) < np.abs(va)
    verdict = np.where(
        exact, np.where(np.abs(diff) <= tolerance, "same", np.where(smaller, "better", "worse")),
        np.where(np.isnan(lo) | np.isnan(hi), "undecided",
                 np.where((lo <= 0.0) & (hi >= 0.0), "same",
                          np.where(smaller, "better", "worse"))))
    both_nan = np.isnan(va) & np.isnan(vb)
    verdict = np.where(both_nan, "same", verdict)
    out = rows[["point", *on]].copy()
    out["unit"], out["statistic"] = rows["unit_a"], statistic
    out["a"], out["b"], out["diff"], out["diff_lo"], out["diff_hi"] = va, vb, diff, lo, hi
    with np.errstate(divide="ignore", invalid="ignore"):
        out["rel_diff"] = np.where(va != 0.0, diff / np.abs(va), np.nan)
    out["comparison"] = np.where(exact, "paired", "independent")
    out["verdict"] = verdict
    return out.reset_index(drop=True)


def confidence_of(run: Run) -> float:
    """The confidence level of a run's study (its intervals' and the comparison's)."""
    return float(run.provenance.get("resolved_study", {}).get("study", {})
                 .get("confidence", 0.95))


def simultaneous_z(confidence: float, m: int) -> float:
    """Half-width of the simultaneous intervals of ``m`` rows in standard errors (Bonferroni):
    each row's two-sided interval at confidence ``1 - (1 - c) / m``, i.e.
    ``z = Phi^-1(1 - (1 - c) / (2 m))`` (m = 1 gives the plain 1.95996 at c = 0.95; m < 1 is
    read as 1)."""
    m = max(int(m), 1)
    return float(ndtri(1.0 - (1.0 - confidence) / (2.0 * m)))


def _se(rows: pd.DataFrame, statistic: str, side: str, z: float) -> np.ndarray:
    """Standard error of one run's statistic (NaN where none can be given); the interval of a
    percentile (distribution-free) or of the superquantile (asymptotically normal, widened by
    its bin bounds) at the study's confidence is read as +-z standard errors.

    ``mean``: s / sqrt(n). ``std``: s / sqrt(2 (n - 1)), the large-sample standard error of a
    sample standard deviation of normal data (from var(s^2) = 2 sigma^4 / (n - 1) and the delta
    method, se(s) = se(s^2) / (2 sigma)); for other distributions it is approximate."""
    n = rows[f"count_{side}"].to_numpy(float)
    std = rows[f"std_{side}"].to_numpy(float)
    with np.errstate(divide="ignore", invalid="ignore"):
        if statistic == "mean":
            return std / np.sqrt(n)
        if statistic == "std":
            return std / np.sqrt(2.0 * np.maximum(n - 1.0, 0.0))
        if statistic == "max":
            return np.full(len(rows), math.nan)
        width = rows[f"{statistic}_hi_{side}"].to_numpy(float) - \
            rows[f"{statistic}_lo_{side}"].to_numpy(float)
        return width / (2.0 * z)


def verdict_counts(table: pd.DataFrame) -> dict[str, int]:
    counts = table["verdict"].value_counts()
    return {v: int(counts.get(v, 0)) for v in VERDICTS}
