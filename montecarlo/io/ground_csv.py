"""Observations of surveyed targets by a strapdown sensor (ground calibration) and their CSV.

    target,x_m,y_m,z_m,px,pz[,t_s][,session]

Positions are surveyed in frame b (x right, y forward, z up) [m]; ``px``, ``pz`` are the measured
image coordinates from the image centre [px] (seed 000, eqs. 1-4 signs).
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from montecarlo.errors import InputError
from montecarlo.geometry.camera import Camera
from montecarlo.io.files import atomic_write_bytes
from montecarlo.io.table import read_table

FloatArray = NDArray[np.float64]


@dataclass(frozen=True)
class GroundData:
    """Observations of surveyed targets.

    Attributes
    ----------
    targets : target names, one per observation.
    positions : (n, 3) surveyed positions in frame b [m].
    pixels : (n, 2) measured ``(px, pz)`` from the image centre [px] (eqs. 1, 4 signs).
    t : (n,) observation times [s], or None.
    session : session label of each observation, or None.
    """

    targets: tuple[str, ...]
    positions: FloatArray
    pixels: FloatArray
    t: FloatArray | None = None
    session: tuple[str, ...] | None = None

    @property
    def n(self) -> int:
        return self.positions.shape[0]

    def sessions(self) -> tuple[str, ...]:
        """Session labels in order of first appearance (``("",)`` without sessions)."""
        return tuple(dict.fromkeys(self.session)) if self.session else ("",)

    def layout(self) -> dict[str, object]:
        """Everything but the measured pixels, as JSON-able lists (for studies)."""
        out: dict[str, object] = {"target": list(self.targets),
                                  "x_m": self.positions[:, 0].tolist(),
                                  "y_m": self.positions[:, 1].tolist(),
                                  "z_m": self.positions[:, 2].tolist()}
        if self.t is not None:
            out["t_s"] = self.t.tolist()
        if self.session is not None:
            out["session"] = list(self.session)
        return out

    @classmethod
    def from_layout(cls, text: str) -> GroundData:
        """A :class:`GroundData` with zero pixels from :meth:`GroundData.layout` as JSON."""
        raw = json.loads(text)
        positions = np.column_stack([raw["x_m"], raw["y_m"], raw["z_m"]]).astype(float)
        n = positions.shape[0]
        return cls(tuple(raw.get("target", [f"T{i + 1}" for i in range(n)])), positions,
                   np.zeros((n, 2)),
                   None if raw.get("t_s") is None else np.asarray(raw["t_s"], float),
                   None if raw.get("session") is None else tuple(map(str, raw["session"])))


FARTHEST = 1e6
"""Largest target coordinate accepted [m] (1000 km)."""

CSV_COLUMNS = ("target", "x_m", "y_m", "z_m", "px", "pz")
"""Required columns of a ground data CSV; ``t_s`` and ``session`` are optional."""


def read_ground_csv(path: str | Path, camera: Camera, min_rows: int = 1, need: str = ""
                    ) -> GroundData:
    """Read and check a ground data CSV (columns :data:`CSV_COLUMNS`, optional t_s, session).

    ``min_rows`` is the fewest observations the caller can use; ``need`` says why. Whether the
    targets lie in front of the sensor depends on the model
    (:func:`montecarlo.discrepancy.ground_effects.check_in_front`).

    Raises
    ------
    InputError
        Missing column, non-numeric or NaN value, too few rows, a row repeating the target,
        session and time of an earlier one, a target at the origin, or an image coordinate
        outside the detector; one line naming file, row and column.
    """
    far = (-FARTHEST, FARTHEST)
    table = read_table(path, ["x_m", "y_m", "z_m", "px", "pz"], optional_numeric=["t_s"],
                       ranges={"x_m": far, "y_m": far, "z_m": far, "t_s": (-1e9, 1e9)},
                       text=["target"])
    if len(table) < min_rows:
        raise InputError(f"{path}: {len(table)} data rows, at least {min_rows} needed"
                         + (f" ({need})" if need else ""))
    session = None
    if "session" in table.columns:
        values = table["session"].str.strip()
        for i, v in enumerate(values):
            if v == "":
                raise InputError(f"{path}: row {i + 2}, column 'session': empty value")
        session = tuple(values)
    for column, half in (("px", camera.n_x / 2.0), ("pz", camera.n_z / 2.0)):
        values = table[column].to_numpy(float)
        bad = np.flatnonzero(np.abs(values) > half)
        if bad.size:
            i = int(bad[0])
            raise InputError(f"{path}: row {i + 2}, column '{column}': {float(values[i])!r} "
                             f"is outside the detector (|{column}| <= {half:g} px)")
    t_column = table["t_s"].to_numpy(float) if "t_s" in table.columns else [None] * len(table)
    first: dict[tuple[str, str, float | None], int] = {}
    for i, key in enumerate(zip(table["target"], session or [""] * len(table), t_column,
                                strict=True)):
        if key in first:
            when = "".join([f" in session {key[1]!r}" if session else "",
                            f" at t_s = {key[2]:g}" if key[2] is not None else ""])
            raise InputError(f"{path}: row {i + 2}, column 'target': {key[0]!r}{when} repeats "
                             f"row {first[key]} (a target is observed once per session and time)")
        first[key] = i + 2
    positions = table[["x_m", "y_m", "z_m"]].to_numpy(float)
    zero = np.flatnonzero(np.linalg.norm(positions, axis=1) == 0.0)
    if zero.size:
        raise InputError(f"{path}: row {int(zero[0]) + 2}, column 'x_m': target at the sensor "
                         "origin (0, 0, 0) has no direction")
    t = table["t_s"].to_numpy(float) if "t_s" in table.columns else None
    return GroundData(tuple(table["target"]), positions, table[["px", "pz"]].to_numpy(float), t,
                      session)


def write_ground_csv(path: str | Path, data: GroundData) -> None:
    """Write observations as a ground data CSV (temporary name, then rename)."""
    cols = ["target", "x_m", "y_m", "z_m", "px", "pz"]
    if data.t is not None:
        cols.append("t_s")
    if data.session is not None:
        cols.append("session")
    lines = [",".join(cols)]
    for i in range(data.n):
        row = [data.targets[i], *(f"{v:.4f}" for v in data.positions[i]),
               *(f"{v:.6f}" for v in data.pixels[i])]
        if data.t is not None:
            row.append(f"{data.t[i]:.1f}")
        if data.session is not None:
            row.append(data.session[i])
        lines.append(",".join(row))
    atomic_write_bytes(Path(path), ("\n".join(lines) + "\n").encode())
