"""Strict reading of a JSON input file (a saved fit, a SALib problem): every problem is one line
naming the file, the field (a dotted path, list positions in brackets) and the value.

Refused: a missing or unreadable file, bytes that are not UTF-8, text that is not JSON, a key
given twice in one object. :func:`field` then takes typed values out of the parsed file and
refuses, naming the field, ``NaN`` and ``Infinity`` (not JSON, though Python writes them) and a
number too large for a float (read as infinite).
"""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

from montecarlo.errors import InputError


def _no_repeats(pairs: list[tuple[str, Any]]) -> dict[str, Any]:
    seen: dict[str, Any] = {}
    for key, value in pairs:
        if key in seen:
            raise ValueError(f"key {key!r} appears twice in one object")
        seen[key] = value
    return seen


def read_json(path: str | Path, what: str) -> Any:
    """The parsed JSON of the file at ``path``; ``what`` names the kind of file in messages
    ("fit file", "problem file")."""
    path = Path(path)
    try:
        data = path.read_bytes()
    except FileNotFoundError:
        raise InputError(f"{path}: no such {what}") from None
    except IsADirectoryError:
        raise InputError(f"{path}: is a directory, not a {what}") from None
    except OSError as exc:
        raise InputError(f"{path}: cannot read ({exc.strerror})") from None
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise InputError(f"{path}: not UTF-8 text (byte 0x{data[exc.start]:02x} at offset "
                         f"{exc.start}); not a {what}") from None
    try:
        return json.loads(text, object_pairs_hook=_no_repeats)
    except json.JSONDecodeError as exc:
        raise InputError(f"{path}: not JSON ({exc.msg}, line {exc.lineno}); not a {what}") \
            from None
    except (ValueError, RecursionError) as exc:
        raise InputError(f"{path}: not a {what} ({str(exc) or 'nested too deeply'})") from None


def _short(value: Any) -> str:
    text = json.dumps(value) if not isinstance(value, str) else repr(value)
    return text if len(text) <= 40 else text[:37] + "..."


def field(data: Any, key: str, path: str | Path, kind: type | tuple[type, ...],
          *, low: float | None = None, high: float | None = None,
          positive: bool = False, choices: Any = None) -> Any:
    """The value at the dotted ``key`` of ``data`` (parsed JSON), which must be of ``kind``
    (``float`` accepts any JSON number and returns a float; ``bool`` only true/false), within
    [``low``, ``high``], > 0 if ``positive``, and among ``choices`` if given.

    Raises
    ------
    InputError
        One line: ``PATH: KEY: ...`` naming the missing field, the wrong type or the value.
    """
    node = data
    for depth, part in enumerate(key.split(".")):
        if not isinstance(node, dict):
            where = ".".join(key.split(".")[:depth]) or "(file)"
            raise InputError(f"{path}: {where}: not a JSON object (got {_short(node)})")
        if part not in node:
            raise InputError(f"{path}: {key}: missing")
        node = node[part]
    kinds = kind if isinstance(kind, tuple) else (kind,)
    if float in kinds and isinstance(node, int) and not isinstance(node, bool):
        node = float(node)
    if not isinstance(node, kinds) or (isinstance(node, bool) and bool not in kinds):
        names = " or ".join({float: "a number", bool: "true or false", str: "a text",
                             int: "a whole number", list: "a list", dict: "an object"}
                            .get(k, k.__name__) for k in kinds)
        raise InputError(f"{path}: {key}: not {names} (got {_short(node)})")
    if isinstance(node, float):
        if not math.isfinite(node):
            raise InputError(f"{path}: {key}: not a finite number (got {node!r})")
        if (low is not None and node < low) or (high is not None and node > high):
            raise InputError(f"{path}: {key}: {node!r} is outside [{low}, {high}]")
        if positive and not node > 0.0:
            raise InputError(f"{path}: {key}: must be > 0 (got {node!r})")
    if choices is not None and node not in choices:
        raise InputError(f"{path}: {key}: {_short(node)} is not one of "
                         f"{', '.join(map(str, choices))}")
    return node
