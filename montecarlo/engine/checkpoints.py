"""Checkpoints of a study run: each finished grid point saved, so a rerun resumes.

Each finished grid point is pickled, written atomically, under ``<root>/<name>-<key>/``. The key
covers everything that changes the numbers: the study (its hash), the package's source code
(a fingerprint of every module) and the options that select an implementation (``reference``).
A rerun after any of them changed starts afresh instead of mixing results.

Each checkpoint directory holds its key (``key.json``). After a successful run
(:meth:`Checkpoints.remove`) the run's own checkpoints are deleted, and so are the stale ones of
the same study (same name and study hash) left by other source versions (another code
fingerprint, package version or checkpoint format), which no rerun could resume from; other
studies' checkpoints are left alone.
"""

from __future__ import annotations

import contextlib
import functools
import hashlib
import json
import pickle
import shutil
from pathlib import Path

from montecarlo import __version__
from montecarlo.engine.aggregate import PointResult
from montecarlo.engine.study import Study
from montecarlo.io.files import atomic_write_bytes

CHECKPOINT_FORMAT = 2

KEY_FILE = "key.json"
"""The key of a checkpoint directory, written beside its points."""

SOURCE_KEYS = ("code", "version", "format")
"""The parts of a key that name a source version (the rest names the study and options)."""


@functools.lru_cache(maxsize=1)
def code_fingerprint() -> str:
    """SHA-256 of the package's source: every module's path and text."""
    root = Path(__file__).resolve().parents[1]
    digest = hashlib.sha256()
    for path in sorted(root.rglob("*.py")):
        digest.update(path.relative_to(root).as_posix().encode() + b"\0" + path.read_bytes())
    return digest.hexdigest()


class Checkpoints:
    """Finished grid points of one study, one pickle file each, under ``root``."""

    def __init__(self, root: Path, study: Study, reference: bool = False):
        key = {"study": study.hash(), "code": code_fingerprint(), "version": __version__,
               "format": CHECKPOINT_FORMAT, "reference": reference}
        digest = hashlib.sha256(json.dumps(key, sort_keys=True).encode()).hexdigest()
        self.key = key
        self.dir = root / f"{study.header.name}-{digest[:16]}"

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
        if not (self.dir / KEY_FILE).exists():
            atomic_write_bytes(self.dir / KEY_FILE, json.dumps(self.key, sort_keys=True).encode())
        atomic_write_bytes(self._file(point), pickle.dumps((result, trials)))

    def stale(self) -> list[Path]:
        """Checkpoint directories of this study (same name and study hash) saved by another
        source version (code fingerprint, package version or format): never resumable."""
        name = self.dir.name.rpartition("-")[0]
        found = []
        for other in sorted(self.dir.parent.glob(f"{name}-*")):
            if other == self.dir or other.name.rpartition("-")[0] != name:
                continue
            try:
                key = json.loads((other / KEY_FILE).read_text())
            except (OSError, ValueError):
                continue  # not ours to judge: no readable key
            if isinstance(key, dict) and key.get("study") == self.key["study"] and \
                    any(key.get(k) != self.key[k] for k in SOURCE_KEYS):
                found.append(other)
        return found

    def remove(self) -> None:
        """Delete this run's checkpoints and this study's stale ones (:meth:`stale`), and the
        checkpoint root if it is left empty."""
        for d in [self.dir, *self.stale()]:
            shutil.rmtree(d, ignore_errors=True)
        with contextlib.suppress(OSError):
            self.dir.parent.rmdir()
