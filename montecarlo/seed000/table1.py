"""Reproduction of seed 000, Table 1: worst-case ground calibration error over the error bounds.

The paper prints twelve numbers (Delta and normalised Delta for six rows).
docs/reference/conventions.md records how they were computed, and this module recomputes them
from the model, never from the printed values (those are kept only to be shown beside ours):

* true mounting angles psi = 30 deg, theta = 20 deg, gamma = 10 deg; 90 x 90 deg field of view;
  512 x 512 pixels;
* the worst case over the 2**6 corners of the bounds: dx, dy, dh1 = +-0.1 m, the height-scale
  error dh = +-db, and one pixel error (+-df along x, +-df along z) common to both targets;
* the solver run without and with the normalisation of eq. (13);
* the metric ``table1_angle = arccos((1 + tr D) / 4)`` (see :mod:`montecarlo.geometry.metrics`).

References
----------
seed 000, section 1.4 and Table 1; docs/reference/conventions.md, "How seed 000's Table 1 was
computed".
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass

import numpy as np
import pandas as pd

from montecarlo.geometry.camera import Camera
from montecarlo.seed000 import ground

PAPER_CAMERA = Camera.from_degrees(90.0, 90.0, 512, 512)
"""Seed 000, section 1.4: 90 x 90 deg field of view, 512 x 512 pixels."""

PAPER_TRUE_ANGLES = tuple(np.radians([30.0, 20.0, 10.0]))
"""Seed 000, section 1.4: true mounting angles (psi, theta, gamma) [rad]."""

PLACEMENT_BOUND_M = 0.1
"""Seed 000, section 1.4: bound on dx, dy and the height reference error dh1 [m]."""


@dataclass(frozen=True)
class Table1Row:
    """One row of seed 000, Table 1: inputs and the two printed results."""

    df_px: float
    L_m: float
    H_m: float
    db_mm: float
    paper_delta_mrad: float
    paper_norm_delta_mrad: float


TABLE1_ROWS = (
    Table1Row(1.0, 50.0, 1.0, 5.0, 7.37, 6.77),
    Table1Row(1.0, 50.0, 1.0, 1.0, 5.92, 5.81),
    Table1Row(0.5, 50.0, 1.0, 1.0, 4.38, 4.23),
    Table1Row(0.5, 100.0, 1.0, 1.0, 3.13, 3.02),
    Table1Row(0.5, 100.0, 2.0, 1.0, 2.96, 2.91),
    Table1Row(0.5, 100.0, 3.0, 1.0, 2.91, 2.88),
)
"""Seed 000, Table 1 as printed (Delta and normalised Delta in mrad, two decimals)."""

CORNER_SOURCES = ("dx", "dy", "dh1", "dh", "pixel_x", "pixel_z")


def corner_signs(n: int) -> np.ndarray:
    """All 2**n sign combinations, shape (2**n, n), entries -1.0 or +1.0."""
    return np.array(list(itertools.product((-1.0, 1.0), repeat=n)))


def worst_case(
    row: Table1Row,
    camera: Camera = PAPER_CAMERA,
    true_angles: tuple[float, float, float] = PAPER_TRUE_ANGLES,
    placement_bound_m: float = PLACEMENT_BOUND_M,
) -> dict[str, dict[str, float]]:
    """Worst case over the 64 corners of one Table 1 row.

    Returns
    -------
    dict
        For each solver ("raw", "normalised"): the largest ``table1_angle`` and the
        ``rotation_angle`` and ``eq18_angle`` of the same corner [rad] (all three are increasing
        functions of one another, so the corner is the same for each).
    """
    s = corner_signs(len(CORNER_SOURCES)).T
    dx, dy, dh1 = (placement_bound_m * s[i] for i in range(3))
    dh = row.db_mm * 1e-3 * s[3]
    pixel_error = row.df_px * np.stack([s[4], s[5]], axis=-1)  # common to A and B
    solutions = ground.simulate(
        camera, true_angles, row.L_m, row.H_m, dx=dx, dy=dy, dh1=dh1, dh=dh,
        pixel_error_a=pixel_error, pixel_error_b=pixel_error,
    )
    out = {}
    for name, sol in solutions.items():
        if not sol.valid.all():
            raise RuntimeError(f"Table 1 row {row} has invalid corners: {sol.invalid}")
        metrics = ground.solution_metrics(sol, true_angles)
        worst = int(np.argmax(metrics["table1_angle"]))
        out[name] = {k: float(metrics[k][worst])
                     for k in ("table1_angle", "rotation_angle", "eq18_angle")}
    return out


def reproduce_table1() -> pd.DataFrame:
    """Our twelve values beside the paper's, one row per Table 1 row.

    Columns ``df_px, L_m, H_m, db_mm, paper_delta_mrad, paper_norm_delta_mrad, delta_mrad,
    norm_delta_mrad`` (the Table 1 metric) plus ``phi_mrad`` and ``norm_phi_mrad``, the true
    rotation angle of the same worst corner.
    """
    records = []
    for row in TABLE1_ROWS:
        worst = worst_case(row)
        records.append({
            **row.__dict__,
            "delta_mrad": 1e3 * worst["raw"]["table1_angle"],
            "norm_delta_mrad": 1e3 * worst["normalised"]["table1_angle"],
            "phi_mrad": 1e3 * worst["raw"]["rotation_angle"],
            "norm_phi_mrad": 1e3 * worst["normalised"]["rotation_angle"],
        })
    return pd.DataFrame.from_records(records)


JSON_KEYS = ("df_px", "L_m", "H_m", "db_mm", "paper_delta_mrad", "paper_norm_delta_mrad",
             "delta_mrad", "norm_delta_mrad")
"""Keys of each row of ``montecarlo table1 --json`` (fixed interface)."""


def relative_differences(table: pd.DataFrame) -> pd.DataFrame:
    """Relative differences ours/paper - 1 for Delta and normalised Delta."""
    return pd.DataFrame({
        "delta": table["delta_mrad"] / table["paper_delta_mrad"] - 1.0,
        "norm_delta": table["norm_delta_mrad"] / table["paper_norm_delta_mrad"] - 1.0,
    })


def format_table1(table: pd.DataFrame) -> str:
    """Human-readable comparison with the paper, as printed by ``montecarlo table1``."""
    rel = relative_differences(table)
    lines = [
        "Seed 000, Table 1: ground static-base calibration, worst case over 2^6 error corners",
        "Setup: FOV 90x90 deg, 512x512 px, true (psi, theta, gamma) = (30, 20, 10) deg;",
        "       dx, dy, dh1 = +-0.1 m; height-scale error +-db; pixel error +-df (x and z),",
        "       the same for both targets (common).",
        "Delta = arccos((1 + tr D)/4), the metric Table 1 reports (about phi/sqrt(2));",
        "phi = true rotation angle of D at the same corner; 'norm' = with eq. (13). [mrad]",
        "",
        f"{'#':>2} {'df/px':>5} {'L/m':>5} {'H/m':>4} {'db/mm':>5} | "
        f"{'Delta':>5} {'ours':>6} {'diff':>7} | {'norm':>5} {'ours':>6} {'diff':>7} | "
        f"{'phi':>6} {'norm phi':>8}",
        f"{'':>2} {'':>5} {'':>5} {'':>4} {'':>5} | {'paper':>5} {'':>6} {'':>7} | "
        f"{'paper':>5} {'':>6} {'':>7} |",
    ]
    for i, r in table.iterrows():
        lines.append(
            f"{i + 1:>2} {r.df_px:>5.1f} {r.L_m:>5.0f} {r.H_m:>4.0f} {r.db_mm:>5.0f} | "
            f"{r.paper_delta_mrad:>5.2f} {r.delta_mrad:>6.3f} {rel.delta[i]:>+7.2%} | "
            f"{r.paper_norm_delta_mrad:>5.2f} {r.norm_delta_mrad:>6.3f} "
            f"{rel.norm_delta[i]:>+7.2%} | "
            f"{r.phi_mrad:>6.3f} {r.norm_phi_mrad:>8.3f}"
        )
    lines.append("")
    lines.append(f"largest |relative difference| from the paper: {rel.abs().to_numpy().max():.2%}")
    return "\n".join(lines)
