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

FILES_KEY = "files"
"""The key of ``provenance.json`` that lists what the command wrote: relative path -> size in
bytes (None for a directory). Anything else found in the directory makes it the user's."""

HASHES_KEY = "sha256"
"""The key of ``provenance.json`` that lists the SHA-256 of each file the command wrote (up to
:data:`HASHED_BYTES`): relative path -> hex digest; an edit that keeps the size is seen too."""

RECORD_KEY = "record_sha256"
"""The key of ``provenance.json`` that holds the SHA-256 of its own other entries (all but
:data:`FILES_KEY`, :data:`HASHES_KEY` and itself, as canonical JSON): an edit is seen."""

HASHED_BYTES = 256 * 2 ** 20
"""Larger files are listed by size only."""

RESULTS_ROOT = Path("results")
"""The default root of result directories (``results/<study>/``); never itself a result."""


def _pid_alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:  # alive, owned by another user
        return True
    return True


def _real(path: Path) -> Path:
    """``path`` with every symbolic link and ``..`` resolved (it need not exist)."""
    return Path(os.path.realpath(path))


def written_files(directory: Path) -> dict[str, int | None]:
    """Every entry below ``directory`` but its ``provenance.json``: relative path -> size in
    bytes, None for a directory and -1 for a symbolic link (not followed)."""
    entries: dict[str, int | None] = {}
    for dirpath, dirnames, filenames in os.walk(directory):
        for name in sorted(dirnames + filenames):
            path = Path(dirpath) / name
            rel = path.relative_to(directory).as_posix()
            if rel == PROVENANCE:
                continue
            if path.is_symlink():
                entries[rel] = -1
            elif path.is_dir():
                entries[rel] = None
            else:
                entries[rel] = path.stat().st_size
    return dict(sorted(entries.items()))


def file_sha256(path: Path) -> str:
    """Hex SHA-256 of a file's bytes."""
    import hashlib

    digest = hashlib.sha256()
    with path.open("rb") as f:
        for block in iter(lambda: f.read(2 ** 20), b""):
            digest.update(block)
    return digest.hexdigest()


def file_hashes(directory: Path, files: dict[str, int | None]) -> dict[str, str]:
    """SHA-256 of the regular files among ``files`` (relative path -> size) up to
    :data:`HASHED_BYTES`."""
    return {rel: file_sha256(directory / rel) for rel, size in files.items()
            if size is not None and 0 <= size <= HASHED_BYTES}


def record_sha256(record: dict[str, Any]) -> str:
    """SHA-256 of a provenance record's entries but its lists of files (:data:`RECORD_KEY`)."""
    import hashlib

    body = {k: v for k, v in record.items() if k not in (FILES_KEY, HASHES_KEY, RECORD_KEY)}
    text = json.dumps(body, sort_keys=True, separators=(",", ":"), default=str)
    return hashlib.sha256(text.encode()).hexdigest()


def record_written_files(directory: Path) -> None:
    """Add the list of ``directory``'s entries (:data:`FILES_KEY`), their checksums
    (:data:`HASHES_KEY`) and the record's own (:data:`RECORD_KEY`) to its ``provenance.json``
    (nothing if it has none): what the command wrote, checked before the directory is replaced
    or read back."""
    marker = directory / PROVENANCE
    try:
        record = json.loads(marker.read_text())
    except (OSError, ValueError):
        return
    if isinstance(record, dict):
        record[FILES_KEY] = written_files(directory)
        record[HASHES_KEY] = file_hashes(directory, record[FILES_KEY])
        record[RECORD_KEY] = record_sha256(record)
        atomic_write_bytes(marker, (json.dumps(record, indent=2, default=str) + "\n").encode())


