"""Provenance recorded beside every result: what was run, with what code, on what."""

from __future__ import annotations

import datetime as dt
import platform
import subprocess
import sys
from importlib import metadata
from pathlib import Path
from typing import Any

from montecarlo import __version__

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


def provenance(study_hash: str, seed: int, resolved: dict[str, Any],
               run_options: dict[str, Any]) -> dict[str, Any]:
    """Provenance record. ``run_options`` (jobs, backend, chunking) do not change results."""
    return {
        "study_hash": study_hash,
        "seed": seed,
        "package_version": __version__,
        "git_commit": git_commit(),
        "libraries": library_versions(),
        "platform": platform.platform(),
        "command": " ".join(sys.argv),
        "created_utc": dt.datetime.now(dt.UTC).isoformat(timespec="seconds"),
        "run_options": run_options,
        "resolved_study": resolved,
    }
