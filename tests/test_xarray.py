"""Result.to_xarray(): swept parameters as dimensions, units as attributes."""

from __future__ import annotations

import numpy as np
import pytest

import montecarlo

xr = pytest.importorskip("xarray")

GRID = {"study": {"name": "grid", "system": "ground", "trials": 300, "seed": 3},
        "sensor": {"fov_deg": [90.0, 90.0], "pixels": [512, 512]},
        "mounting": {"psi_deg": 30.0, "theta_deg": 20.0, "gamma_deg": 10.0},
        "geometry": {"L_m": 50.0, "H_m": 2.0},
        "errors": {"dx_m": {"dist": "uniform", "bound": 0.05},
                   "pixel_px": {"dist": "normal", "sigma": 0.3}, "pixel_relation": "common"},
        "sweep": [{"geometry.L_m": [50.0, 100.0], "geometry.H_m": [1.0, 2.0, 5.0],
                   "errors.pixel_relation": ["common", "independent"]}]}


def test_product_sweep_is_a_grid_with_units():
    result = montecarlo.run(GRID)
    ds = result.to_xarray()
    assert isinstance(ds, xr.Dataset)
    assert ds["rotation_angle"].dims == ("geometry.L_m", "geometry.H_m",
                                         "errors.pixel_relation", "variant", "statistic")
    assert ds.sizes["geometry.L_m"] == 2 and ds.sizes["geometry.H_m"] == 3
    assert ds["rotation_angle"].attrs["units"] == "mrad"
    assert ds["geometry.L_m"].attrs["units"] == "m"
    assert ds["geometry.H_m"].attrs["units"] == "m"
    s = result.summary
    row = s[(s["metric"] == "rotation_angle") & (s["geometry.L_m"] == 100.0)
            & (s["geometry.H_m"] == 2.0) & (s["errors.pixel_relation"] == "independent")
            & (s["variant"] == "raw")].iloc[0]
    cell = ds["rotation_angle"].sel({"geometry.L_m": 100.0, "geometry.H_m": 2.0,
                                     "errors.pixel_relation": "independent",
                                     "variant": "raw"})
    for stat in ("mean", "p95", "p95_lo", "p95_hi", "cvar95", "max", "nominal"):
        np.testing.assert_equal(float(cell.sel(statistic=stat)), row[stat])
    assert int(ds["trials"].max()) == 300


def test_zipped_sweep_lies_along_points():
    result = montecarlo.run("studies/table1.toml", trials=32)
    ds = result.to_xarray()
    assert ds["table1_angle"].dims == ("point", "variant", "statistic")
    assert list(ds["geometry.H_m"].values) == [1.0] * 8 + [2.0, 2.0, 3.0, 3.0]
    assert ds["table1_angle"].attrs["units"] == "mrad"