def update_written_files(directory: Path, replaced: tuple[str, ...]) -> None:
    """After a command rewrote the entries ``replaced`` (top-level names) of a result
    directory, list what they now hold in its ``provenance.json``, keeping the rest of the list
    (a result without a list keeps none: its files still cannot be told apart)."""
    marker = directory / PROVENANCE
    try:
        record = json.loads(marker.read_text())
    except (OSError, ValueError):
        return
    if not isinstance(record, dict) or not isinstance(record.get(FILES_KEY), dict):
        return
    kept = {rel: size for rel, size in record[FILES_KEY].items()
            if rel.split("/")[0] not in replaced}
    now = {rel: size for rel, size in written_files(directory).items()
           if rel.split("/")[0] in replaced}
    record[FILES_KEY] = dict(sorted({**kept, **now}.items()))
    if isinstance(record.get(HASHES_KEY), dict):
        record[HASHES_KEY] = dict(sorted({**{rel: h for rel, h in record[HASHES_KEY].items()
                                             if rel.split("/")[0] not in replaced},
                                          **file_hashes(directory, now)}.items()))
    atomic_write_bytes(marker, (json.dumps(record, indent=2, default=str) + "\n").encode())


def foreign_entries(directory: Path, record: dict[str, Any]) -> list[str] | None:
    """Entries of a result directory that its command did not write (or that changed size
    since), sorted; None if ``record`` (its provenance) has no list of written files."""
    listed = record.get(FILES_KEY)
    if not isinstance(listed, dict):
        return None
    found = written_files(directory)
    return [rel for rel, size in found.items()
            if rel not in listed or listed[rel] != size or size == -1]


def protected_reason(path: Path, inputs: tuple[Path, ...] = ()) -> str | None:
    """Why ``path`` may never be replaced by a result directory, or None.

    Refused: the current directory and its parents (``.``, ``..``), the results root
    :data:`RESULTS_ROOT` and its parents, the home directory, a directory holding one of the
    ``inputs`` (the study or data file read), and a path that is a symbolic link or leads
    through one to any of these.
    """
    if path.is_symlink():
        return "is a symbolic link; give the directory itself"
    real = _real(path)
    cwd = _real(Path.cwd())
    if real == cwd or real in cwd.parents:
        return "is the current directory or one of its parents"
    results = _real(RESULTS_ROOT)
    if real == results or real in results.parents:
        return f"is the results root {str(RESULTS_ROOT)!r} or one of its parents, not a result"
    if real == _real(Path.home()):
        return "is the home directory"
    for source in inputs:
        if real in _real(source).parents:
            return f"holds the input {str(source)!r}"
    return None


class OutputLock:
    """``with OutputLock(path):`` holds the lock file ``.NAME.lock`` beside ``path`` (an output
    directory), so that a second writer of the same directory is refused instead of replacing
    the first one's result; the lock file is removed on exit.

    The lock is an ``flock`` on that file: a killed process releases it, and a lock file it
    leaves behind is taken over by the next writer.
    """

    def __init__(self, path: str | Path):
        self.path = Path(path)
        self.file = self.path.parent / f".{self.path.name}.lock"
        self.fd: int | None = None

    def __enter__(self) -> OutputLock:
        import fcntl

        from montecarlo.errors import InputError

        while True:
            try:
                fd = os.open(self.file, os.O_RDWR | os.O_CREAT, with_umask(0o666))
            except OSError as exc:
                raise InputError(f"{self.path}: cannot write here ({exc.strerror})") from None
            try:
                fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
            except OSError:
                holder = os.read(fd, 32).decode(errors="replace").strip() or "?"
                os.close(fd)
                raise InputError(f"{self.path}: another process (pid {holder}) is writing it "
                                 f"(lock {self.file.name}); wait for it to finish or choose "
                                 "another output path") from None
            try:  # the file may have been removed by the holder we waited for: lock anew
                same = os.fstat(fd).st_ino == os.stat(self.file).st_ino
            except FileNotFoundError:
                same = False
            if same:
                break
            os.close(fd)
        os.ftruncate(fd, 0)
        os.write(fd, f"{os.getpid()}\n".encode())
        self.fd = fd
        return self

    def __exit__(self, *exc: Any) -> None:
        assert self.fd is not None
        with contextlib.suppress(FileNotFoundError):
            os.unlink(self.file)
        os.close(self.fd)
        self.fd = None


