"""Blind simulator of the autocollimator/INS axis-offset calibration data (paper 003, section 3.2).

Provenance: written from the seed text 003 (003_e2e77508c99ae003.redacted.txt, Chinese, numeric
results withheld) and the data format FORMAT.md only, without reading any other implementation.

Physics: an autocollimator rigidly fixed to a strapdown INS; its optical axis deviates from the INS
roll axis by the small azimuth offset gamma and pitch offset lambda (the text's names:
"自准直光轴与惯导轴在方位向偏差角γ" / "在俯仰向偏差角λ" = "the azimuth / pitch offset angle between
the autocollimator optical axis and the INS axis").  Autocollimating on a mirror makes the optical
axis parallel to the mirror normal ("此时自准直经纬仪光轴与平晶表面垂直" = "the autocollimating
theodolite's optical axis is then perpendicular to the flat"), which the theodolite measured.  The
rotation about the optical axis is free: a per-pointing "mount roll" is given or drawn.

Conventions (all angles in the CSV in degrees; gamma, lambda and sigmas in arc-seconds):
 C1 Internal frame: local level NED (x north, y east, z down); internal azimuths are clockwise from
    north seen from above, in radians.  Readings: azimuth/heading = s * internal, s = +1 for
    azimuth_sense "cw", -1 for "ccw"; BOTH the theodolite azimuth and the INS heading increase in the
    same sense (the text does not say which; FORMAT.md leaves it open).
 C2 Elevation and pitch are positive upward (nose up).  Not stated in the text; the customary sense.
 C3 INS attitude (heading psi, pitch theta, roll phi), rotation order heading -> pitch -> roll
    (intrinsic Z-Y-X):  C_b^n = Rz(s*psi) Ry(theta) Rx(phi), body axes x forward = the roll axis
    ("其光轴需和惯导横滚轴平行" = "its optical axis must be parallel to the INS roll axis"), y right,
    z down.  Roll is positive right side down (the usual 右倾为正 / aerospace convention; the text
    does not fix it).  Same sign of roll for both azimuth senses.
 C4 gamma, lambda: the optical axis in the body frame has body azimuth gamma (positive toward
    increasing heading) and body elevation lambda (positive above the roll axis):
    u_b = (cos(l) cos(s*g), cos(l) sin(s*g), -sin(l)).  Signs not fixed by the text.
 C5 "Mirror normal as the theodolite reads it" = the line of sight from the instrument to the mirror
    when autocollimated; the autocollimator's outgoing optical axis points the same way.
 C6 Mount roll = the true INS roll phi at that pointing (one-to-one with the rotation about the
    optical axis, which autocollimation does not fix).  Given (scalar, dict by mirror, or list in
    pointing order C, R, A1.., P1..) or drawn N(0, mount_roll_sigma_deg); the reference pointings
    roll too.  Written only if write_roll.
 C7 roll_mirror_side ("该装置右侧安装一块基准镜,其法线方位与中间基准镜夹角为90°" = "a reference
    mirror is mounted on the right side of the device, its normal at 90° in azimuth to the central
    reference mirror"): "right" means the line of sight to the roll mirror is 90° CLOCKWISE (seen
    from above) from the line of sight to the central mirror, i.e. an observer at the INS facing the
    central mirror turns right.  Reading "right" from the fixture's own viewpoint is our "left".
 C8 Reference axis system ("对该装置中间和右侧两基准镜光学自准,获取基准轴" = "autocollimate on the
    middle and right reference mirrors to obtain the reference axes"; the roll mirror "表征惯导的
    横滚" = "characterises the INS roll"): the INS knows only its own axis, so it builds the frame
    from its roll-axis directions d_C, d_R (from its heading and pitch readings at C and R):
    x_ref = d_C, y_ref = +-(d_R made orthogonal to x_ref) (+ for right, - for left), z_ref =
    x_ref x y_ref.  Relative readings = Z-Y-X Euler angles of C_ref^T C_b, computed exactly from the
    noisy absolute readings (relative heading/pitch depend only on the heading/pitch readings; the
    roll readings at C, R are not used).  The central mirror reads exactly (0, 0).  This reproduces
    the text's "在α=180°时,偏差Δβ几乎是偏差λ的两倍" ("at alpha = 180° the pitch deviation is
    almost twice lambda") for horizontal mirrors.
 C9 Layout (relative to the central mirror, reading sense): C at az 0 el center_el_deg (0); R at
    +-roll_mirror_angle_deg (90) el roll_mirror_el_deg (0); azimuth mirrors A1.. at azimuths_deg
    (-30,-15,15,30,45) el 0; pitch mirrors P1.. at az 0, elevations 4,7.5,11,14.5,18 deg.  The text
    gives only 7 mirrors per family (one a reference), 10 measured mirrors, 90°±15″ and <15″.
 C10 The central line of sight has true heading central_heading_deg (random U[0,360) by default).
    Theodolite azimuth zero: random U[0,360) for files with reference rows; at the central mirror
    for files without (theodolite azimuths then read relative to it, like the paper's table).
    Wrapping: absolute INS heading and theodolite az in [0,360) for files with reference rows;
    theodolite az and relative INS heading in (-180,180] for files without.
 C11 Noise: independent Gaussian on every reading; theodolite default 2″ ("T3经纬仪标定,精度为2″"
    = "calibrated with a T3 theodolite, accuracy 2″"); INS default 5″ (not from the text).  The
    autocollimator points exactly along the true normal.  ins_heading_offset_deg is a constant INS
    heading (self-alignment) error added to all absolute headings; it cancels in relative files.
"""
import argparse
import json
import math
from pathlib import Path

