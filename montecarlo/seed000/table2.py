"""Seed 000, Table 2: the printed transfer-alignment accuracies beside our filter's.

Table 2 gives the slave IMU's heading and level accuracy (1σ) after transfer alignment for five
IMU grades; :func:`table2_grid` runs :mod:`montecarlo.seed000.transfer_alignment` for the same
grades.

References
----------
seed 000, section 2 and Table 2; docs/reference/air.md; docs/reference/references.md.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
import pandas as pd

from montecarlo.seed000.transfer_alignment import AlignmentConfig, simulate
from montecarlo.units import ARCMIN, DEG_PER_HOUR, G0


@dataclass(frozen=True)
class Table2Row:
    """One row of seed 000, Table 2 (all 1σ)."""

    gyro_deg_h: float
    accel_g: float
    heading_arcmin: float
    level_arcmin: float

    @property
    def gyro_drift(self) -> float:
        """Gyro drift [rad/s]."""
        return self.gyro_deg_h * DEG_PER_HOUR

    @property
    def accel_bias(self) -> float:
        """Accelerometer bias [m/s²]."""
        return self.accel_g * G0


TABLE2_ROWS = (
    Table2Row(0.05, 5e-4, 13.0, 20.0),
    Table2Row(0.05, 1e-4, 8.0, 12.0),
    Table2Row(0.05, 5e-5, 3.0, 5.0),
    Table2Row(0.50, 5e-5, 3.0, 5.0),
    Table2Row(1.00, 5e-5, 3.0, 5.0),
)
"""Seed 000, Table 2 as printed: gyro [°/h], accelerometer [g], heading and level accuracy [′]."""



def grade_config(gyro_drift: float, accel_bias: float, base: AlignmentConfig | None = None
                 ) -> AlignmentConfig:
    """``base`` (default :class:`AlignmentConfig`) with the IMU grade replaced."""
    return replace(base or AlignmentConfig(), gyro_drift=float(gyro_drift),
                   accel_bias=float(accel_bias))


def table2_grid(base: AlignmentConfig | None = None, rng: int | np.random.Generator | None = 0,
                runs: int = 100) -> pd.DataFrame:
    """Table 2 as printed beside this module's filter for the same five IMU grades.

    Heading is phi_U; "level" is the root-sum-square of the two level axes,
    ``sqrt(phi_E^2 + phi_N^2)`` (the reading under which the paper's 1.70 mrad is the RSS of
    heading and level, see :mod:`montecarlo.seed000.air`); the per-axis worst level is also given.
    ``*_cov`` columns are the filter's 1σ, ``*_mc`` the root-mean-square of the actual error over
    ``runs`` Monte Carlo runs. All angles in arc-minutes.
    """
    seeds = np.random.SeedSequence(
        rng if not isinstance(rng, np.random.Generator) else rng.integers(2**63)
    ).spawn(len(TABLE2_ROWS))
    rows = []
    for row, seed in zip(TABLE2_ROWS, seeds, strict=True):
        cfg = grade_config(row.gyro_drift, row.accel_bias, base)
        res = simulate(cfg, np.random.default_rng(seed), runs)
        sig = res.cov.attitude_sigma()[-1]
        rms = np.sqrt(np.mean(res.phi[-1] ** 2, axis=0))
        rows.append({
            "gyro_deg_h": row.gyro_deg_h,
            "accel_g": row.accel_g,
            "paper_heading_arcmin": row.heading_arcmin,
            "paper_level_arcmin": row.level_arcmin,
            "heading_cov_arcmin": sig[2] / ARCMIN,
            "heading_mc_arcmin": rms[2] / ARCMIN,
            "level_cov_arcmin": np.hypot(sig[0], sig[1]) / ARCMIN,
            "level_mc_arcmin": np.hypot(rms[0], rms[1]) / ARCMIN,
            "level_axis_max_cov_arcmin": max(sig[0], sig[1]) / ARCMIN,
            "runs": runs,
        })
    return pd.DataFrame(rows)


def describe(cfg: AlignmentConfig) -> str:
    """One-paragraph description of a configuration, for printed reports."""
    match = "velocity + attitude matching" if cfg.attitude_matching else "velocity matching"
    return (
        f"{match}; {cfg.manoeuvre} (speed {cfg.speed:g} m/s, bank {np.degrees(cfg.bank):g}°, "
        f"period {cfg.period:g} s), {cfg.duration:g} s; IMU {1 / cfg.dt:g} Hz, Kalman update "
        f"{1 / (cfg.dt * cfg.kf_interval):g} Hz; master velocity noise {cfg.velocity_noise:g} m/s"
        + (f", attitude noise {cfg.attitude_noise * 1e3:g} mrad" if cfg.attitude_matching else "")
        + f"; ARW {cfg.gyro_arw / (np.pi / 180 / 60):g} °/√h, VRW "
        f"{cfg.accel_vrw / G0 * 1e6:g} µg/√Hz; initial misalignment 1σ "
        f"{np.degrees(cfg.initial_level):g}° about each level axis, "
        f"{np.degrees(cfg.initial_heading):g}° in heading"
    )


def format_table2(table: pd.DataFrame, cfg: AlignmentConfig) -> str:
    """Human-readable Table 2 comparison, as printed by ``montecarlo transfer-alignment``."""
    runs = int(table.runs.iloc[0])
    lines = [
        "Seed 000, Table 2: transfer-alignment accuracy of the slave IMU, 1σ [arc-min]",
        "Ours: " + describe(cfg) + ".",
        "Heading = phi_U; level = RSS of the two level axes (phi_E, phi_N); "
        f"cov = filter 1σ, mc = rms of the actual error over {runs} runs.",
        "",
        f"{'gyro':>6} {'accel':>7} | {'heading':>7} {'ours':>6} {'ours':>6} | "
        f"{'level':>6} {'ours':>6} {'ours':>6} | {'bias/g':>6}",
        f"{'°/h':>6} {'g':>7} | {'paper':>7} {'cov':>6} {'mc':>6} | "
        f"{'paper':>6} {'cov':>6} {'mc':>6} | {'x √2':>6}",
    ]
    for r in table.itertuples():
        lines.append(
            f"{r.gyro_deg_h:>6.2f} {r.accel_g:>7.0e} | {r.paper_heading_arcmin:>7.0f} "
            f"{r.heading_cov_arcmin:>6.2f} {r.heading_mc_arcmin:>6.2f} | "
            f"{r.paper_level_arcmin:>6.0f} {r.level_cov_arcmin:>6.2f} {r.level_mc_arcmin:>6.2f} | "
            f"{np.sqrt(2) * r.accel_g / ARCMIN:>6.2f}")
    lines += [
        "",
        "bias/g x √2: the level error (RSS of two axes) that an accelerometer bias alone leaves",
        "without any manoeuvre (tilt and horizontal bias indistinguishable), in arc-min.",
    ]
    return "\n".join(lines)