class OutputDir:
    """A results directory written all or nothing, that never replaces what it did not write.

    ``with OutputDir(path, kind) as tmp:`` checks ``path`` first. It may be absent, an empty
    directory, or wholly an earlier result of the same kind: its ``provenance.json`` has
    ``kind`` and the items of ``match``, and lists every other entry of the directory with its
    size (:data:`FILES_KEY`, recorded when the result was written). A file the command did not
    write makes the directory the user's. The path must not be one :func:`protected_reason`
    refuses (the current directory or a parent, the results root, a directory holding one of
    ``inputs``, a symbolic link). Anything else is an :class:`~montecarlo.errors.InputError`,
    raised before any work is done and touching nothing.

    While the body runs, :class:`OutputLock` holds ``.NAME.lock`` beside ``path``: a second
    writer of the same directory is refused. The body writes into ``tmp``, a hidden sibling
    ``.NAME.tmp-<pid>-<random>``; on success the list of written files is added to its
    ``provenance.json`` and it replaces ``path``; on any exception (Ctrl-C included) it is
    removed. Hidden siblings left by a process that was killed are removed when the next one
    starts.

    ``previous`` is the existing result (or None), for commands that carry files forward.
    Directories made to hold ``path`` are removed again if the body fails while they are empty.
    """

    def __init__(self, path: str | Path, kind: str, match: dict[str, Any] | None = None,
                 inputs: tuple[str | Path, ...] = ()):
        self.path = Path(path)
        self.kind = kind
        self.match = match or {}
        self.inputs = tuple(Path(p) for p in inputs)
        self.previous: Path | None = None
        self.tmp: Path | None = None
        self.created: list[Path] = []
        self.lock: OutputLock | None = None

    def check(self) -> None:
        """Raise InputError unless the directory may be (re)written; touches nothing."""
        from montecarlo.errors import InputError

        p = self.path
        reason = protected_reason(p, self.inputs)
        if reason is not None:
            raise InputError(f"{p}: {reason}; choose another output path")
        if not p.exists():
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
        foreign = foreign_entries(p, record)
        if foreign is None:
            raise InputError(f"{p}: an earlier result without the list of its files (written "
                             "by an older version), so files added to it cannot be told apart; "
                             "choose another output path or remove it")
        if foreign:
            raise InputError(f"{p}: holds {len(foreign)} file(s) this command did not write "
                             f"(first {foreign[0]!r}), so it is not wholly an earlier result; "
                             "choose another output path or move them out")
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
        except OSError as exc:
            raise InputError(f"{self.path}: cannot write here ({exc.strerror})") from None
        self.created = missing
        try:
            self.lock = OutputLock(self.path).__enter__()
            self.check()  # again, under the lock: another writer may have finished meanwhile
            self._remove_stale()
            self.tmp = Path(tempfile.mkdtemp(dir=self.path.parent,
                                             prefix=f".{self.path.name}.tmp-{os.getpid()}-"))
        except BaseException as exc:
            self._release()
            self._remove_created()
            if isinstance(exc, OSError):
                raise InputError(f"{self.path}: cannot write here ({exc.strerror})") from None
            raise
        self.tmp.chmod(with_umask(0o777))  # mkdtemp makes it private; results are shared
        return self.tmp

    def _release(self) -> None:
        if self.lock is not None:
            self.lock.__exit__(None, None, None)
            self.lock = None

    def _remove_created(self) -> None:
        for d in self.created:  # innermost first: directories made for this result only
            with contextlib.suppress(OSError):
                d.rmdir()

    def __exit__(self, exc_type: Any, exc: Any, tb: Any) -> None:
        assert self.tmp is not None
        try:
            if exc_type is not None:
                shutil.rmtree(self.tmp, ignore_errors=True)
                self._release()
                self._remove_created()
                return
            record_written_files(self.tmp)
            old = None
            if self.path.exists():
                old = Path(tempfile.mkdtemp(dir=self.path.parent,
                                            prefix=f".{self.path.name}.old-{os.getpid()}-"))
                self.path.rename(old / "results")
            self.tmp.rename(self.path)
            if old is not None:
                shutil.rmtree(old, ignore_errors=True)
        finally:
            self._release()


