"""A study's summary as an xarray Dataset: swept parameters as dimensions, units as attributes.

Needs the optional dependency ``xarray`` (``pip install montecarlo[xarray]``).

Layout: one data variable per metric, over the dimensions ``(*sweep keys, variant, statistic)``
(``statistic``: mean, std, the percentiles with their interval ends, ``cvar95`` and its
interval, max, nominal), with ``units`` and ``long_name`` attributes; ``trials`` and
``invalid_fraction`` (per metric) beside them. A sweep that is a full product of single keys
gives one dimension per key, so ``ds["rotation_angle"].sel({"geometry.L_m": 100})`` slices it;
a zipped or one-at-a-time sweep is not a grid, and its points lie along a ``point`` dimension
with each sweep key as a coordinate of it.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import pandas as pd

from montecarlo.engine.aggregate import VALUE_COLUMNS
from montecarlo.engine.runner import StudyResult
from montecarlo.engine.superquantile import is_cvar_column
from montecarlo.output.plots import key_label


def _key_unit(key: str) -> str:
    label = key_label(key)
    return label.rpartition("[")[2].rstrip("]") if label.endswith("]") else ""


def grid_dims(result: StudyResult, summary: pd.DataFrame) -> list[str]:
    """The sweep keys if the grid is their full product, else ``["point"]``."""
    study = result.study
    keys = list(study.sweep_keys)
    if not keys:
        return ["point"]
    product = all(mode == "product" for mode, _ in study.sweep_groups)
    sizes = [summary[k].nunique() for k in keys]
    if product and int(np.prod(sizes)) == len(study.points):
        return keys
    return ["point"]


def to_xarray(result: StudyResult, summary: pd.DataFrame) -> Any:
    """The summary (display units) as an ``xarray.Dataset``; see the module docstring.

    Raises
    ------
    ImportError
        xarray is not installed (an optional dependency).
    """
    import xarray as xr

    study = result.study
    dims = grid_dims(result, summary)
    stats = [c for c in summary.columns
             if c in VALUE_COLUMNS or is_cvar_column(c) or c == "nominal"]
    index = [*dims, "variant"]
    data: dict[str, Any] = {}
    for _, m in dict.fromkeys((m.name, m) for _, m in study.metrics):
        rows = summary[summary["metric"] == m.name].set_index(index)
        arr = rows[stats].to_xarray().to_array("statistic").transpose(*index, "statistic")
        arr.attrs = {"units": m.unit, "long_name": m.label,
                     "percentiles_of": "abs" if m.signed else "value",
                     "percentiles_over": "valid"}
        data[m.name] = arr
        inv = rows["invalid_fraction"].to_xarray()
        inv.attrs = {"units": "1", "long_name": f"fraction of trials without a value of "
                     f"{m.name}"}
        data[f"{m.name}_invalid_fraction"] = inv
    first = summary.drop_duplicates(index).set_index(index)
    data["trials"] = first["trials"].to_xarray()
    data["trials"].attrs = {"units": "1", "long_name": "trials per grid point"}
    ds = xr.Dataset(data)
    if dims == ["point"]:  # the sweep values as coordinates along the points
        per_point = summary.drop_duplicates("point").set_index("point")
        ds = ds.assign_coords({k: ("point", per_point.loc[ds["point"].values, k].to_numpy())
                               for k in study.sweep_keys})
    for k in study.sweep_keys:
        ds[k].attrs = {"units": _key_unit(k), "long_name": key_label(k)}
    h = study.header
    ds.attrs = {"study": h.name, "system": h.system, "seed": h.seed,
                "confidence": h.confidence,
                "statistics": "moments, percentiles, cvar and max over the trials with a "
                              "value; nominal: one trial with every error source at its centre"}
    return ds