import numpy as np

ARCSEC = math.pi / (180.0 * 3600.0)  # radians per arc-second
BASE_HEADER = ["mirror", "set", "theodolite_az_deg", "theodolite_el_deg", "ins_az_deg", "ins_el_deg"]
DEFAULT_AZIMUTHS = (-30.0, -15.0, 15.0, 30.0, 45.0)
DEFAULT_PITCH_ELS = (4.0, 7.5, 11.0, 14.5, 18.0)


def rot_x(a):
    """Right-handed active rotation about x by a [rad]."""
    c, s = math.cos(a), math.sin(a)
    return np.array([[1.0, 0, 0], [0, c, -s], [0, s, c]])


def rot_y(a):
    """Right-handed active rotation about y by a [rad]."""
    c, s = math.cos(a), math.sin(a)
    return np.array([[c, 0, s], [0, 1.0, 0], [-s, 0, c]])


def rot_z(a):
    """Right-handed active rotation about z by a [rad]."""
    c, s = math.cos(a), math.sin(a)
    return np.array([[c, -s, 0], [s, c, 0], [0, 0, 1.0]])


def euler_to_matrix(psi, theta, phi):
    """Body->NED matrix Rz(psi) Ry(theta) Rx(phi); internal clockwise heading psi [rad]."""
    return rot_z(psi) @ rot_y(theta) @ rot_x(phi)


def matrix_to_euler(c):
    """Inverse of euler_to_matrix -> (psi, theta, phi) [rad]."""
    theta = -math.asin(max(-1.0, min(1.0, c[2, 0])))
    return math.atan2(c[1, 0], c[0, 0]), theta, math.atan2(c[2, 1], c[2, 2])


def direction(az, el):
    """Unit NED vector of internal azimuth az (clockwise from x) and elevation el (up) [rad]."""
    return np.array([math.cos(el) * math.cos(az), math.cos(el) * math.sin(az), -math.sin(el)])


def az_el(v):
    """Internal (azimuth, elevation) [rad] of a vector; inverse of direction()."""
    v = np.asarray(v, float) / np.linalg.norm(v)
    return math.atan2(v[1], v[0]), math.asin(max(-1.0, min(1.0, -v[2])))


