"""Simulated data of seed 003's measuring procedure (section 3.2): an INS carrying an
autocollimator autocollimates a central and a roll reference mirror, then each measured mirror,
and its attitudes are written as the calibration CSV
``mirror,set,theodolite_az_deg,theodolite_el_deg,ins_az_deg,ins_el_deg[,ins_roll_deg]``.

Conventions (radians inside, degrees in files and layouts, arc-seconds for small angles):

- navigation frame n: x east, y north, z up; ``direction(az, el) = [sin az cos el,
  cos az cos el, sin el]`` (azimuth clockwise from above, elevation up).
- mirror frame t: levelled; theodolite azimuth ``az`` points at heading ``az + h_t``.
- INS body b: x right, y roll axis, z up; ``C_b^n = Rotation.from_euler("ZXY", [-psi, theta,
  phi])`` with heading psi (clockwise), pitch theta (up), roll phi (right side down).
- optical axis in b: ``u = direction(gamma, lam)``: gamma > 0 turns it right, lam > 0 up.
- autocollimation on mirror k: ``C_k u = C_t^n direction(az_k, el_k)``; the roll about the
  optical axis is fixed by the INS's own absolute roll ``phi_k`` (0 on a level mount).
- reference R: ``y_R = C_c e_y``, ``x_R = s * unit(C_r e_y - (C_r e_y . y_R) y_R)`` (s = +1 roll
  mirror right, -1 left), ``z_R = x_R x y_R``; readings relative to R decompose ``C_R^T C_k``.

With reference rows every INS reading is absolute (in n); without, the measured rows hold the
readings relative to R. INS readings carry N(0, sigma_ins) noise, theodolite readings
N(0, sigma_theodolite) noise; the geometry uses the true mirror angles.
"""

import argparse
import csv
import io
import sys
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

ARCSEC = np.pi / 648000.0
"""One arc-second [rad]."""
DEG = np.pi / 180.0
"""One degree [rad]."""

Layout = list[tuple[str, str, float, float]]
"""Rows ``(mirror, set, theodolite_az_deg, theodolite_el_deg)`` of true mirror normals [deg]."""


def direction(az: float, el: float) -> np.ndarray:
    """Unit vector of azimuth ``az`` [rad] (clockwise from north) and elevation ``el`` [rad]."""
    return np.array([np.sin(az) * np.cos(el), np.cos(az) * np.cos(el), np.sin(el)])


def attitude(heading: float, pitch: float, roll: float) -> np.ndarray:
    """INS attitude C_b^n from heading, pitch, roll [rad] (seed 003, Z-X-Y rule)."""
    return Rotation.from_euler("ZXY", [-heading, pitch, roll]).as_matrix()


def euler_readings(c: np.ndarray) -> np.ndarray:
    """Heading, pitch, roll [rad] of an attitude matrix by the Z-X-Y rule; inverse of attitude."""
    a, pitch, roll = Rotation.from_matrix(c).as_euler("ZXY")
    return np.array([-a, pitch, roll])


def point_ins(u: np.ndarray, v: np.ndarray, roll: float) -> np.ndarray:
    """Attitude C with ``C u = v`` and absolute roll ``roll`` [rad] (autocollimation, sec. 3.2).

    With ``w = R_y(roll) u`` the pitch solves ``(R_x(pitch) w)_z = v_z`` (the upright solution)
    and the heading turns the horizontal part of ``R_x(pitch) w`` onto that of ``v``.
    """
    w = Rotation.from_euler("Y", roll).apply(u)
    radius, alpha = np.hypot(w[1], w[2]), np.arctan2(w[2], w[1])
    if abs(v[2]) > radius:
        raise ValueError(f"no attitude with roll {roll / DEG:.3f} deg points the axis at {v}")
    base = np.arcsin(v[2] / radius)
    candidates = np.angle(np.exp(1j * (np.array([base, np.pi - base]) - alpha)))
    pitch = candidates[np.argmin(np.abs(candidates))]
    p = Rotation.from_euler("X", pitch).apply(w)
    heading = np.arctan2(v[0], v[1]) - np.arctan2(p[0], p[1])
    c = attitude(heading, pitch, roll)
    miss = np.linalg.norm(c @ u - v)
    if miss > 1e-12:
        raise ArithmeticError(f"pointing misses the mirror normal by {miss:.3e} rad")
    return c


def reference_frame(c_center: np.ndarray, c_roll: np.ndarray, roll_mirror: str) -> np.ndarray:
    """C_R^n = [x_R y_R z_R] from the INS attitudes on the central and roll reference mirrors."""
    side = {"right": 1.0, "left": -1.0}[roll_mirror]
    y = c_center[:, 1]
    x = c_roll[:, 1] - (c_roll[:, 1] @ y) * y
    x = side * x / np.linalg.norm(x)
    return np.column_stack([x, y, np.cross(x, y)])


def _layout(pitch_elevations: tuple[float, ...], roll_mirror: str) -> Layout:
    roll_az = {"right": 90.0, "left": -90.0}[roll_mirror]
    return [
        ("C", "reference_center", 0.0, 0.0),
        ("R" if roll_mirror == "right" else "L", "reference_roll", roll_az, 0.0),
        *[(f"A{i + 1}", "azimuth", az, 0.0) for i, az in enumerate((-30, -15, 15, 30, 45))],
        *[(f"P{i + 1}", "pitch", 0.0, el) for i, el in enumerate(pitch_elevations)],
    ]


def paper_like_layout(roll_mirror: str = "right") -> Layout:
    """Seed 003's fixture: centre (0, 0), roll mirror at +-90 deg, 5 azimuth and 5 pitch mirrors."""
    return _layout((4.0, 7.5, 11.0, 14.5, 18.0), roll_mirror)


