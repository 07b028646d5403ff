"""Nightly regression check: Table 1 reproduction and the trends of seed 000, section 1.4.

Runs ``studies/table1.toml`` and ``studies/trends.toml``, checks

* every worst-case (corner) value of Table 1 within 1 % of the paper;
* under pixel error common to both targets: Delta falls with the range L, falls with the height
  difference H up to 2 m (the paper: "H matters below 2 m, little above"), rises with the pixel
  error df and with the height-scale error delta_b;
* under independent pixel noise: Delta rises with L (the L trend reverses, docs/conventions.md);

for both solver variants, on the mean and the p95 of the true rotation angle. Appends one row
per check to ``results/nightly/history.csv``, writes ``results/nightly/report.md`` and exits
non-zero if any check fails.
"""

from __future__ import annotations

import datetime as dt
import io
import json
import shutil
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd

from montecarlo import __version__
from montecarlo.engine.checkpoints import Checkpoints
from montecarlo.engine.runner import RunOptions, run_study
from montecarlo.io.files import PROVENANCE, OutputDir, atomic_write_bytes
from montecarlo.output.outputs import write_outputs
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
    name: str
    passed: bool
    value: str
    expected: str


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
            checks.append(Check(f"table1 row {i} {variant}", abs(rel) <= TABLE1_TOLERANCE,
                                f"{ours:.3f} mrad ({rel:+.2%})",
                                f"{paper:.2f} mrad ± {TABLE1_TOLERANCE:.0%}"))
    return checks


def _line(summary: pd.DataFrame, factor: str, values: list[float], relation: str,
          variant: str, stat: str) -> np.ndarray:
    """The statistic along one factor with the others at the base point."""
    sel = summary[(summary["metric"] == "rotation_angle") & (summary["variant"] == variant)
                  & (summary["errors.pixel_relation"] == relation)]
    for key, base in TREND_BASE.items():
        if key != factor:
            sel = sel[np.isclose(sel[key], base)]
    return np.array([float(sel.loc[np.isclose(sel[factor], v), stat].iloc[0]) for v in values])


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
                y = _line(summary, factor, values, relation, variant, stat)
                steps = np.diff(y)
                ok = bool(np.all(steps < 0) if direction == "falls" else np.all(steps > 0))
                checks.append(Check(
                    f"{relation} pixel error: Delta {label} ({variant}, {stat})", ok,
                    " → ".join(f"{v:.3f}" for v in y) + " mrad",
                    f"{direction} over {', '.join(f'{v:g}' for v in values)}"))
    return checks


def append_history(path: Path, checks: list[Check], stamp: str, commit: str | None) -> None:
    """Append one row per check to the history CSV (rewritten atomically)."""
    new = pd.DataFrame([{"timestamp_utc": stamp, "git_commit": commit,
                         "package_version": __version__, "check": c.name, "value": c.value,
                         "expected": c.expected, "passed": c.passed} for c in checks])
    old = pd.read_csv(path) if path.exists() else None
    table = new if old is None else pd.concat([old, new], ignore_index=True)
    buffer = io.StringIO()
    table.to_csv(buffer, index=False)
    atomic_write_bytes(path, buffer.getvalue().encode())


def run_nightly(studies_dir: Path = Path("studies"), out_dir: Path = Path("results/nightly"),
                n_jobs: int | None = None, progress: bool = True) -> tuple[bool, list[Check]]:
    """Run the nightly studies and checks; returns (all passed, checks).

    ``out_dir`` is replaced as a whole (it must be absent, empty or an earlier nightly result);
    its ``history.csv`` is carried forward with this run's rows appended.
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
        stamp = dt.datetime.now(dt.UTC).isoformat(timespec="seconds")
        commit = git_commit()
        if target.previous is not None and (target.previous / "history.csv").exists():
            shutil.copy(target.previous / "history.csv", staging / "history.csv")
        append_history(staging / "history.csv", checks, stamp, commit)
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
            "History: `history.csv`. Study outputs: `table1/`, `trends/`.", ""])
        atomic_write_bytes(staging / "report.md", report.encode())
        atomic_write_bytes(staging / PROVENANCE, json.dumps(provenance(
            "nightly", studies=str(studies_dir), passed=passed), indent=2).encode())
    return passed, checks