def sense_sign(azimuth_sense):
    """+1 for 'cw', -1 for 'ccw' (sense in which theodolite azimuth and INS heading increase)."""
    if azimuth_sense not in ("cw", "ccw"):
        raise ValueError("azimuth_sense must be 'cw' or 'ccw'")
    return 1 if azimuth_sense == "cw" else -1


def wrap360(x):
    """Wrap degrees to [0, 360)."""
    y = math.fmod(x, 360.0)
    y = y + 360.0 if y < 0 else y
    return 0.0 if y >= 360.0 else y


def wrap180(x):
    """Wrap degrees to (-180, 180]."""
    y = -wrap360(-x + 180.0) + 180.0
    return y


def optical_axis_body(gamma_rad, lambda_rad, s):
    """Optical axis in the body frame (convention C4); gamma, lambda in rad, s = sense sign."""
    return direction(s * gamma_rad, lambda_rad)


def solve_attitude(d, u_b, phi):
    """Internal (psi, theta) [rad] such that euler_to_matrix(psi, theta, phi) @ u_b == d, exactly.

    The roll phi is imposed; theta solves the elevation equation, psi the azimuth one.  The branch
    keeps the rotated optical axis pointing forward (cos(theta + mu) > 0).
    """
    w = rot_x(phi) @ u_b
    rho, mu = math.hypot(w[0], w[2]), math.atan2(-w[2], w[0])
    _, el = az_el(d)
    theta = math.asin(math.sin(el) / rho) - mu
    v = rot_y(theta) @ w
    return az_el(d)[0] - math.atan2(v[1], v[0]), theta


def reference_frame(center_reading, roll_reading, roll_mirror_side, s):
    """Reference axis system (C8) from the INS (heading, pitch) readings [deg] at C and R.

    Returns the 3x3 matrix whose columns are x_ref, y_ref, z_ref in the internal NED frame.
    """
    d_c = direction(s * math.radians(center_reading[0]), math.radians(center_reading[1]))
    d_r = direction(s * math.radians(roll_reading[0]), math.radians(roll_reading[1]))
    y = d_r - (d_r @ d_c) * d_c
    y /= np.linalg.norm(y)
    if roll_mirror_side == "left":
        y = -y
    elif roll_mirror_side != "right":
        raise ValueError("roll_mirror_side must be 'right' or 'left'")
    return np.column_stack([d_c, y, np.cross(d_c, y)])


def relative_reading(ref, reading, s):
    """INS reading (heading, pitch, roll) [deg] expressed in the reference frame -> same [deg].

    heading in (-180, 180], exact (Z-Y-X Euler angles of ref^T C_b)."""
    h, p, r = reading
    cb = euler_to_matrix(s * math.radians(h), math.radians(p), math.radians(r))
    psi, theta, phi = matrix_to_euler(ref.T @ cb)
    return wrap180(s * math.degrees(psi)), math.degrees(theta), math.degrees(phi)


def _sigmas(value, n):
    """Broadcast a scalar or a sequence of n sigmas [arcsec]."""
    out = [float(value)] * n if np.isscalar(value) else [float(v) for v in value]
    if len(out) != n:
        raise ValueError(f"expected a scalar or {n} sigmas, got {value!r}")
    return out


