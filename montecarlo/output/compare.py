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
from montecarlo.io.results import check_unchanged, read_parquet_table, read_provenance

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
    """Read a result directory of ``montecarlo run``, checked before it is compared: its
    provenance (:func:`~montecarlo.io.results.read_provenance`), its summary unchanged since the
    run wrote it (:func:`~montecarlo.io.results.check_unchanged`) and of the expected columns
    and types. Anything else is one line naming the directory, the file and the field."""
    path = Path(path)
    prov = read_provenance(path, "run", "compare")
    check_unchanged(path, prov, "compare", ("summary.parquet",))
    marker = path / PROVENANCE
    resolved = prov.get("resolved_study", {})
    header = resolved.get("study", {}) if isinstance(resolved, dict) else None
    spec = resolved.get("spec") if isinstance(resolved, dict) else None
    if not isinstance(header, dict) or not (spec is None or isinstance(spec, dict)):
        raise InputError(f"{marker}: resolved_study: not the tables `montecarlo run` writes")
    confidence = header.get("confidence", 0.95)
    if isinstance(confidence, bool) or not isinstance(confidence, (int, float)) \
            or not 0.0 < confidence < 1.0:
        raise InputError(f"{marker}: resolved_study.study.confidence: {confidence!r} is not a "
                         "number in (0, 1)")
    if spec is not None and spec.get("statistic", "p95") not in STATISTICS:
        raise InputError(f"{marker}: resolved_study.spec.statistic: {spec.get('statistic')!r} "
                         f"is not one of {', '.join(STATISTICS)}")
    numeric = [c for s in STATISTICS for c in (s, f"{s}_lo", f"{s}_hi")]
    summary = read_parquet_table(path / "summary.parquet",
                                 ["point", "variant", "metric", "unit", "count", "std"],
                                 numeric=numeric, integer=["point", "count"])
    columns = list(summary.columns)
    if columns.index("variant") < columns.index("point"):
        raise InputError(f"{path / 'summary.parquet'}: columns out of order (the sweep keys "
                         "lie between 'point' and 'variant')")
    return Run(path, summary, prov)


def paired(a: Run, b: Run) -> bool:
    """True if both runs drew the same random numbers (same resolved study and seed)."""
    return a.provenance.get("study_hash") == b.provenance.get("study_hash")


def _canonical(value: Any) -> str:
    """A sweep value as a text that is equal for equal values however they were stored (2 and
    2.0, a list and an array, a table in any key order)."""
    def plain(v: Any) -> Any:
        if isinstance(v, (bool, np.bool_)):
            return bool(v)
        if isinstance(v, (int, float, np.integer, np.floating)):
            return float(v)
        if isinstance(v, (list, tuple, np.ndarray)):
            return [plain(x) for x in v]
        if isinstance(v, dict):
            return {str(k): plain(x) for k, x in v.items()}
        return v
    return json.dumps(plain(value), sort_keys=True, default=str)


def _config_value(run: Run, point: int, key: str) -> Any:
    """The value of the dotted ``key`` in the resolved configuration of grid point ``point``
    of ``run`` (what the study ran with, defaults filled in); KeyError if it has none."""
    points = run.provenance.get("resolved_study", {}).get("points")
    if not isinstance(points, list) or not 0 <= point < len(points):
        raise KeyError(key)
    node: Any = points[point].get("config") if isinstance(points[point], dict) else None
    for part in key.split("."):
        if not isinstance(node, dict) or part not in node:
            raise KeyError(key)
        node = node[part]
    return node


def grid_values(run: Run, keys: list[str], other: Run) -> pd.DataFrame:
    """One row per row of ``run``'s summary: the value of every key of ``keys`` (as
    :func:`_canonical` text), from the resolved configuration of its grid point where the
    provenance has it, else from the summary's own sweep column.

    Raises
    ------
    InputError
        A key (a sweep key of ``other``) whose value in ``run`` cannot be told.
    """
    columns: dict[str, Any] = {}
    points = run.summary["point"]
    first = run.summary.groupby("point", sort=False).head(1)  # a row of each grid point
    for key in keys:
        values: dict[int, str] = {}
        for row, p in zip(first.index, first["point"], strict=True):
            try:
                values[p] = _canonical(_config_value(run, int(p), key))
            except KeyError:
                if key not in run.sweep_keys:
                    raise InputError(f"{run.path}: {PROVENANCE}: resolved_study has no value "
                                     f"of {key!r} (a sweep key of {other.path}), so its rows "
                                     "cannot be matched") from None
                values[p] = _canonical(run.summary.at[row, key])
        columns[key] = points.map(values)
    return pd.DataFrame(columns, index=run.summary.index)


