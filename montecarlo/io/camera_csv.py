"""A planar calibration target and its images in several views: the two CSV files.

The target's model points (one row per point, coordinates on the target plane, Z = 0)::

    id,X,Y,unit

``unit`` is one of ``m``, ``cm``, ``mm``, ``in`` (every row the same). The observed image points
(one row per point seen in a view)::

    view,id,u,v

``u`` along the image rows (to the right), ``v`` down the columns [px], from the image's own
origin (any fixed origin: the principal point is fitted). ``id`` names a model point; a view
need not see every point. Rows are refused in one line naming file, row (as a text editor
counts, header = 1), column and value.
"""

from __future__ import annotations

import io
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from montecarlo.errors import InputError
from montecarlo.io.files import atomic_write_bytes
from montecarlo.io.table import read_table

FloatArray = NDArray[np.float64]

UNITS = {"m": 1.0, "cm": 0.01, "mm": 0.001, "in": 0.0254}
"""Length units of model points -> metres."""

MAX_COORDINATE = 1e6
"""Largest model coordinate accepted, in the file's unit (1 km in mm): a target is a plate."""

MIN_POINTS_PER_VIEW = 4
"""A homography needs four points."""

MIN_VIEWS = 3
"""Zhang's closed form needs three views (two constraints each on five intrinsics)."""


@dataclass(frozen=True)
class CameraData:
    """Image points of a planar target.

    Attributes
    ----------
    views : view labels in order of first appearance.
    point_id : (n,) model point id of each observation.
    view : (n,) index into ``views`` of each observation.
    points : (n, 2) target coordinates X, Y of each observation [m].
    pixels : (n, 2) measured (u, v) [px].
    rows : (n,) line of each observation in the views file (header = 1).
    unit : the model file's unit (for writing back).
    """

    views: tuple[str, ...]
    point_id: tuple[str, ...]
    view: NDArray[np.int64]
    points: FloatArray
    pixels: FloatArray
    rows: NDArray[np.int64]
    unit: str = "m"

    @property
    def n(self) -> int:
        return self.points.shape[0]


def read_model_csv(path: str | Path) -> tuple[dict[str, FloatArray], str]:
    """Model points: id -> (X, Y) [m], and the file's unit.

    Raises
    ------
    InputError
        Missing column, non-numeric coordinate or one beyond +-:data:`MAX_COORDINATE`, unknown
        or mixed unit, repeated id, fewer than four points.
    """
    table = read_table(path, ("X", "Y"), text=("id", "unit"), choices={"unit": UNITS},
                       ranges={"X": (-MAX_COORDINATE, MAX_COORDINATE),
                               "Y": (-MAX_COORDINATE, MAX_COORDINATE)},
                       min_rows=MIN_POINTS_PER_VIEW)
    units = table["unit"].tolist()
    for i, u in enumerate(units):
        if u != units[0]:
            raise InputError(f"{path}: row {i + 2}, column 'unit': {u!r} differs from the first "
                             f"row's {units[0]!r} (one unit per file)")
    seen: dict[str, int] = {}
    for i, name in enumerate(table["id"]):
        if name in seen:
            raise InputError(f"{path}: row {i + 2}, column 'id': {name!r} repeats row "
                             f"{seen[name] + 2}")
        seen[name] = i
    xy = table[["X", "Y"]].to_numpy(float) * UNITS[units[0]]
    return {name: xy[i] for i, name in enumerate(table["id"])}, units[0]


def read_camera_csv(model_path: str | Path, views_path: str | Path) -> CameraData:
    """Read the model points and the observed image points (module docstring).

    Raises
    ------
    InputError
        Any problem of :func:`read_model_csv`; in the views file a missing column, a non-finite
        or absurd pixel (beyond +-1e6), an id not in the model, an id seen twice in one view,
        a view with fewer than four points, fewer than three views.
    """
    model, unit = read_model_csv(model_path)
    table = read_table(views_path, ("u", "v"), text=("view", "id"),
                       ranges={"u": (-1e6, 1e6), "v": (-1e6, 1e6)}, min_rows=1)
    seen: dict[tuple[str, str], int] = {}
    for i, (v, name) in enumerate(zip(table["view"], table["id"], strict=True)):
        if name not in model:
            raise InputError(f"{views_path}: row {i + 2}, column 'id': {name!r} is not a point "
                             f"of {model_path}")
        if (v, name) in seen:
            raise InputError(f"{views_path}: row {i + 2}, column 'id': {name!r} already seen in "
                             f"view {v!r} (row {seen[(v, name)] + 2})")
        seen[(v, name)] = i
    views = tuple(dict.fromkeys(table["view"]))
    labels = table["view"].tolist()
    for v in views:
        count = labels.count(v)
        if count < MIN_POINTS_PER_VIEW:
            i = labels.index(v)
            raise InputError(f"{views_path}: row {i + 2}, column 'view': view {v!r} has {count} "
                             f"points, at least {MIN_POINTS_PER_VIEW} needed (a homography)")
    if len(views) < MIN_VIEWS:
        raise InputError(f"{views_path}: column 'view': {len(views)} views "
                         f"({', '.join(views)}), at least {MIN_VIEWS} needed")
    index = {v: k for k, v in enumerate(views)}
    return CameraData(views, tuple(table["id"]), np.array([index[v] for v in labels]),
                      np.array([model[name] for name in table["id"]]),
                      table[["u", "v"]].to_numpy(float), np.arange(len(table)) + 2,
                      unit)


def write_camera_csv(model_path: str | Path, views_path: str | Path, ids: list[str],
                     xy: FloatArray, unit: str, data: CameraData) -> None:
    """Write a model file (``xy`` in ``unit``) and a views file, each atomically."""
    text = io.StringIO()
    text.write("id,X,Y,unit\n")
    for name, (x, y) in zip(ids, xy, strict=True):
        text.write(f"{name},{x:.10g},{y:.10g},{unit}\n")
    out = io.StringIO()
    out.write("view,id,u,v\n")
    for k in range(data.n):
        out.write(f"{data.views[data.view[k]]},{data.point_id[k]},{data.pixels[k, 0]:.12g},"
                  f"{data.pixels[k, 1]:.12g}\n")
    for path, body in ((model_path, text), (views_path, out)):
        try:
            atomic_write_bytes(Path(path), body.getvalue().encode())
        except OSError as exc:
            raise InputError(f"{path}: cannot write ({exc.strerror})") from None
