"""Reading a result directory back (``report``, ``compare``): its ``provenance.json`` checked
for structure and types, and every file it lists checked against the size (and, when recorded,
the SHA-256) it had when the command wrote it, before anything is read, drawn or written.

A result that no longer matches what its command wrote (a file edited, removed, replaced by a
directory or added) is refused in one line naming the directory and the entry: drawing a report
from edited data would present numbers the study did not produce.
"""

from __future__ import annotations

import json
import math
from collections.abc import Iterable
from pathlib import Path
from typing import Any

import pandas as pd

from montecarlo.errors import InputError
from montecarlo.io.files import (
    FILES_KEY,
    HASHES_KEY,
    PROVENANCE,
    RECORD_KEY,
    file_sha256,
    record_sha256,
    written_files,
)


def read_provenance(path: str | Path, kind: str, command: str) -> dict[str, Any]:
    """The ``provenance.json`` of a result directory of ``montecarlo KIND`` as a dict, its
    ``study`` (text), ``study_hash`` (text) and list of written files (when present) checked.

    ``command`` names the command reading it, for the message.
    """
    path = Path(path)
    if not path.is_dir():
        raise InputError(f"{path}: no such result directory")
    marker = path / PROVENANCE
    try:
        prov = json.loads(marker.read_bytes().decode("utf-8"))
    except FileNotFoundError:
        raise InputError(f"{path}: no readable {PROVENANCE}; not a result of "
                         f"`montecarlo {kind}`") from None
    except (OSError, ValueError, RecursionError) as exc:
        why = exc.strerror if isinstance(exc, OSError) else str(exc).splitlines()[0][:80]
        raise InputError(f"{path}: no readable {PROVENANCE} ({why}); not a result of "
                         f"`montecarlo {kind}`") from None
    if not isinstance(prov, dict):
        raise InputError(f"{marker}: not a JSON object; not a result of `montecarlo {kind}`")
    if RECORD_KEY in prov and prov[RECORD_KEY] != record_sha256(prov):
        raise InputError(f"{marker}: edited since `montecarlo {kind}` wrote it (its "
                         f"{RECORD_KEY} no longer matches); {command} refuses it (run the "
                         "study again)")
    if prov.get("kind") != kind:
        got = prov.get("kind")
        what = f"a result of `montecarlo {got}`" if isinstance(got, str) else \
            f"kind {got!r}"
        raise InputError(f"{path}: {what}, not of `montecarlo {kind}`")
    for key in ("study", "study_hash"):
        if not isinstance(prov.get(key), str) or not prov[key]:
            raise InputError(f"{marker}: {key}: missing or not a text "
                             f"(got {_short(prov.get(key))}); the result was edited")
    files = prov.get(FILES_KEY)
    if files is not None and not (isinstance(files, dict) and all(
            isinstance(k, str) and (v is None or (isinstance(v, int) and not isinstance(v, bool)))
            for k, v in files.items())):
        raise InputError(f"{marker}: {FILES_KEY}: not a list of file sizes; the result was "
                         "edited")
    hashes = prov.get(HASHES_KEY)
    if hashes is not None and not (isinstance(hashes, dict) and all(
            isinstance(k, str) and isinstance(v, str) for k, v in hashes.items())):
        raise InputError(f"{marker}: {HASHES_KEY}: not a list of checksums; the result was "
                         "edited")
    return prov


def _short(value: Any) -> str:
    text = repr(value)
    return text if len(text) <= 40 else text[:37] + "..."


def check_unchanged(path: str | Path, prov: dict[str, Any], command: str,
                    entries: Iterable[str] | None = None, redrawn: tuple[str, ...] = ()
                    ) -> None:
    """Refuse a result directory whose entries differ from the list its command recorded.

    ``entries``: the listed entries to check (every one of them must be there, of the same
    kind, size and checksum); None checks the whole directory, where an entry the command
    did not write is refused too. ``redrawn``: top-level entries the reading command writes
    again, which may be missing (nothing is lost) but not changed. A result without a list
    (an older version) is not checked.
    """
    path = Path(path)
    listed = prov.get(FILES_KEY)
    if not isinstance(listed, dict):
        return
    hashes = prov.get(HASHES_KEY) or {}
    found = written_files(path)
    names = sorted(listed) if entries is None else list(entries)
    for rel in names:
        if rel not in listed:
            continue
        want, got = listed[rel], found.get(rel, "missing")
        if got == "missing" and rel.split("/")[0] in redrawn:
            continue
        if got != want:
            raise InputError(f"{path}: {rel!r} is {_entry(got)} where `montecarlo run` wrote "
                             f"{_entry(want)}: the result was changed since; {command} refuses "
                             "it (run the study again)")
        if rel in hashes and isinstance(want, int) and file_sha256(path / rel) != hashes[rel]:
            raise InputError(f"{path}: {rel!r} was edited since `montecarlo run` wrote it "
                             f"(its SHA-256 differs); {command} refuses it (run the study "
                             "again)")
    if entries is None:
        extra = [rel for rel in found if rel not in listed]
        if extra:
            names = ", ".join(repr(rel) for rel in extra[:3]) + \
                (f" and {len(extra) - 3} more" if len(extra) > 3 else "")
            raise InputError(f"{path}: {names} {'was' if len(extra) == 1 else 'were'} not "
                             f"written by `montecarlo run`; move them out of the result "
                             f"before {command}")


def _entry(size: int | str | None) -> str:
    """An entry of :func:`~montecarlo.io.files.written_files` in words."""
    if size is None:
        return "a directory"
    if size == -1:
        return "a symbolic link"
    if size == "missing":
        return "missing"
    return f"a file of {size} bytes"


def read_parquet_table(path: str | Path, columns: Iterable[str], numeric: Iterable[str] = (),
                       integer: Iterable[str] = ()) -> pd.DataFrame:
    """A parquet table of a result directory with the ``columns`` it must have; ``numeric``
    columns are numbers (NaN allowed: an undefined statistic), ``integer`` columns finite
    whole numbers >= 0."""
    path = Path(path)
    try:
        table = pd.read_parquet(path)
    except FileNotFoundError:
        raise InputError(f"{path}: missing from the result directory") from None
    except Exception as exc:  # pyarrow raises many kinds on a damaged file
        why = str(exc).splitlines()[0][:80] if str(exc) else type(exc).__name__
        raise InputError(f"{path}: not a readable parquet file ({why})") from None
    for column in columns:
        if column not in table.columns:
            raise InputError(f"{path}: missing column {column!r}")
    for column in (*numeric, *integer):
        if column in table.columns and not pd.api.types.is_numeric_dtype(table[column]):
            raise InputError(f"{path}: column {column!r} is not numeric "
                             f"(dtype {table[column].dtype})")
    for column in integer:
        values = table[column].to_numpy(float)
        bad = [i for i, v in enumerate(values) if not (math.isfinite(v) and v >= 0
                                                       and v == int(v))]
        if bad:
            raise InputError(f"{path}: row {bad[0]}, column {column!r}: "
                             f"{values[bad[0]]!r} is not a whole number >= 0")
    return table
