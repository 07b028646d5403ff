"""Provenance recorded beside every result: what was run, with what code, on what."""

from __future__ import annotations

import contextlib
import datetime as dt
import platform
import subprocess
import sys
from importlib import metadata
from pathlib import Path
from typing import Any

from montecarlo import __version__
from montecarlo.engine.checkpoints import code_fingerprint

LIBRARIES = ("numpy", "scipy", "pandas", "pyarrow", "joblib", "dask", "distributed",
             "matplotlib", "pydantic", "numba")


def git_commit() -> str | None:
    """Commit of the source tree the package is imported from, '+dirty' if it has changes."""
    root = Path(__file__).resolve().parent.parent
    try:
        commit = subprocess.run(["git", "rev-parse", "HEAD"], cwd=root, capture_output=True,
                                text=True, timeout=10, check=True).stdout.strip()
        dirty = subprocess.run(["git", "status", "--porcelain", "--untracked-files=no"],
                               cwd=root, capture_output=True, text=True, timeout=10).stdout.strip()
    except (OSError, subprocess.SubprocessError):
        return None
    return commit + ("+dirty" if dirty else "")


def library_versions() -> dict[str, str | None]:
    versions: dict[str, str | None] = {"python": platform.python_version()}
    for name in LIBRARIES:
        try:
            versions[name] = metadata.version(name)
        except metadata.PackageNotFoundError:
            versions[name] = None
    return versions


def cpu_model() -> str:
    """The processor's model name (results are bit-identical only on one CPU type)."""
    with contextlib.suppress(OSError):
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                return line.partition(":")[2].strip()
    return platform.processor() or platform.machine()


def provenance(kind: str, **record: Any) -> dict[str, Any]:
    """Provenance of a result of command ``kind`` (``run``, ``size``, ``diagnose``, ...).

    Beside ``record`` (seed, study hash and resolved study, inputs, options), it records the
    package version, the git commit and a fingerprint of the source, library versions, the
    platform and CPU model, the command line and the time. ``kind`` (and ``study`` for a study
    run) is what :class:`montecarlo.io.files.OutputDir` checks before replacing a result.
    """
    return {
        "kind": kind,
        **record,
        "package_version": __version__,
        "git_commit": git_commit(),
        "code_fingerprint": code_fingerprint(),
        "libraries": library_versions(),
        "platform": platform.platform(),
        "cpu": cpu_model(),
        "command": " ".join(sys.argv),
        "created_utc": dt.datetime.now(dt.UTC).isoformat(timespec="seconds"),
    }


def study_provenance(result: Any, run_options: dict[str, Any]) -> dict[str, Any]:
    """Provenance of a study run: the study, its hash, seed and resolved form, how it was run
    (``run_options`` do not change results), which path computed the trials (``kernel``), on
    how many worker processes (``workers``, see ``StudyResult``) and which points came from
    checkpoints. ``study_source`` (the study as given) lets
    ``montecarlo report`` build the study again."""
    study = result.study
    return provenance("run", study=study.header.name, study_hash=study.hash(),
                      seed=study.header.seed, run_options=run_options, kernel=result.kernel,
                      workers=result.workers,
                      resumed=result.resumed or None, resolved_study=study.resolved(),
                      study_path=str(study.path), study_source=study.source,
                      point_trials=[gp.trials for gp in study.points])
