"""Nightly regression check: Table 1 reproduction and the trends of seed 000, section 1.4.

Runs ``studies/table1.toml`` and ``studies/trends.toml``, checks

* every worst-case (corner) value of Table 1 within 1 % of the paper;
* under pixel error common to both targets: Delta falls with the range L, falls with the height
  difference H up to 2 m (the paper: "H matters below 2 m, little above"), rises with the pixel
  error df and with the height-scale error delta_b;
* under independent pixel noise: Delta rises with L (the L trend reverses,
docs/reference/conventions.md);

for both solver variants, on the mean and the p95 of the true rotation angle; and that nothing
changed since the previous nightly run (:mod:`montecarlo.output.compare`: with the same study
files the runs are paired, so any difference beyond 1e-9 is the code's; after a study file
changed they are independent samples, judged on their intervals, and a sampled max, which has
none, is undecided rather than changed). Appends the numbers
behind every check (value, unit, interval, expected range) to ``results/nightly/history.csv``,
plots them in ``plots/history.png``, writes ``report.md`` and exits non-zero if any check fails.
"""

from __future__ import annotations

import datetime as dt
import io
import json
import math
import shutil
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
from matplotlib.figure import Figure

from montecarlo import __version__
from montecarlo.engine.checkpoints import Checkpoints
from montecarlo.engine.runner import RunOptions, run_study
from montecarlo.errors import InputError
from montecarlo.io.files import PROVENANCE, OutputDir, atomic_write_bytes
from montecarlo.output.compare import compare_runs, load_run, paired, verdict_counts
from montecarlo.output.outputs import write_outputs
from montecarlo.output.plots import key_label
from montecarlo.output.provenance import git_commit, provenance
from montecarlo.output.report import markdown_table
from montecarlo.seed000.table1 import TABLE1_ROWS
from montecarlo.systems import load_study

TABLE1_TOLERANCE = 0.01
TREND_BASE = {"geometry.L_m": 100.0, "geometry.H_m": 2.0, "errors.pixel_px.bound": 0.5,
              "errors.dh_m.bound": 0.001}
"""The point around which studies/trends.toml varies one factor at a time."""


@dataclass(frozen=True)
class Check:
    """A pass/fail check, its value and expectation as text, and the numbers behind it."""

    name: str
    passed: bool
    value: str
    expected: str
    numbers: tuple[dict[str, Any], ...] = ()
    """History rows: ``quantity``, ``value``, ``unit``, ``ci_lo``, ``ci_hi``, ``expected_lo``,
    ``expected_hi`` (NaN where there is none)."""


def _number(quantity: str, value: float, unit: str, ci: tuple[float, float] = (math.nan,) * 2,
            expected: tuple[float, float] = (math.nan,) * 2) -> dict[str, Any]:
    return {"quantity": quantity, "value": value, "unit": unit, "ci_lo": ci[0], "ci_hi": ci[1],
            "expected_lo": expected[0], "expected_hi": expected[1]}


def table1_checks(summary: pd.DataFrame) -> list[Check]:
    """Worst-case max of the Table 1 metric against each printed value, within 1 %."""
    worst = summary[(summary["errors.evaluation"] == "worst_case")
                    & (summary["metric"] == "table1_angle")]
    checks = []
    for i, row in enumerate(TABLE1_ROWS, start=1):
        sel = worst[(worst["errors.pixel_px.bound"] == row.df_px)
                    & (worst["geometry.L_m"] == row.L_m) & (worst["geometry.H_m"] == row.H_m)
                    & np.isclose(worst["errors.dh_m.bound"], row.db_mm * 1e-3)]
        for variant, paper in (("raw", row.paper_delta_mrad),
                               ("normalised", row.paper_norm_delta_mrad)):
            ours = float(sel.loc[sel["variant"] == variant, "max"].iloc[0])
            rel = ours / paper - 1.0
            band = (paper * (1 - TABLE1_TOLERANCE), paper * (1 + TABLE1_TOLERANCE))
            checks.append(Check(f"table1 row {i} {variant}", abs(rel) <= TABLE1_TOLERANCE,
                                f"{ours:.3f} mrad ({rel:+.2%})",
                                f"{paper:.2f} mrad ± {TABLE1_TOLERANCE:.0%}",
                                (_number("max of table1_angle over the corners", ours, "mrad",
                                         (ours, ours), band),)))
    return checks


def _line(summary: pd.DataFrame, factor: str, values: list[float], relation: str,
          variant: str, stat: str) -> pd.DataFrame:
    """The summary rows along one factor with the others at the base point, in ``values``'
    order."""
    sel = summary[(summary["metric"] == "rotation_angle") & (summary["variant"] == variant)
                  & (summary["errors.pixel_relation"] == relation)]
    for key, base in TREND_BASE.items():
        if key != factor:
            sel = sel[np.isclose(sel[key], base)]
    return pd.concat([sel[np.isclose(sel[factor], v)].iloc[:1] for v in values])


