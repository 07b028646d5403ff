"""Write a study's results into a directory (the staging directory of an ``OutputDir``), and
draw its plots and report again from what it saved.

``montecarlo run`` writes into a hidden sibling of ``results/<study>/`` and renames it into place
when everything is written (:class:`montecarlo.io.files.OutputDir`), so a crash never leaves
half-written results and a directory that is not an earlier result is never replaced.
"""

from __future__ import annotations

import json
import shutil
import tempfile
from dataclasses import asdict
from pathlib import Path
from typing import Any

import pandas as pd

from montecarlo.engine.runner import RunOptions, StudyResult
from montecarlo.io.files import PROVENANCE, atomic_write_bytes
from montecarlo.output.captions import figure_caption
from montecarlo.output.html_report import HtmlFigure, figure_svg, write_html
from montecarlo.output.plots import all_figures
from montecarlo.output.provenance import study_provenance
from montecarlo.output.report import render_report
from montecarlo.output.saved import HISTOGRAMS, histogram_table, load_result


def write_outputs(result: StudyResult, out_dir: Path, options: RunOptions,
                  fmt: str = "png") -> Path:
    """Write summary.csv/.parquet, histograms.parquet, trials.parquet (if kept),
    provenance.json, plots (in ``fmt``), report.md and report.html."""
    out_dir = Path(out_dir)
    summary = result.to_frame()
    summary.to_csv(out_dir / "summary.csv", index=False)
    summary.to_parquet(out_dir / "summary.parquet", index=False)
    histogram_table(result).to_parquet(out_dir / HISTOGRAMS, index=False)
    if result.trials:
        pd.concat(result.trials.values(), ignore_index=True).to_parquet(
            out_dir / "trials.parquet", index=False)
    options_record = {k: str(v) if isinstance(v, Path) else v
                      for k, v in asdict(options).items()}
    prov = study_provenance(result, options_record)
    (out_dir / PROVENANCE).write_text(json.dumps(prov, indent=2, default=str))
    (out_dir / "plots").mkdir()
    names, figures = _draw(result, summary, out_dir / "plots", fmt)
    md = render_report(result, summary, prov, names)
    (out_dir / "report.md").write_text(md)
    write_html(out_dir, figures, f"Study {result.study.header.name}", md)
    return out_dir


def _draw(result: StudyResult, summary: pd.DataFrame, plots: Path, fmt: str
          ) -> tuple[list[str], dict[str, HtmlFigure]]:
    """Save every figure into ``plots`` as ``fmt``; returns the file names and the figures
    for report.html (inline SVG with captions), by file name."""
    names, figures = [], {}
    for name, fig in all_figures(result, summary):
        name = f"{Path(name).stem}.{fmt}"
        fig.savefig(plots / name, dpi=110)
        names.append(name)
        figures[name] = HtmlFigure(figure_svg(fig), figure_caption(result, name))
    return names, figures


def rerender(path: str | Path, fmt: str = "png") -> tuple[list[str], dict[str, Any]]:
    """Draw the plots and write report.md and report.html of a result directory again from its
    saved data.

    The new plots are drawn into a temporary directory beside ``plots/`` and swapped in only
    when all are drawn; report.md is replaced atomically. Nothing else in ``path`` changes.
    """
    path = Path(path)
    result, summary, prov = load_result(path)
    for stale in [*path.glob(".plots.tmp-*"), *path.glob(".plots.old-*")]:  # a killed rerun's
        shutil.rmtree(stale, ignore_errors=True)
    staging = Path(tempfile.mkdtemp(prefix=".plots.tmp-", dir=path))
    try:
        names, figures = _draw(result, summary, staging, fmt)
        md = render_report(result, summary, prov, names)
        atomic_write_bytes(path / "report.md", md.encode())
        write_html(path, figures, f"Study {result.study.header.name}", md)
        old = path / "plots"
        if old.exists():
            retired = Path(tempfile.mkdtemp(prefix=".plots.old-", dir=path))
            old.rename(retired / "plots")
            staging.rename(old)
            shutil.rmtree(retired)
        else:
            staging.rename(old)
    finally:
        if staging.exists():
            shutil.rmtree(staging)
    return names, prov