def simulate(gamma_arcsec, lambda_arcsec, *, roll_mirror_side="right", azimuth_sense="cw",
             mount_roll_sigma_deg=0.0, mount_rolls_deg=None, write_roll=False, reference_rows=True,
             theodolite_sigma_arcsec=2.0, ins_sigma_arcsec=5.0,
             azimuths_deg=DEFAULT_AZIMUTHS, pitch_elevations_deg=DEFAULT_PITCH_ELS,
             azimuth_mirror_els_deg=None, pitch_mirror_azs_deg=None,
             center_el_deg=0.0, roll_mirror_angle_deg=90.0, roll_mirror_el_deg=0.0,
             central_heading_deg=None, theodolite_zero_heading_deg=None,
             ins_heading_offset_deg=0.0, rng=None):
    """Simulate one calibration session (paper section 3.2) -> (rows, truth).

    gamma_arcsec, lambda_arcsec: true offsets [arcsec] (C4).  theodolite_sigma_arcsec: scalar or
    (az, el); ins_sigma_arcsec: scalar or (heading, pitch, roll) [arcsec].  All layout angles in
    degrees, azimuths relative to the central mirror in the reading sense (C9, C10).  rng: a
    numpy Generator, an int seed or None.  rows: dicts keyed by the CSV columns; truth: every true
    value, noise draw and convention.
    """
    rng = rng if isinstance(rng, np.random.Generator) else np.random.default_rng(rng)
    s = sense_sign(azimuth_sense)
    if roll_mirror_side not in ("right", "left"):
        raise ValueError("roll_mirror_side must be 'right' or 'left'")
    side = 1 if roll_mirror_side == "right" else -1  # +1: clockwise seen from above (C7)
    az_els = [0.0] * len(azimuths_deg) if azimuth_mirror_els_deg is None else azimuth_mirror_els_deg
    p_azs = [0.0] * len(pitch_elevations_deg) if pitch_mirror_azs_deg is None else pitch_mirror_azs_deg
    layout = [("C", "reference_center", 0.0, float(center_el_deg)),
              ("R", "reference_roll", side * s * float(roll_mirror_angle_deg), float(roll_mirror_el_deg))]
    layout += [(f"A{i + 1}", "azimuth", float(a), float(e)) for i, (a, e) in enumerate(zip(azimuths_deg, az_els))]
    layout += [(f"P{i + 1}", "pitch", float(a), float(e)) for i, (a, e) in enumerate(zip(p_azs, pitch_elevations_deg))]
    names = [m[0] for m in layout]

    if central_heading_deg is None:
        central_heading_deg = float(rng.uniform(0.0, 360.0))
    if theodolite_zero_heading_deg is None:
        theodolite_zero_heading_deg = float(rng.uniform(0.0, 360.0)) if reference_rows else central_heading_deg
    if mount_rolls_deg is None:
        rolls = [float(v) for v in rng.normal(0.0, mount_roll_sigma_deg, len(layout))] \
            if mount_roll_sigma_deg > 0 else [0.0] * len(layout)
    elif np.isscalar(mount_rolls_deg):
        rolls = [float(mount_rolls_deg)] * len(layout)
    elif isinstance(mount_rolls_deg, dict):
        rolls = [float(mount_rolls_deg.get(n, 0.0)) for n in names]
    else:
        rolls = [float(v) for v in mount_rolls_deg]
        if len(rolls) != len(layout):
            raise ValueError(f"mount_rolls_deg needs {len(layout)} values in order {names}")
    th_sig = _sigmas(theodolite_sigma_arcsec, 2)
    ins_sig = _sigmas(ins_sigma_arcsec, 3)
    th_noise = rng.normal(0.0, 1.0, (len(layout), 2)) * np.array(th_sig) / 3600.0   # [deg]
    ins_noise = rng.normal(0.0, 1.0, (len(layout), 3)) * np.array(ins_sig) / 3600.0  # [deg]

    u_b = optical_axis_body(gamma_arcsec * ARCSEC, lambda_arcsec * ARCSEC, s)
    wrap_th = wrap360 if reference_rows else wrap180
    pointings = []
    for k, (name, kind, az_rel, el) in enumerate(layout):
        los_heading = central_heading_deg + az_rel  # reading sense [deg]
        d = direction(s * math.radians(los_heading), math.radians(el))
        psi, theta = solve_attitude(d, u_b, math.radians(rolls[k]))
        ins_true = (wrap360(s * math.degrees(psi) + ins_heading_offset_deg), math.degrees(theta), rolls[k])
        th_true = (wrap_th(los_heading - theodolite_zero_heading_deg), el)
        pointings.append(dict(
            mirror=name, set=kind, az_rel_deg=az_rel, el_deg=el, los_heading_deg=wrap360(los_heading),
            mount_roll_deg=rolls[k], theodolite_true=th_true, ins_true=ins_true,
            theodolite_noise_deg=th_noise[k].tolist(), ins_noise_deg=ins_noise[k].tolist(),
            theodolite=(wrap_th(th_true[0] + th_noise[k, 0]), th_true[1] + th_noise[k, 1]),
            ins=(wrap360(ins_true[0] + ins_noise[k, 0]), ins_true[1] + ins_noise[k, 1],
                 ins_true[2] + ins_noise[k, 2])))

    ref = reference_frame(pointings[0]["ins"], pointings[1]["ins"], roll_mirror_side, s)
    ref_true = reference_frame(pointings[0]["ins_true"], pointings[1]["ins_true"], roll_mirror_side, s)
    rows = []
    for p in pointings:
        p["ins_relative"] = relative_reading(ref, p["ins"], s)
        p["ins_relative_true"] = relative_reading(ref_true, p["ins_true"], s)
        if not reference_rows and p["set"].startswith("reference"):
            continue
        ins = p["ins"] if reference_rows else p["ins_relative"]
        row = dict(mirror=p["mirror"], set=p["set"], theodolite_az_deg=p["theodolite"][0],
                   theodolite_el_deg=p["theodolite"][1], ins_az_deg=ins[0], ins_el_deg=ins[1])
        if write_roll:
            row["ins_roll_deg"] = ins[2]
        rows.append(row)

    truth = dict(
        gamma_arcsec=float(gamma_arcsec), lambda_arcsec=float(lambda_arcsec),
        roll_mirror_side=roll_mirror_side, azimuth_sense=azimuth_sense,
        reference_rows=bool(reference_rows), write_roll=bool(write_roll),
        mount_roll_sigma_deg=float(mount_roll_sigma_deg),
        theodolite_sigma_arcsec=th_sig, ins_sigma_arcsec=ins_sig,
        central_heading_deg=float(central_heading_deg),
        theodolite_zero_heading_deg=float(theodolite_zero_heading_deg),
        ins_heading_offset_deg=float(ins_heading_offset_deg),
        center_el_deg=float(center_el_deg), roll_mirror_angle_deg=float(roll_mirror_angle_deg),
        roll_mirror_el_deg=float(roll_mirror_el_deg),
        optical_axis_body_ned=u_b.tolist(),
        reference_frame_noisy=ref.tolist(), reference_frame_true=ref_true.tolist(),
        pointings=pointings,
        conventions=dict(
            internal_frame="NED, internal azimuth clockwise from north seen from above",
            azimuth_sense=f"{azimuth_sense}: theodolite azimuth and INS heading both increase "
                          f"{'clockwise' if s > 0 else 'counter-clockwise'} seen from above",
            elevation_pitch="positive up (nose up)",
            attitude="C_b^n = Rz(s*heading) Ry(pitch) Rx(roll), intrinsic heading->pitch->roll; "
                     "body x forward (roll axis), y right, z down",
            roll_sign="positive right side down",
            gamma_lambda="optical axis in body: azimuth gamma (toward increasing heading), "
                         "elevation lambda (up) relative to the roll axis",
            roll_mirror_side=f"{roll_mirror_side}: line of sight to the roll mirror is 90 deg "
                             f"{'clockwise' if side > 0 else 'counter-clockwise'} seen from above "
                             "from the line of sight to the central mirror",
            reference_frame="x=d_C, y=+-(d_R orthogonalised), z=x cross y, from INS heading/pitch "
                            "readings at C and R; relative = ZYX Euler of ref^T C_b",
            mount_roll="true INS roll at each pointing",
            theodolite_az_wrap="[0,360)" if reference_rows else "(-180,180], zero default at C",
            ins_heading_wrap="[0,360) absolute" if reference_rows else "(-180,180] relative"))
    return rows, truth