def _interval(row: pd.Series, stat: str) -> tuple[float, float]:
    """The 95 % interval of a summary row's mean (normal) or percentile (order statistics)."""
    if stat == "mean":
        half = 1.959963984540054 * row["std"] / math.sqrt(row["count"])
        return row["mean"] - half, row["mean"] + half
    return row[f"{stat}_lo"], row[f"{stat}_hi"]


TREND_CHECKS = (
    # (label, factor, values, relation, expected direction)
    ("falls with L", "geometry.L_m", [50.0, 100.0, 200.0, 400.0], "common", "falls"),
    ("falls with H (up to 2 m)", "geometry.H_m", [0.5, 1.0, 2.0], "common", "falls"),
    ("rises with df", "errors.pixel_px.bound", [0.25, 0.5, 1.0, 2.0], "common", "rises"),
    ("rises with delta_b", "errors.dh_m.bound", [0.0005, 0.001, 0.005, 0.02], "common", "rises"),
    ("rises with L", "geometry.L_m", [50.0, 100.0, 200.0, 400.0], "independent", "rises"),
)


def trend_checks(summary: pd.DataFrame) -> list[Check]:
    """Direction of each trend, for both variants, on the mean and the p95."""
    checks = []
    for label, factor, values, relation, direction in TREND_CHECKS:
        for variant in ("raw", "normalised"):
            for stat in ("mean", "p95"):
                rows = _line(summary, factor, values, relation, variant, stat)
                y = rows[stat].to_numpy(float)
                steps = np.diff(y)
                ok = bool(np.all(steps < 0) if direction == "falls" else np.all(steps > 0))
                name = key_label(factor).split(" [")[0]
                numbers = tuple(_number(f"{stat} of rotation_angle at {name} = {v:g}", yi,
                                        "mrad", _interval(row, stat))
                                for v, yi, (_, row) in zip(values, y, rows.iterrows(),
                                                           strict=True))
                checks.append(Check(
                    f"{relation} pixel error: Delta {label} ({variant}, {stat})", ok,
                    " → ".join(f"{v:.3f}" for v in y) + " mrad",
                    f"{direction} over {', '.join(f'{v:g}' for v in values)}", numbers))
    return checks


def change_check(name: str, previous: Path, summary_dir: Path, accept: bool) -> Check | None:
    """Whether ``name``'s results changed since the previous nightly run (None if there is no
    previous result to compare with)."""
    if not (previous / name / PROVENANCE).exists():
        return None
    a, b = load_run(previous / name), load_run(summary_dir)
    try:
        table = compare_runs(a, b, "mean")
        for stat in ("p95", "max"):
            table = pd.concat([table, compare_runs(a, b, stat)], ignore_index=True)
    except InputError as exc:
        return Check(f"{name}: unchanged since the previous nightly", accept,
                     f"not comparable ({exc})", "the same results")
    counts = verdict_counts(table)
    changed = counts["better"] + counts["worse"]
    same_draws = paired(a, b)
    mode = "paired" if same_draws else "independent (the study file changed)"
    commit = a.provenance.get("git_commit")
    moved = table[table["verdict"].isin(["better", "worse"])]
    worst = moved.loc[moved["rel_diff"].abs().idxmax()] if changed else None
    value = f"{changed} of {len(table)} statistics changed ({counts['worse']} worse)" + (
        f"; largest {worst['rel_diff']:+.3%} ({worst['statistic']} of {worst['metric']}, "
        f"{worst['variant']}, point {worst['point']})" if worst is not None else "") + (
        f"; {counts['undecided']} undecided (a sampled max has no interval)"
        if counts["undecided"] else "")
    return Check(f"{name}: unchanged since the previous nightly (commit {commit}, {mode})",
                 changed == 0 or accept, value + (" — accepted" if changed and accept else ""),
                 "no change beyond 1e-9 (relative)" if same_draws else
                 "no difference outside its simultaneous interval",
                 (_number("statistics changed since the previous nightly", changed, "rows",
                          expected=(0.0, 0.0)),))


HISTORY_COLUMNS = ["timestamp_utc", "git_commit", "package_version", "check", "passed",
                   "quantity", "value", "unit", "ci_lo", "ci_hi", "expected_lo", "expected_hi"]


def append_history(path: Path, checks: list[Check], stamp: str, commit: str | None) -> None:
    """Append the numbers of every check to the history CSV (rewritten atomically)."""
    new = pd.DataFrame([{"timestamp_utc": stamp, "git_commit": commit,
                         "package_version": __version__, "check": c.name, "passed": c.passed,
                         **number} for c in checks for number in c.numbers],
                       columns=HISTORY_COLUMNS)
    old = pd.read_csv(path) if path.exists() else None
    table = new if old is None else pd.concat([old, new], ignore_index=True)
    buffer = io.StringIO()
    table.to_csv(buffer, index=False)
    atomic_write_bytes(path, buffer.getvalue().encode())


