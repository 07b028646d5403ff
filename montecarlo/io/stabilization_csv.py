"""The CSV time series of a gyro indirect-stabilisation run (seed 001): reading and writing.

One row per sample::

    t_s, gyro_x, gyro_y, gyro_z, eta_rad, eps_rad, los_x_px, los_z_px

The gyro columns hold either the IMU rate at ``t_s`` (``point``) or its mean over the sample
interval ending at ``t_s`` (``interval-mean``: the IMU's delta-angle over its last interval
divided by the interval, the first row's interval as long as the second's). The file does not
say which: the reader states it (``--gyro-sampling``).
"""

from __future__ import annotations

import io
from pathlib import Path

import numpy as np

from montecarlo.errors import InputError
from montecarlo.io.files import atomic_write_bytes
from montecarlo.io.table import read_table
from montecarlo.seed001.simulate import Record

CSV_COLUMNS = ("t_s", "gyro_x", "gyro_y", "gyro_z", "eta_rad", "eps_rad", "los_x_px", "los_z_px")
"""Columns of a run: time [s], IMU rate [rad/s] (IMU axes), gimbal azimuth and pitch [rad],
measured image position of the target [px] (x right, z up, from the image centre)."""

MAX_RATE = 100.0
"""Largest gyro rate accepted [rad/s] (beyond any carrier's rocking)."""

MAX_GIMBAL_PITCH = np.radians(89.0)
"""Eq. (4) divides by cos(eps): runs with |eps| beyond this are refused [rad]."""


def write_csv(path: str | Path, record: Record) -> None:
    """Write one run (no batch axes) as a CSV file, atomically (temporary file, then rename).

    Raises
    ------
    InputError
        The file cannot be written (the message names it); nothing is left behind.
    """
    path = Path(path)
    columns = np.column_stack([record.t, record.gyro, record.eta, record.eps, record.los_px])
    text = io.StringIO()
    text.write(",".join(CSV_COLUMNS) + "\n")
    np.savetxt(text, columns, fmt="%.12g", delimiter=",")
    try:
        atomic_write_bytes(path, text.getvalue().encode())
    except OSError as exc:
        raise InputError(f"{path}: cannot write ({exc.strerror})") from None


def read_csv(path: str | Path) -> Record:
    """Read a run written by :func:`write_csv` or measured in the same format.

    Raises
    ------
    InputError
        Missing column, non-numeric value, fewer than 10 rows, times not strictly increasing,
        or a gimbal pitch beyond ``MAX_GIMBAL_PITCH``; one line naming file, row and column.
    """
    rate = (-MAX_RATE, MAX_RATE)
    table = read_table(path, CSV_COLUMNS, min_rows=10,
                       ranges={"gyro_x": rate, "gyro_y": rate, "gyro_z": rate,
                               "eta_rad": (-4 * np.pi, 4 * np.pi), "t_s": (-1e9, 1e9),
                               "los_x_px": (-1e6, 1e6), "los_z_px": (-1e6, 1e6)})
    t = table["t_s"].to_numpy(float)
    bad = np.flatnonzero(np.diff(t) <= 0.0)
    if bad.size:
        i = int(bad[0]) + 1
        raise InputError(f"{path}: row {i + 2}, column 't_s': {float(t[i])!r} is not after the "
                         f"previous time {float(t[i - 1])!r}")
    eps = table["eps_rad"].to_numpy(float)
    bad = np.flatnonzero(np.abs(eps) > MAX_GIMBAL_PITCH)
    if bad.size:
        i = int(bad[0])
        raise InputError(f"{path}: row {i + 2}, column 'eps_rad': {float(eps[i])!r} is beyond "
                         f"+-{MAX_GIMBAL_PITCH:.4f} rad (eq. (4) divides by cos(eps))")
    return Record(t=t, gyro=table[["gyro_x", "gyro_y", "gyro_z"]].to_numpy(float),
                  eta=table["eta_rad"].to_numpy(float), eps=eps,
                  los_px=table[["los_x_px", "los_z_px"]].to_numpy(float))