def writable_file(path: str | Path, replace: bool = False) -> Path:
    """Check, before any work, that a file can be written at ``path`` (which is not touched).

    Raises
    ------
    InputError
        The path is a directory, its directory does not exist or is not writable, or (unless
        ``replace``, the command's ``--force``) a file is already there.
    """
    from montecarlo.errors import InputError

    path = Path(path)
    if path.is_dir():
        raise InputError(f"{path}: is a directory; give a file name")
    if not path.parent.is_dir():
        raise InputError(f"{path}: no such directory {str(path.parent)!r}")
    if not os.access(path.parent, os.W_OK | os.X_OK) or (path.exists()
                                                         and not os.access(path, os.W_OK)):
        raise InputError(f"{path}: not writable")
    if (path.exists() or path.is_symlink()) and not replace:
        raise InputError(f"{path}: exists; choose another name or add --force to replace it")
    return path


FIXED_METADATA = {"png": {}, "svg": {"Date": None}, "pdf": {"CreationDate": None}}
"""Metadata that would change on every render (the date), left out so that drawing the same
figure again gives the same bytes."""

SVG_HASHSALT = "montecarlo"
"""matplotlib's ``svg.hashsalt``: the ids of clip paths and markers in an SVG are hashes salted
with it (random otherwise)."""


def figure_bytes(fig: Any, fmt: str = "png", dpi: int | None = 110,
                 rc: dict[str, Any] | None = None) -> bytes:
    """A matplotlib figure rendered as ``fmt`` (png, svg, pdf), the same bytes every time: no
    creation date, fixed SVG ids (``rc``: further rcParams for this render; ``dpi`` None: the
    figure's own).

    The bytes are those of ``fig.savefig``, drawn once: the figure's layout engine is run for
    this format as ``savefig`` runs it (:func:`_laid_out`), then switched off while saving,
    where ``savefig`` alone would first walk the whole figure with drawing disabled only to
    run the layout."""
    import io

    import matplotlib

    buf = io.BytesIO()
    params: Any = {"svg.hashsalt": SVG_HASHSALT, **(rc or {})}
    with matplotlib.rc_context(params), _laid_out(fig, fmt, dpi):
        fig.savefig(buf, format=fmt, dpi=dpi, metadata=FIXED_METADATA.get(fmt) or None)
    return buf.getvalue()


@contextlib.contextmanager
def _laid_out(fig: Any, fmt: str, dpi: int | None) -> Any:
    """Within: ``fig`` laid out for ``fmt`` at ``dpi``, on the canvas that saves ``fmt``, with
    no layout engine (so ``savefig`` draws it once); afterwards as it was.

    As in ``savefig``: the canvas of the format (unless the figure's own can print it), and
    the figure's dpi the format's fixed one (72 for svg and pdf) or the saving dpi while the
    layout is computed."""
    import matplotlib
    from matplotlib.backend_bases import get_registered_canvas_class

    engine, canvas, figure_dpi = fig.get_layout_engine(), fig.canvas, fig.dpi
    target = None if hasattr(canvas, f"print_{fmt}") else get_registered_canvas_class(fmt)
    if engine is None or (target is None and not hasattr(canvas, f"print_{fmt}")):
        yield  # nothing to lay out, or a format savefig will refuse itself
        return
    try:
        if target is not None:
            target(fig)  # the new canvas sets itself on the figure
        fig.dpi = getattr(fig.canvas, "fixed_dpi", None) or dpi or figure_dpi
        engine.execute(fig)
        fig.dpi = figure_dpi
        with matplotlib.rc_context({"figure.autolayout": False,
                                    "figure.constrained_layout.use": False}):
            fig.set_layout_engine(None)  # none at all: a placeholder engine draws twice too
        yield
    finally:
        fig.set_layout_engine(engine)
        fig.dpi = figure_dpi
        fig.set_canvas(canvas)


def save_figure(fig: Any, path: str | Path, dpi: int = 110) -> Path:
    """Render a matplotlib figure to PNG (or the format of the suffix), the same bytes every
    time (:func:`figure_bytes`), and write it atomically."""
    path = Path(path)
    atomic_write_bytes(path, figure_bytes(fig, path.suffix.lstrip(".") or "png", dpi))
    return path