def write_csv(path, rows, with_roll=None):
    """Write rows to path with the exact header of FORMAT.md; roll column if asked / present."""
    if with_roll is None:
        with_roll = any("ins_roll_deg" in r for r in rows)
    header = BASE_HEADER + (["ins_roll_deg"] if with_roll else [])
    lines = [",".join(header)]
    for r in rows:
        cells = [str(r["mirror"]), str(r["set"])] + [f"{float(r[h]):.9f}" for h in header[2:]]
        lines.append(",".join(cells))
    Path(path).write_text("\n".join(lines) + "\n")


def _floats(text):
    return [float(x) for x in text.split(",") if x.strip()]


def main(argv=None):
    """Command line: python collimation_blind.py OUT.csv --seed N ...; writes OUT.truth.json too."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("out")
    ap.add_argument("--seed", type=int, default=None)
    ap.add_argument("--gamma-arcsec", type=float, default=0.0)
    ap.add_argument("--lambda-arcsec", type=float, default=0.0)
    ap.add_argument("--roll-mirror-side", choices=("right", "left"), default="right")
    ap.add_argument("--azimuth-sense", choices=("cw", "ccw"), default="cw")
    ap.add_argument("--no-reference-rows", action="store_true")
    ap.add_argument("--with-roll", action="store_true")
    ap.add_argument("--mount-roll-sigma-deg", type=float, default=0.0)
    ap.add_argument("--mount-roll-deg", type=float, default=None, help="fixed roll at every pointing")
    ap.add_argument("--theodolite-sigma-arcsec", type=float, default=2.0)
    ap.add_argument("--ins-sigma-arcsec", type=float, default=5.0)
    ap.add_argument("--azimuths-deg", type=_floats, default=list(DEFAULT_AZIMUTHS))
    ap.add_argument("--pitch-elevations-deg", type=_floats, default=list(DEFAULT_PITCH_ELS))
    ap.add_argument("--central-heading-deg", type=float, default=None)
    ap.add_argument("--theodolite-zero-deg", type=float, default=None)
    ap.add_argument("--ins-heading-offset-deg", type=float, default=0.0)
    ap.add_argument("--roll-mirror-angle-deg", type=float, default=90.0)
    ap.add_argument("--roll-mirror-el-deg", type=float, default=0.0)
    ap.add_argument("--center-el-deg", type=float, default=0.0)
    a = ap.parse_args(argv)
    rows, truth = simulate(
        a.gamma_arcsec, a.lambda_arcsec, roll_mirror_side=a.roll_mirror_side,
        azimuth_sense=a.azimuth_sense, mount_roll_sigma_deg=a.mount_roll_sigma_deg,
        mount_rolls_deg=a.mount_roll_deg, write_roll=a.with_roll,
        reference_rows=not a.no_reference_rows, theodolite_sigma_arcsec=a.theodolite_sigma_arcsec,
        ins_sigma_arcsec=a.ins_sigma_arcsec, azimuths_deg=a.azimuths_deg,
        pitch_elevations_deg=a.pitch_elevations_deg, central_heading_deg=a.central_heading_deg,
        theodolite_zero_heading_deg=a.theodolite_zero_deg,
        ins_heading_offset_deg=a.ins_heading_offset_deg, center_el_deg=a.center_el_deg,
        roll_mirror_angle_deg=a.roll_mirror_angle_deg, roll_mirror_el_deg=a.roll_mirror_el_deg,
        rng=a.seed)
    out = Path(a.out)
    write_csv(out, rows, with_roll=a.with_roll)
    truth["seed"] = a.seed
    truth["argv"] = vars(a)
    out.with_name(out.stem + ".truth.json").write_text(json.dumps(truth, indent=1))
    return rows, truth


if __name__ == "__main__":
    main()