def pitch_to_60_layout(roll_mirror: str = "right") -> Layout:
    """The paper-like layout with pitch mirrors at 12, 24, 36, 48, 60 deg elevation."""
    return _layout((12.0, 24.0, 36.0, 48.0, 60.0), roll_mirror)


def simulate_procedure(
    layout: Layout,
    gamma_arcsec: float,
    lam_arcsec: float,
    *,
    rng: np.random.Generator,
    sigma_theodolite_arcsec: float,
    sigma_ins_arcsec: float,
    roll_sigma_deg: float = 0.0,
    record_roll: bool = False,
    roll_mirror: str = "right",
    reference_rows: bool = True,
    heading_of_theodolite_zero_deg: float = 40.0,
) -> str:
    """CSV text of one calibration: the procedure run with offsets gamma, lam [arcsec].

    Absolute INS rolls are N(0, roll_sigma_deg) at every pointing (0: level mount). The random
    draws (rolls, theodolite noise, INS noise) do not depend on ``reference_rows``,
    ``record_roll`` or ``heading_of_theodolite_zero_deg``.
    """
    sets = [row[1] for row in layout]
    if sets.count("reference_center") != 1 or sets.count("reference_roll") != 1:
        raise ValueError("layout needs exactly one reference_center and one reference_roll row")
    if roll_mirror not in ("right", "left"):
        raise ValueError(f"roll_mirror must be 'right' or 'left', not {roll_mirror!r}")
    true = np.array([[az, el] for _, _, az, el in layout], dtype=float) * DEG
    center, roll_row = sets.index("reference_center"), sets.index("reference_roll")
    side = np.sin(true[roll_row, 0] - true[center, 0])
    if side * (1.0 if roll_mirror == "right" else -1.0) <= 0.0:
        raise ValueError(f"the reference_roll mirror is not on the {roll_mirror} of the centre")
    u = direction(gamma_arcsec * ARCSEC, lam_arcsec * ARCSEC)
    heading_t = heading_of_theodolite_zero_deg * DEG
    rolls = rng.normal(0.0, roll_sigma_deg * DEG, size=len(layout))
    theodolite = true + rng.normal(0.0, sigma_theodolite_arcsec * ARCSEC, size=true.shape)
    ins_noise = rng.normal(0.0, sigma_ins_arcsec * ARCSEC, size=(len(layout), 3))
    cs = [point_ins(u, direction(az + heading_t, el), phi)
          for (az, el), phi in zip(true, rolls, strict=True)]
    c_ref = reference_frame(cs[center], cs[roll_row], roll_mirror)

    header = ["mirror", "set", "theodolite_az_deg", "theodolite_el_deg", "ins_az_deg",
              "ins_el_deg"] + (["ins_roll_deg"] if record_roll else [])
    out = io.StringIO()
    writer = csv.writer(out, lineterminator="\n")
    writer.writerow(header)
    for k, (mirror, kind, _, _) in enumerate(layout):
        if not reference_rows and kind.startswith("reference"):
            continue
        c = cs[k] if reference_rows else c_ref.T @ cs[k]
        reading = euler_readings(c) + ins_noise[k]
        values = [*theodolite[k], *reading[: 3 if record_roll else 2]]
        writer.writerow([mirror, kind, *(repr(float(x / DEG)) for x in values)])
    return out.getvalue()


def main(argv: list[str] | None = None) -> int:
    """``python -m tests.independent.collimation_procedure OUT.csv --gamma-arcsec G ...``."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("out", type=Path, help="CSV file to write")
    parser.add_argument("--gamma-arcsec", type=float, required=True, help="azimuth offset")
    parser.add_argument("--lam-arcsec", type=float, required=True, help="pitch offset")
    parser.add_argument("--seed", type=int, required=True)
    parser.add_argument("--sigma-theodolite-arcsec", type=float, default=2.0)
    parser.add_argument("--sigma-ins-arcsec", type=float, required=True)
    parser.add_argument("--roll-sigma-deg", type=float, default=0.0)
    parser.add_argument("--record-roll", action="store_true")
    parser.add_argument("--roll-mirror", choices=("right", "left"), default="right")
    parser.add_argument("--no-reference-rows", action="store_true")
    parser.add_argument("--heading-of-theodolite-zero-deg", type=float, default=40.0)
    parser.add_argument("--layout", choices=("paper", "pitch60"), default="paper")
    args = parser.parse_args(argv)
    for name in ("sigma_theodolite_arcsec", "sigma_ins_arcsec", "roll_sigma_deg"):
        if not getattr(args, name) >= 0.0:
            parser.error(f"--{name.replace('_', '-')} must be >= 0, got {getattr(args, name)}")
    build = paper_like_layout if args.layout == "paper" else pitch_to_60_layout
    text = simulate_procedure(
        build(args.roll_mirror), args.gamma_arcsec, args.lam_arcsec,
        rng=np.random.default_rng(args.seed),
        sigma_theodolite_arcsec=args.sigma_theodolite_arcsec,
        sigma_ins_arcsec=args.sigma_ins_arcsec, roll_sigma_deg=args.roll_sigma_deg,
        record_roll=args.record_roll, roll_mirror=args.roll_mirror,
        reference_rows=not args.no_reference_rows,
        heading_of_theodolite_zero_deg=args.heading_of_theodolite_zero_deg)
    try:
        args.out.write_text(text)
    except OSError as exc:
        print(f"error: cannot write {args.out}: {exc.strerror}", file=sys.stderr)
        return 2
    return 0


if __name__ == "__main__":
    sys.exit(main())
