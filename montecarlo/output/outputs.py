"""Write a study's results into a directory (the staging directory of an ``OutputDir``).

``montecarlo run`` writes into a hidden sibling of ``results/<study>/`` and renames it into place
when everything is written (:class:`montecarlo.io.files.OutputDir`), so a crash never leaves
half-written results and a directory that is not an earlier result is never replaced.
"""

from __future__ import annotations

import json
from dataclasses import asdict
from pathlib import Path

import pandas as pd

from montecarlo.engine.runner import RunOptions, StudyResult
from montecarlo.io.files import PROVENANCE
from montecarlo.output.plots import all_figures
from montecarlo.output.provenance import study_provenance
from montecarlo.output.report import render_report


def write_outputs(result: StudyResult, out_dir: Path, options: RunOptions) -> Path:
    """Write summary.csv/.parquet, trials.parquet (if kept), provenance.json, plots, report.md."""
    out_dir = Path(out_dir)
    summary = result.to_frame()
    summary.to_csv(out_dir / "summary.csv", index=False)
    summary.to_parquet(out_dir / "summary.parquet", index=False)
    if result.trials:
        pd.concat(result.trials.values(), ignore_index=True).to_parquet(
            out_dir / "trials.parquet", index=False)
    options_record = {k: str(v) if isinstance(v, Path) else v
                      for k, v in asdict(options).items()}
    prov = study_provenance(result, options_record)
    (out_dir / PROVENANCE).write_text(json.dumps(prov, indent=2, default=str))
    (out_dir / "plots").mkdir()
    names = []
    for name, fig in all_figures(result, summary):
        fig.savefig(out_dir / "plots" / name, dpi=110)
        names.append(name)
    (out_dir / "report.md").write_text(render_report(result, summary, prov, names))
    return out_dir
