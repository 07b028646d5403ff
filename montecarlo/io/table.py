"""Strict reading of measured-data CSV files: every problem is one line naming file, row, column.

Row numbers in messages are the line numbers a text editor shows (the header is line 1).
"""

from __future__ import annotations

import csv
import math
from collections.abc import Iterable, Mapping
from pathlib import Path

import numpy as np
import pandas as pd

from montecarlo.errors import InputError


def read_table(
    path: str | Path,
    numeric: Iterable[str],
    *,
    optional_numeric: Iterable[str] = (),
    text: Iterable[str] = (),
    choices: Mapping[str, Iterable[str]] | None = None,
    ranges: Mapping[str, tuple[float, float]] | None = None,
    min_rows: int = 1,
) -> pd.DataFrame:
    """Read a CSV file and check its columns and values.

    Parameters
    ----------
    path : path of the CSV file.
    numeric : columns that must be present, finite numbers in every row.
    optional_numeric : columns that may be absent; if present they are checked like ``numeric``.
    text : columns that must be present, non-empty strings.
    choices : for some text columns, the values allowed.
    ranges : for some numeric columns, the interval [low, high] their values must lie in.
    min_rows : fewest data rows accepted.

    Returns
    -------
    DataFrame with float64 numeric columns and str text columns (extra columns kept as read).

    Raises
    ------
    InputError
        Missing file or column, a repeated column name, a non-numeric, NaN or infinite value,
        a value out of its range or not among its choices, or fewer than ``min_rows`` rows;
        the message names file, row and column.
    """
    path = Path(path)
    try:
        frame = pd.read_csv(path, dtype=str, keep_default_na=False, skipinitialspace=True)
    except FileNotFoundError:
        raise InputError(f"{path}: no such file") from None
    except IsADirectoryError:
        raise InputError(f"{path}: is a directory, not a CSV file") from None
    except OSError as exc:
        raise InputError(f"{path}: cannot read ({exc.strerror})") from None
    except (pd.errors.ParserError, pd.errors.EmptyDataError, UnicodeDecodeError) as exc:
        raise InputError(f"{path}: not a readable CSV file ({str(exc).splitlines()[0]})") from None
    with path.open(errors="replace") as f:
        header = next(csv.reader([f.readline()]), [])
    names = [c.strip() for c in header]
    repeated = sorted({c for c in names if names.count(c) > 1})
    if repeated:
        raise InputError(f"{path}: column {repeated[0]!r} appears {names.count(repeated[0])} "
                         "times in the header")
    frame.columns = [str(c).strip() for c in frame.columns]
    numeric, text = list(numeric), list(text)
    for column in [*numeric, *text]:
        if column not in frame.columns:
            have = ", ".join(frame.columns)
            raise InputError(f"{path}: missing column '{column}' (have: {have})")
    if len(frame) < min_rows:
        raise InputError(f"{path}: {len(frame)} data rows, at least {min_rows} needed")

    for column in [*numeric, *(c for c in optional_numeric if c in frame.columns)]:
        raw = frame[column].str.strip()
        values = pd.to_numeric(raw, errors="coerce").to_numpy(float)
        bad = ~np.isfinite(values)
        if bad.any():
            i = int(np.flatnonzero(bad)[0])
            raise InputError(
                f"{path}: row {i + 2}, column '{column}': {raw.iloc[i]!r} is not a finite number")
        low, high = (ranges or {}).get(column, (-math.inf, math.inf))
        bad = (values < low) | (values > high)
        if bad.any():
            i = int(np.flatnonzero(bad)[0])
            raise InputError(f"{path}: row {i + 2}, column '{column}': {raw.iloc[i]} is outside "
                             f"[{low:g}, {high:g}]")
        frame[column] = values
    for column in text:
        values = frame[column].str.strip()
        allowed = None if choices is None else choices.get(column)
        for i, value in enumerate(values):
            if value == "":
                raise InputError(f"{path}: row {i + 2}, column '{column}': empty value")
            if allowed is not None and value not in allowed:
                raise InputError(f"{path}: row {i + 2}, column '{column}': {value!r} is not one "
                                 f"of {', '.join(sorted(allowed))}")
        frame[column] = values
    return frame
