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
from montecarlo.errors import InputError
from montecarlo.io.files import (
    PROVENANCE,
    OutputLock,
    atomic_write_bytes,
    figure_bytes,
    update_written_files,
    with_umask,
)
from montecarlo.output.captions import figure_caption
from montecarlo.output.html_report import HtmlFigure, figure_markup, write_html
from montecarlo.output.plots import all_figures
from montecarlo.output.provenance import study_provenance
from montecarlo.output.report import render_report
from montecarlo.output.saved import HISTOGRAMS, REDRAWN, histogram_table, load_result


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
        trials_table(result).to_parquet(out_dir / "trials.parquet", index=False)
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


def trials_table(result: StudyResult) -> pd.DataFrame:
    """The per-trial values of every grid point as ``trials.parquet`` holds them: ``point``,
    ``trial`` and one column ``<variant>/<metric>_<unit>`` per value, in the metric's display
    unit as in ``summary.csv`` (mrad, arcsec, ...; no suffix for a ratio or a rate)."""
    metrics = {m.name: m for _, m in result.study.metrics}
    frames = []
    for frame in result.trials.values():
        out = frame[["point", "trial"]].copy()
        for col in frame.columns[2:]:
            metric = metrics[col.rpartition("/")[2]]
            suffix = "" if metric.unit == "1" else f"_{metric.unit}"
            out[f"{col}{suffix}"] = frame[col].to_numpy(float) * metric.scale
        frames.append(out)
    return pd.concat(frames, ignore_index=True)


def _draw(result: StudyResult, summary: pd.DataFrame, plots: Path, fmt: str
          ) -> tuple[list[str], dict[str, HtmlFigure]]:
    """Save every figure into ``plots`` as ``fmt`` (the same bytes on every render, see
    :func:`montecarlo.io.files.figure_bytes`); returns the file names and the figures for
    report.html with captions, by file name: the saved bytes themselves (drawn once), or for a
    PDF plot a PNG drawn beside it."""
    import matplotlib.pyplot as plt

    names, figures = [], {}
    for name, fig in all_figures(result, summary):
        name = f"{Path(name).stem}.{fmt}"
        data = figure_bytes(fig, fmt, dpi=110)
        atomic_write_bytes(plots / name, data)
        shown, shown_fmt = (data, fmt) if fmt in ("png", "svg") else (
            figure_bytes(fig, "png", dpi=110), "png")
        figures[name] = HtmlFigure(figure_markup(shown, shown_fmt, Path(name).stem),
                                   figure_caption(result, name))
        plt.close(fig)
        names.append(name)
    return names, figures


def rerender(path: str | Path, fmt: str = "png") -> tuple[list[str], dict[str, Any]]:
    """Draw the plots and write report.md and report.html of a result directory again from its
    saved data.

    The new plots are drawn into a temporary directory beside ``plots/`` and swapped in only
    when all are drawn; report.md is replaced atomically. Nothing else in ``path`` changes. A
    result that no longer matches the list of files its run recorded (a file added, edited,
    removed, or a file where a directory was) is refused before anything is drawn
    (:func:`montecarlo.output.saved.load_result`). The lock of the result directory is held
    meanwhile (:class:`montecarlo.io.files.OutputLock`), and the list of written files is
    brought up to date afterwards.
    """
    path = Path(path)
    if not path.is_dir():
        raise InputError(f"{path}: no such result directory")
    with OutputLock(path):
        result, summary, prov = load_result(path)  # every file checked, under the lock
        plots = path / "plots"
        if plots.is_symlink() or (plots.exists() and not plots.is_dir()):
            raise InputError(f"{plots}: not the directory `montecarlo run` wrote; move it out "
                             "before drawing the plots again")
        names = _redraw(path, result, summary, prov, fmt)
        update_written_files(path, REDRAWN)
    return names, prov


def _redraw(path: Path, result: StudyResult, summary: pd.DataFrame, prov: dict[str, Any],
            fmt: str) -> list[str]:
    for stale in [*path.glob(".plots.tmp-*"), *path.glob(".plots.old-*")]:  # a killed rerun's
        shutil.rmtree(stale, ignore_errors=True)
    staging = Path(tempfile.mkdtemp(prefix=".plots.tmp-", dir=path))
    staging.chmod(with_umask(0o777))  # mkdtemp makes it private; `run` leaves plots/ shared
    try:
        names, figures = _draw(result, summary, staging, fmt)
        md = render_report(result, summary, prov, names)
        atomic_write_bytes(path / "report.md", md.encode())
        write_html(path, figures, f"Study {result.study.header.name}", md)
        old = path / "plots"
        if old.is_dir() and not old.is_symlink():
            retired = Path(tempfile.mkdtemp(prefix=".plots.old-", dir=path))
            old.rename(retired / "plots")
            staging.rename(old)
            shutil.rmtree(retired)
        else:
            staging.rename(old)
    finally:
        if staging.exists():
            shutil.rmtree(staging)
    return names
