"""Write a study's results to ``results/<study>/``, all or nothing.

Everything is written into a temporary sibling directory which then replaces the old results, so
a crash never leaves half-written results behind.
"""

from __future__ import annotations

import json
import shutil
import tempfile
from dataclasses import asdict
from pathlib import Path

import pandas as pd

from montecarlo.engine.runner import RunOptions, StudyResult
from montecarlo.io.files import with_umask
from montecarlo.output.plots import all_figures
from montecarlo.output.provenance import provenance
from montecarlo.output.report import render_report


def write_outputs(result: StudyResult, out_dir: Path, options: RunOptions) -> Path:
    """Write summary.csv/.parquet, trials.parquet (if kept), provenance.json, plots, report.md."""
    study = result.study
    out_dir = Path(out_dir)
    out_dir.parent.mkdir(parents=True, exist_ok=True)
    tmp = Path(tempfile.mkdtemp(dir=out_dir.parent, prefix=f".{out_dir.name}.tmp-"))
    tmp.chmod(with_umask(0o777))  # mkdtemp makes it private; results are meant to be shared
    try:
        summary = result.to_frame()
        summary.to_csv(tmp / "summary.csv", index=False)
        summary.to_parquet(tmp / "summary.parquet", index=False)
        if result.trials:
            pd.concat(result.trials.values(), ignore_index=True).to_parquet(
                tmp / "trials.parquet", index=False)
        options_record = {k: str(v) if isinstance(v, Path) else v
                          for k, v in asdict(options).items()}
        prov = provenance(study.hash(), study.header.seed, study.resolved(), options_record)
        (tmp / "provenance.json").write_text(json.dumps(prov, indent=2, default=str))
        (tmp / "plots").mkdir()
        names = []
        for name, fig in all_figures(result, summary):
            fig.savefig(tmp / "plots" / name, dpi=110)
            names.append(name)
        (tmp / "report.md").write_text(render_report(result, summary, prov, names))
        old = None
        if out_dir.exists():
            old = Path(tempfile.mkdtemp(dir=out_dir.parent, prefix=f".{out_dir.name}.old-"))
            out_dir.rename(old / "results")
        tmp.rename(out_dir)
        if old is not None:
            shutil.rmtree(old, ignore_errors=True)
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
    return out_dir