def history_figure(history: pd.DataFrame) -> Figure:
    """The Table 1 values of every nightly run, relative to the paper, with the tolerance."""
    t1 = history[history["check"].str.startswith("table1 row")].copy()
    runs = list(dict.fromkeys(t1["timestamp_utc"]))
    t1["run"] = t1["timestamp_utc"].map({r: i for i, r in enumerate(runs)})
    mid = (t1["expected_lo"] + t1["expected_hi"]) / 2.0
    t1["deviation"] = (t1["value"] / mid - 1.0) * 100.0
    fig = Figure(figsize=(9.0, 4.0), layout="constrained")
    axes = fig.subplots(1, 2, sharey=True)
    for ax, variant in zip(axes, ("raw", "normalised"), strict=True):
        sel = t1[t1["check"].str.endswith(variant)]
        for i, (check, rows) in enumerate(sel.groupby("check", sort=False)):
            ax.plot(rows["run"], rows["deviation"], "-o", ms=3, color=f"C{i}",
                    label=check.replace("table1 ", "").replace(f" {variant}", ""))
        ax.axhspan(-TABLE1_TOLERANCE * 100, TABLE1_TOLERANCE * 100, color="g", alpha=0.1,
                   label=f"± {TABLE1_TOLERANCE:.0%}")
        ax.axhline(0.0, color="k", lw=0.8)
        ax.set_title(f"Table 1, {variant} solver", fontsize=9)
        ax.set_xlabel("nightly run")
        ax.set_xticks(range(len(runs)), [r[5:16].replace("T", " ") for r in runs], rotation=45,
                      fontsize=7)
        ax.grid(alpha=0.3)
    axes[0].set_ylabel("worst case − paper [% of the paper's value]")
    axes[0].legend(fontsize=7, ncols=2)
    fig.suptitle("Nightly history: Table 1 against the paper", fontsize=10)
    return fig


def run_nightly(studies_dir: Path = Path("studies"), out_dir: Path = Path("results/nightly"),
                n_jobs: int | None = None, progress: bool = True, accept_changes: bool = False
                ) -> tuple[bool, list[Check]]:
    """Run the nightly studies and checks; returns (all passed, checks).

    ``out_dir`` is replaced as a whole (it must be absent, empty or an earlier nightly result);
    its ``history.csv`` is carried forward with this run's rows appended, and its results are
    what this run is compared with (``accept_changes``: a change does not fail the run).
    """
    checkpoint_root = out_dir.parent / ".checkpoints"
    options = RunOptions(n_jobs=n_jobs, progress=progress, checkpoint_dir=checkpoint_root)
    target = OutputDir(out_dir, "nightly")
    with target as staging:
        summaries = {}
        for name in ("table1", "trends"):
            study = load_study(studies_dir / f"{name}.toml")
            result = run_study(study, options)
            (staging / name).mkdir()
            write_outputs(result, staging / name, options)
            Checkpoints(checkpoint_root, study).remove()
            summaries[name] = result.to_frame()
        checks = table1_checks(summaries["table1"]) + trend_checks(summaries["trends"])
        if target.previous is not None:
            for name in summaries:
                change = change_check(name, target.previous, staging / name, accept_changes)
                if change is not None:
                    checks.append(change)
        stamp = dt.datetime.now(dt.UTC).isoformat(timespec="seconds")
        commit = git_commit()
        if target.previous is not None:
            _carry_history(target.previous, staging)
        append_history(staging / "history.csv", checks, stamp, commit)
        (staging / "plots").mkdir()
        history_figure(pd.read_csv(staging / "history.csv")).savefig(
            staging / "plots" / "history.png", dpi=110)
        passed = all(c.passed for c in checks)
        table = pd.DataFrame([{"check": c.name, "value": c.value, "expected": c.expected,
                               "result": "pass" if c.passed else "**FAIL**"} for c in checks])
        report = "\n".join([
            "# Nightly regression check", "",
            f"{stamp}, montecarlo {__version__}, commit `{commit}`: "
            f"**{'all checks passed' if passed else 'REGRESSION'}** "
            f"({sum(c.passed for c in checks)} of {len(checks)} checks pass).", "",
            "Delta is the Table 1 metric arccos((1 + tr D)/4) for the Table 1 rows (worst case "
            "over the 64 corners) and the true rotation angle of D for the trends (sampled, "
            "common random numbers; `trends/report.md`).", "",
            markdown_table(table), "",
            "History: `history.csv` (the numbers behind every check, every run) and "
            "`plots/history.png`. Study outputs: `table1/`, `trends/`.", "",
            "![history](plots/history.png)", ""])
        atomic_write_bytes(staging / "report.md", report.encode())
        atomic_write_bytes(staging / PROVENANCE, json.dumps(provenance(
            "nightly", studies=str(studies_dir), passed=passed), indent=2).encode())
    return passed, checks


def _carry_history(previous: Path, staging: Path) -> None:
    """Carry the previous run's history forward; one in an older layout (text values) is kept
    beside the new one as ``history_text.csv`` rather than mixed into it."""
    for name in ("history.csv", "history_text.csv"):
        if not (previous / name).exists():
            continue
        old = pd.read_csv(previous / name, nrows=0)
        if name == "history.csv" and list(old.columns) != HISTORY_COLUMNS:
            shutil.copy(previous / name, staging / "history_text.csv")
        else:
            shutil.copy(previous / name, staging / name)
