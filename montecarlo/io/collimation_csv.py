"""The data of one autocollimator-INS calibration (seed 003) and its CSV file.

    mirror,set,theodolite_az_deg,theodolite_el_deg,ins_az_deg,ins_el_deg[,ins_roll_deg]

``set`` is ``azimuth`` or ``pitch``, the two mirror families of seed 003, section 3.1, or (for
the paper's procedure, section 3.2) ``reference_center`` / ``reference_roll``, the two reference
mirrors; angles are in degrees in the file and radians inside. With the reference rows every INS
reading is absolute; without them the readings are relative to the INS's reference
(docs/reference/collimation.md).
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from montecarlo.errors import InputError
from montecarlo.io.files import atomic_write_bytes
from montecarlo.io.table import read_table
from montecarlo.seed003.procedure import ProcedureData

FloatArray = NDArray[np.float64]

SETS = ("azimuth", "pitch")
"""The two mirror families of seed 003, section 3.1 (7 + 7 mirrors in the paper)."""

REFERENCE_SETS = ("reference_center", "reference_roll")
"""The central and the roll reference mirror of the procedure (seed 003, section 3.2)."""

CSV_COLUMNS = ("mirror", "set", "theodolite_az_deg", "theodolite_el_deg", "ins_az_deg",
               "ins_el_deg")
"""Required columns; ``ins_roll_deg`` is optional."""


@dataclass(frozen=True)
class MirrorData:
    """One calibration: theodolite and INS readings at each mirror (angles [rad]).

    ``ins_az``/``ins_el`` are zero for a layout (no readings); ``ins_roll`` is None when not
    reported (a level mount is then assumed).
    """

    mirror: tuple[str, ...]
    sets: tuple[str, ...]
    theodolite_az: FloatArray
    theodolite_el: FloatArray
    ins_az: FloatArray
    ins_el: FloatArray
    ins_roll: FloatArray | None = None

    @property
    def roll(self) -> FloatArray:
        """The INS roll at each mirror, zero where not reported [rad]."""
        return np.zeros_like(self.ins_az) if self.ins_roll is None else self.ins_roll

    def layout(self) -> dict[str, object]:
        """The mirrors without the INS readings, JSON-able (for studies)."""
        return {"mirror": list(self.mirror), "set": list(self.sets),
                "theodolite_az": self.theodolite_az.tolist(),
                "theodolite_el": self.theodolite_el.tolist(),
                "ins_roll": None if self.ins_roll is None else self.ins_roll.tolist()}

    @classmethod
    def from_layout(cls, text: str) -> MirrorData:
        """A :class:`MirrorData` with zero INS readings from :meth:`MirrorData.layout` as JSON."""
        raw = json.loads(text)
        az = np.asarray(raw["theodolite_az"], float)
        roll = raw.get("ins_roll")
        return cls(tuple(raw["mirror"]), tuple(raw["set"]), az,
                   np.asarray(raw["theodolite_el"], float), np.zeros_like(az),
                   np.zeros_like(az), None if roll is None else np.asarray(roll, float))


def read_mirror_csv(path: str | Path, min_mirrors: int = 1, need: str = "",
                    sets: tuple[str, ...] = SETS) -> MirrorData:
    """Read and check a calibration CSV (:data:`CSV_COLUMNS`, optional ``ins_roll_deg``).

    ``min_mirrors`` is the fewest rows the caller can use; ``need`` says why (for the message).
    ``sets`` are the accepted values of ``set``; with :data:`REFERENCE_SETS` among them each
    reference set may appear once, and both or neither.

    Raises
    ------
    InputError
        Missing column, non-numeric or NaN value, unknown ``set``, a mirror repeated in its
        set, a reference row repeated or alone, or too few mirrors; one line naming file, row
        and column.
    """
    numeric = [c for c in CSV_COLUMNS if c.endswith("_deg")]
    azimuth, elevation = (-360.0, 360.0), (-90.0, 90.0)
    table = read_table(path, numeric, optional_numeric=["ins_roll_deg"], text=["mirror", "set"],
                       choices={"set": sets},
                       ranges={"theodolite_az_deg": azimuth, "ins_az_deg": azimuth,
                               "theodolite_el_deg": elevation, "ins_el_deg": elevation,
                               "ins_roll_deg": (-180.0, 180.0)})
    kinds = list(table["set"])
    first: dict[tuple[str, str], int] = {}
    for i, key in enumerate(zip(table["mirror"], kinds, strict=True)):
        if key in first:
            raise InputError(f"{path}: row {i + 2}, column 'mirror': {key[0]!r} in set "
                             f"{key[1]!r} repeats row {first[key]} (each mirror is read once)")
        first[key] = i + 2
    for kind in REFERENCE_SETS:
        rows = [i + 2 for i, k in enumerate(kinds) if k == kind]
        if len(rows) > 1:
            raise InputError(f"{path}: row {rows[1]}, column 'set': a second {kind!r} row "
                             f"(the first is row {rows[0]})")
    present = [k for k in REFERENCE_SETS if k in kinds]
    if len(present) == 1:
        other = next(k for k in REFERENCE_SETS if k not in present)
        raise InputError(f"{path}: column 'set': a {present[0]!r} row without a {other!r} row "
                         "(give both reference mirrors or neither)")
    if len(table) < min_mirrors:
        raise InputError(f"{path}: {len(table)} data rows, at least {min_mirrors} needed"
                         + (f" ({need})" if need else ""))
    rad = {c: np.radians(table[c].to_numpy(float)) for c in numeric}
    roll = np.radians(table["ins_roll_deg"].to_numpy(float)) if "ins_roll_deg" in table else None
    return MirrorData(tuple(table["mirror"]), tuple(table["set"]), rad["theodolite_az_deg"],
                      rad["theodolite_el_deg"], rad["ins_az_deg"], rad["ins_el_deg"], roll)


def write_mirror_csv(path: str | Path, data: MirrorData) -> None:
    """Write one calibration (``ins_roll_deg`` if the data have a roll), all or nothing.

    Degrees with 9 decimals (3.6e-6 arc-seconds).
    """
    cols = [("theodolite_az_deg", data.theodolite_az), ("theodolite_el_deg", data.theodolite_el),
            ("ins_az_deg", data.ins_az), ("ins_el_deg", data.ins_el)]
    if data.ins_roll is not None:
        cols.append(("ins_roll_deg", data.ins_roll))
    values = [np.degrees(np.asarray(v, float)) for _, v in cols]
    lines = [",".join(["mirror", "set", *(c for c, _ in cols)])]
    for i, (name, kind) in enumerate(zip(data.mirror, data.sets, strict=True)):
        lines.append(",".join([name, kind, *(f"{v[i]:.9f}" for v in values)]))
    atomic_write_bytes(Path(path), ("\n".join(lines) + "\n").encode())


def procedure_data(data: MirrorData) -> ProcedureData:
    """The rows as seed 003's procedure reads them (reference rows located by their ``set``)."""
    index = {k: data.sets.index(k) if k in data.sets else None for k in REFERENCE_SETS}
    return ProcedureData(data.theodolite_az, data.theodolite_el, data.ins_az, data.ins_el,
                         data.ins_roll, index["reference_center"], index["reference_roll"])
