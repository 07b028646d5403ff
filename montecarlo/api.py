"""The Python interface: run a study and look at its result, writing nothing unless asked.

>>> import montecarlo
>>> result = montecarlo.run("studies/table1.toml", trials=2000)    # doctest: +SKIP
>>> result.summary.query("metric == 'table1_angle'")               # doctest: +SKIP
>>> result.plot()                                                   # doctest: +SKIP
>>> result.report("results/table1-quick")                           # doctest: +SKIP

A study is given as a path to a study file, as the dict a study file parses to, or as a loaded
:class:`~montecarlo.engine.study.Study`. ``docs/reference/python-api.md`` walks through an example.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import pandas as pd

from montecarlo.engine.runner import RunOptions, StudyResult, run_study
from montecarlo.engine.study import Study
from montecarlo.systems import load_study, study_from_dict

if TYPE_CHECKING:
    from matplotlib.axes import Axes
    from matplotlib.figure import Figure


@dataclass
class Result:
    """A finished study: its summary, per-trial values (if kept), plots and report.

    Attributes
    ----------
    study : the validated study that was run.
    summary : one row per grid point, variant and metric, in the metric's display unit (the
        ``unit`` column); see the README for the columns.
    trials : per-trial values of each grid point (``per_trial = true`` in the study) [SI units].
    """

    study: Study
    summary: pd.DataFrame
    trials: dict[int, pd.DataFrame]
    options: RunOptions
    _result: StudyResult = field(repr=False)

    @property
    def verdicts(self) -> pd.DataFrame | None:
        """The spec's verdict per grid point and variant (None without a ``[spec]``)."""
        from montecarlo.output.report import spec_verdicts

        return spec_verdicts(self._result, self.summary)

    def figures(self) -> dict[str, Figure]:
        """Every figure ``montecarlo run`` writes, by file name."""
        from montecarlo.output.plots import all_figures

        return dict(all_figures(self._result, self.summary))

    def plot(self, metric: str | None = None, variant: str | None = None,
             ax: Axes | None = None) -> Axes:
        """p50 with the band up to p95, p99 and the interval of p95 of ``metric`` against the
        first swept key (or per point).

        ``metric`` defaults to the study's plotted one (its spec's, else the rotation angle
        where the system has one, else its first metric); ``ax`` to a new figure's axes.
        """
        from montecarlo.output.plots import metric_axes

        return metric_axes(self._result, self.summary, metric, variant, ax)

    def to_xarray(self) -> Any:
        """The summary as an ``xarray.Dataset``: one variable per metric over the swept
        parameters, ``variant`` and ``statistic``, units as attributes (see
        :mod:`montecarlo.output.gridded`). Needs the optional dependency xarray
        (``pip install 'montecarlo[xarray]'``)."""
        from montecarlo.output.gridded import to_xarray

        return to_xarray(self._result, self.summary)

    def report(self, directory: str | Path, fmt: str = "png") -> Path:
        """Write what ``montecarlo run`` writes into ``directory`` (absent, empty or an earlier
        result of this study), all or nothing; plots as ``fmt`` (png, svg or pdf)."""
        from montecarlo.io.files import OutputDir
        from montecarlo.output.outputs import write_outputs

        directory = Path(directory)
        with OutputDir(directory, "run", {"study": self.study.header.name}) as staging:
            write_outputs(self._result, staging, self.options, fmt)
        return directory


def run(study: Study | str | Path | dict[str, Any], *, trials: int | None = None,
        seed: int | None = None, n_jobs: int | None = None, backend: str = "loky",
        scheduler: str | None = None, progress: bool = False,
        checkpoint_dir: str | Path | None = None) -> Result:
    """Run a study and return its :class:`Result`; nothing is written unless asked.

    Parameters
    ----------
    study : a study file's path, its parsed dict, or a loaded Study.
    trials, seed : override the study's trials per grid point and seed (not for a Study).
    n_jobs : local workers (default: the cores; small work runs in this process).
    backend, scheduler : ``"loky"`` or ``"dask"`` (with a scheduler address, or a LocalCluster).
    progress : show a progress bar on stderr.
    checkpoint_dir : save finished grid points there and resume from them (default: none).

    Raises
    ------
    montecarlo.errors.InputError
        A mistake in the study, in one line naming the file, key and value.
    """
    if isinstance(study, Study):
        if trials is not None or seed is not None:
            study = study_from_dict(study.source, study.path, trials=trials, seed=seed)
    elif isinstance(study, dict):
        study = study_from_dict(study, trials=trials, seed=seed)
    else:
        study = load_study(study, trials=trials, seed=seed)
    options = RunOptions(n_jobs=n_jobs, backend=backend, scheduler=scheduler,  # type: ignore
                         progress=progress,
                         checkpoint_dir=None if checkpoint_dir is None else Path(checkpoint_dir))
    result = run_study(study, options)
    return Result(study, result.to_frame(), result.trials, options, result)