def match_rows(a: Run, b: Run) -> tuple[pd.DataFrame, pd.DataFrame, pd.DataFrame, list[str]]:
    """Rows of ``a`` and ``b`` that are the same grid point, variant and metric: matched on
    every sweep key of both runs (a key only one run sweeps is taken at its fixed value in the
    other), so a row matches at most one row. Returns the pairs (``row_a``, ``row_b``, index
    into each summary), the rows of ``a`` only and of ``b`` only (their ``point``, keys,
    ``variant``, ``metric``), and the keys.

    Raises
    ------
    InputError
        A run whose summary has two rows for one grid point, variant and metric (a row would be
        paired twice), or a key whose value in a run cannot be told.
    """
    keys = list(dict.fromkeys([*a.sweep_keys, *b.sweep_keys]))
    sides = []
    for run, other in ((a, b), (b, a)):
        frame = grid_values(run, keys, other)
        frame["variant"] = run.summary["variant"].astype(str)
        frame["metric"] = run.summary["metric"].astype(str)
        repeated = frame.duplicated(keep=False)
        if repeated.any():
            row = frame[repeated].iloc[0]
            raise InputError(f"{run.path}: summary.parquet: two rows for one grid point "
                             f"({', '.join(f'{k}={row[k]}' for k in keys) or 'the base point'}, "
                             f"variant {row['variant']}, metric {row['metric']}); cannot pair "
                             "them")
        sides.append(frame.assign(row=np.arange(len(frame))))
    on = [*keys, "variant", "metric"]
    merged = sides[0].merge(sides[1], on=on, how="outer", suffixes=("_a", "_b"),
                            indicator=True)
    pairs = merged[merged["_merge"] == "both"].sort_values("row_a")

    def only(side: str, run: Run) -> pd.DataFrame:
        column = "row_a" if side == "left" else "row_b"
        picked = merged[merged["_merge"] == f"{side}_only"].sort_values(column)
        rows = picked[column].astype(int).to_numpy()
        shown = run.summary.iloc[rows][["point", "variant", "metric"]].reset_index(drop=True)
        for i, k in enumerate(keys):  # as the run's summary shows it, else its resolved value
            values = run.summary[k].iloc[rows].to_numpy() if k in run.sweep_keys else \
                [json.loads(v) for v in picked[k]]
            shown.insert(1 + i, k, values)
        return shown

    return (pairs[["row_a", "row_b"]].astype(int).reset_index(drop=True),
            only("left", a), only("right", b), keys)


def compare_runs(a: Run, b: Run, statistic: str = "p95", rtol: float = RTOL,
                 allow_different: bool = False) -> pd.DataFrame:
    """One row per grid point, variant and metric found in both runs: ``point`` (of ``a``),
    every sweep key of both runs, ``variant``, ``metric``, ``a``, ``b``, ``diff`` (b - a), its
    interval ``diff_lo``, ``diff_hi``, ``rel_diff`` and ``verdict``. Rows are matched by
    :func:`match_rows` (each at most once); :func:`match_rows` also gives the rows of one run
    only.

    Raises
    ------
    InputError
        Different studies (name or grid) unless ``allow_different``; no row in common.
    """
    if statistic not in STATISTICS:
        raise InputError(f"--statistic: {statistic!r} is not one of {', '.join(STATISTICS)}")
    keys = a.sweep_keys
    if not allow_different and (a.name != b.name or keys != b.sweep_keys
                                or not a.summary[keys].equals(b.summary[keys])):
        raise InputError(f"{a.path} and {b.path} are results of different studies "
                         f"({a.name} and {b.name}, or different grids); add "
                         "--allow-different to match their common grid points")
    pairs, _, _, keys = match_rows(a, b)
    if pairs.empty:
        raise InputError(f"{a.path} and {b.path} have no grid point in common")
    cols = list(dict.fromkeys(["unit", "sampling", "count", statistic, "std",
                               *([f"{statistic}_lo", f"{statistic}_hi"]
                                 if statistic not in ("mean", "std", "max") else [])]))
    left = a.summary.iloc[pairs["row_a"].to_numpy()].reset_index(drop=True)
    right = b.summary.iloc[pairs["row_b"].to_numpy()].reset_index(drop=True)
    for k in keys:  # a key one run does not sweep: its fixed value, as the other run's column
        if k not in left:
            left[k] = right[k]
    on = [*keys, "variant", "metric"]
    rows = pd.concat([left[["point", *on]],
                      left[[c for c in cols if c in left]].add_suffix("_a"),
                      right[[c for c in cols if c in right]].add_suffix("_b")], axis=1)
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
