"""Writing files and result directories all or nothing: a temporary name, then a rename."""

from __future__ import annotations

import contextlib
import json
import os
import shutil
import tempfile
from pathlib import Path
from typing import Any


def with_umask(mode: int) -> int:
    """``mode`` as the process's umask would leave it for a newly created file."""
    umask = os.umask(0)
    os.umask(umask)
    return mode & ~umask


def atomic_write_bytes(path: str | Path, data: bytes) -> None:
    """Write a file under a temporary name in the same directory, then rename it.

    The directory must exist. The file gets the usual permissions (``0o666`` less the umask),
    not the private mode of the temporary file; a failure leaves neither a partial file nor the
    temporary one.
    """
    path = Path(path)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    try:
        with os.fdopen(fd, "wb") as f:
            f.write(data)
        os.chmod(tmp, with_umask(0o666))
        os.replace(tmp, path)
    except BaseException:
        with contextlib.suppress(FileNotFoundError):
            os.unlink(tmp)
        raise


PROVENANCE = "provenance.json"
"""The file that marks a directory as results this package wrote (see :class:`OutputDir`)."""


def _pid_alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:  # alive, owned by another user
        return True
    return True


class OutputDir:
    """A results directory written all or nothing, that never replaces what it did not write.

    ``with OutputDir(path, kind) as tmp:`` checks ``path`` first: it may be absent, an empty
    directory, or an earlier result of the same kind (its ``provenance.json`` has ``kind`` and
    the items of ``match``); anything else is an :class:`~montecarlo.errors.InputError`,
    raised before any work is done and touching nothing. The body writes into ``tmp``, a hidden
    sibling ``.NAME.tmp-<pid>-<random>``; on success it replaces ``path``, on any exception
    (Ctrl-C included) it is removed. Hidden siblings left by a process that was killed are
    removed when the next one starts.

    ``previous`` is the existing result (or None), for commands that carry files forward.
    Directories made to hold ``path`` are removed again if the body fails while they are empty.
    """

    def __init__(self, path: str | Path, kind: str, match: dict[str, Any] | None = None):
        self.path = Path(path)
        self.kind = kind
        self.match = match or {}
        self.previous: Path | None = None
        self.tmp: Path | None = None
        self.created: list[Path] = []

    def check(self) -> None:
        """Raise InputError unless the directory may be (re)written; touches nothing."""
        from montecarlo.errors import InputError

        p = self.path
        if not p.exists():
            if p.is_symlink():
                raise InputError(f"{p}: a broken symbolic link; choose another output path")
            return
        if not p.is_dir():
            raise InputError(f"{p}: exists and is not a directory; choose another output path")
        if not any(p.iterdir()):
            return
        marker = p / PROVENANCE
        try:
            record = json.loads(marker.read_text())
        except (OSError, ValueError):
            record = None
        wanted = {"kind": self.kind, **self.match}
        if not isinstance(record, dict) or any(record.get(k) != v for k, v in wanted.items()):
            what = " ".join(f"{k}={v}" for k, v in wanted.items())
            raise InputError(f"{p}: exists and is not an earlier result of this command ({what}); "
                             "choose another output path or remove it")
        self.previous = p

    def _remove_stale(self) -> None:
        for sibling in self.path.parent.glob(f".{self.path.name}.*-*-*"):
            stage, _, rest = sibling.name[len(self.path.name) + 2:].partition("-")
            pid = rest.partition("-")[0]
            if stage in ("tmp", "old") and pid.isdigit() and not _pid_alive(int(pid)):
                shutil.rmtree(sibling, ignore_errors=True)

    def __enter__(self) -> Path:
        from montecarlo.errors import InputError

        self.check()
        missing = [d for d in (self.path.parent, *self.path.parent.parents) if not d.exists()]
        try:
            self.path.parent.mkdir(parents=True, exist_ok=True)
            self.created = missing
            self._remove_stale()
            self.tmp = Path(tempfile.mkdtemp(dir=self.path.parent,
                                             prefix=f".{self.path.name}.tmp-{os.getpid()}-"))
        except OSError as exc:
            raise InputError(f"{self.path}: cannot write here ({exc.strerror})") from None
        self.tmp.chmod(with_umask(0o777))  # mkdtemp makes it private; results are shared
        return self.tmp

    def __exit__(self, exc_type: Any, exc: Any, tb: Any) -> None:
        assert self.tmp is not None
        if exc_type is not None:
            shutil.rmtree(self.tmp, ignore_errors=True)
            for d in self.created:  # innermost first: directories made for this result only
                with contextlib.suppress(OSError):
                    d.rmdir()
            return
        old = None
        if self.path.exists():
            old = Path(tempfile.mkdtemp(dir=self.path.parent,
                                        prefix=f".{self.path.name}.old-{os.getpid()}-"))
            self.path.rename(old / "results")
        self.tmp.rename(self.path)
        if old is not None:
            shutil.rmtree(old, ignore_errors=True)


def writable_file(path: str | Path) -> Path:
    """Check, before any work, that a file can be written at ``path`` (which is not touched).

    Raises
    ------
    InputError
        The path is a directory, or its directory does not exist or is not writable.
    """
    from montecarlo.errors import InputError

    path = Path(path)
    if path.is_dir():
        raise InputError(f"{path}: is a directory; give a file name")
    parent = path.parent if str(path.parent) else Path(".")
    if not parent.is_dir():
        raise InputError(f"{path}: no such directory {str(parent)!r}")
    if not os.access(parent, os.W_OK | os.X_OK) or (path.exists() and not os.access(path, os.W_OK)):
        raise InputError(f"{path}: not writable")
    return path


def save_figure(fig: Any, path: str | Path, dpi: int = 110) -> Path:
    """Render a matplotlib figure to PNG (or the format of the suffix) and write it atomically."""
    import io

    path = Path(path)
    buf = io.BytesIO()
    fig.savefig(buf, format=path.suffix.lstrip(".") or "png", dpi=dpi)
    atomic_write_bytes(path, buf.getvalue())
    return path
