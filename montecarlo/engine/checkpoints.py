"""Checkpoints of a study run: each finished grid point saved, so a rerun resumes.

Each finished grid point is pickled, written atomically, under
``<root>/<name>-<hash>-v<version>-f<format>/point-NNNNNN.pkl``.
"""

from __future__ import annotations

import contextlib
import pickle
import shutil
from pathlib import Path

from montecarlo import __version__
from montecarlo.engine.aggregate import PointResult
from montecarlo.engine.study import Study
from montecarlo.io.files import atomic_write_bytes

CHECKPOINT_FORMAT = 1


class Checkpoints:
    """Finished grid points of one study, one pickle file each.

    The directory name carries the study hash, the package version and the checkpoint format,
    so a changed study or package never resumes from another's checkpoints.
    """

    def __init__(self, root: Path, study: Study):
        tag = f"{study.hash()[:16]}-v{__version__}-f{CHECKPOINT_FORMAT}"
        self.dir = root / f"{study.header.name}-{tag}"

    def _file(self, point: int) -> Path:
        return self.dir / f"point-{point:06d}.pkl"

    def load(self, point: int) -> tuple[PointResult, dict] | None:
        """The saved result of a point, or None if absent or unreadable."""
        try:
            loaded = pickle.loads(self._file(point).read_bytes())
        except (OSError, EOFError, pickle.UnpicklingError, AttributeError, ImportError):
            return None
        ok = isinstance(loaded, tuple) and len(loaded) == 2 and isinstance(loaded[0], PointResult)
        return loaded if ok else None

    def save(self, point: int, result: PointResult, trials: dict) -> None:
        self.dir.mkdir(parents=True, exist_ok=True)
        atomic_write_bytes(self._file(point), pickle.dumps((result, trials)))

    def remove(self) -> None:
        """Delete this study's checkpoints (and the checkpoint root if it is left empty)."""
        shutil.rmtree(self.dir, ignore_errors=True)
        with contextlib.suppress(OSError):
            self.dir.parent.rmdir()
