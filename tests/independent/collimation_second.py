"""Second, independent simulator of autocollimator-INS axis-offset calibration readings (seed 003).

Given: only BRIEF.md (task + CSV/JSON format) and seed003.txt (Chinese paper, numeric results
withheld).  No other code or document was read.  numpy only (scipy only in the tests).

Geometry (section 2 / 3.2 of the text): an autocollimator sits on a strapdown INS; its optical axis
should be parallel to the INS roll axis but is off by an azimuth angle gamma and a pitch angle
lambda ("方位向偏差角γ", "俯仰向偏差角λ").  A fixture carries mirrors whose normals a theodolite
(T3, 2") measured; the INS autocollimates on each mirror, i.e. its optical axis is made parallel to
the mirror normal, and its attitude is read.  Procedure 3.2: first the centre reference mirror and the
right-hand roll reference mirror ("获取基准轴"), then the azimuth- and pitch-family mirrors.

ASSUMPTIONS (passage they rest on; * = exposed as argument)
 A1 Local level frame NED (x north, y east, z down); INS body frame x = roll axis (forward), y right,
    z down.  Attitude C_b^n from heading psi, pitch theta, roll phi.  *euler_sequence:
    'heading-pitch-roll' C=Rz(psi)Ry(theta)Rx(phi) (default) or 'heading-roll-pitch'
    C=Rz(psi)Rx(phi)Ry(theta).  (text gives no order; "惯导横滚轴" = roll axis is the body x axis.)
 A2 Heading clockwise from north seen from above (*ins_heading_sense 'cw'/'ccw'); pitch nose-up
    positive (the text's "俯仰" with elevation up positive, brief); roll positive right side down
    (*ins_roll_positive 'right_down'/'left_down').  Text silent on senses.
 A3 Offset definition: optical-axis unit vector in body = Rz(gamma) Ry(lambda) [1,0,0]
    = (cos l cos g, cos l sin g, -sin l): gamma>0 axis points right of the roll axis, lambda>0 up.
    (section 2: "自准直光轴与惯导轴在方位向/俯仰向存在偏差").
 A4 Autocollimation = optical axis along the theodolite line of sight into the mirror (inward
    normal).  The theodolite az/el written are of that line of sight (*theodolite_direction
    'line_of_sight' or 'outward_normal' = az+180, -el).  Theodolite azimuth = sense*(true az - zero)
    (*theodolite_az_sense, *theodolite_az_zero_deg).  Text: "利用自准直经纬仪将每面反射镜的法线调整至水平".
 A5 The INS roll is the free third degree of freedom: the INS sits on a level az/el mount and keeps a
    roll *mount_roll_deg (+ per-pointing hidden jitter *mount_roll_jitter_arcsec); heading and pitch
    are whatever makes the optical axis hit the mirror normal (closed form, below).
 A6 Fixture frame F: x = line of sight into the centre reference mirror, y right, z down, placed at
    *setup_heading_deg, *fixture_pitch_deg, *fixture_roll_deg (ZYX) in NED.  Azimuth-family mirror a:
    Rz(a)[1,0,0]; pitch-family mirror b: Ry(b)[1,0,0] (elevation b up); roll reference mirror:
    Rz(+-90deg)[1,0,0] (*roll_mirror_side 'right' = clockwise of the centre line of sight as seen
    from above by the INS looking at the centre mirror; text: "该装置右侧安装一块基准镜,其法线方位
    与中间基准镜夹角为90°").  Hidden fixture errors (text, 3.1): off-plane angle of each family mirror
    and elevation/azimuth error of the roll mirror uniform in +-*mirror_tolerance_arcsec (15").
 A7 Reference axes (3.2 "获取基准轴"), *reference_axes:
    'mirror_frame' (default): x_r = INS body x axis (heading/pitch reading) at the centre mirror,
      y_r = body x axis at the roll mirror orthogonalised to x_r (sign flipped if the roll mirror is on
      the left), z_r = x_r cross y_r.  The roll mirror thus fixes the roll of the reference ("表征
      惯导的横滚").  'center_attitude': reference = full INS attitude read at the centre mirror.
    Relative reading = Euler angles (same sequence/senses) of C_r^T C_b, built from the NOISY INS
    readings.  Heading relative is wrapped to (-180,180]; absolute heading to [0,360).
    Check against the text: gamma only -> level mirrors give (alpha,0) exactly; lambda only ->
    relative pitch at alpha=180 is -2*lambda ("Δβ几乎是偏差λ的两倍"); gamma only, beta=60 ->
    relative heading = -gamma ("在β=60°时...与偏差γ相等", read as Δα).
 A8 Noise: independent Gaussian per written angle; theodolite sigma on az and on el (2", T3 "精度为2″"
    read as 1 sigma); INS sigma per heading/pitch/roll.  All random numbers are drawn for all rows
    (reference rows included) in a fixed order, so a file with and one without reference rows from
    the same seed share every draw.  Zero noise -> exact readings.
SCENARIO NUMBERS: from the text: 15" fixture tolerances, 90deg roll mirror, 2" theodolite, 10 measured
 mirrors (3.2).  Mine: mirror angles (az -45,-20,20,45,70; pitch -30,-15,15,30,60 - 60 echoes the
 text's beta=60), 5+5 split, offsets gamma=180", lambda=-108" (within the text's 0.02-0.1deg range),
 INS sigmas 8"/3"/3", mount roll 0.4deg, roll jitter 20", setup heading 37.5deg, theodolite zero
 123.4deg, fixture level.
"""
import csv
import json
import os

import numpy as np

AS = np.pi / (180.0 * 3600.0)  # one arc-second in rad
D = np.pi / 180.0


def rx(a):
    c, s = np.cos(a), np.sin(a)
    return np.array([[1, 0, 0], [0, c, -s], [0, s, c]])


def ry(a):
    c, s = np.cos(a), np.sin(a)
    return np.array([[c, 0, s], [0, 1, 0], [-s, 0, c]])


def rz(a):
    c, s = np.cos(a), np.sin(a)
    return np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])


def attitude_matrix(psi, theta, phi, seq="heading-pitch-roll"):
    """C_b^n (body -> NED) from heading, pitch, roll [rad] in the internal (cw, right-down) senses."""
    if seq == "heading-pitch-roll":
        return rz(psi) @ ry(theta) @ rx(phi)
    if seq == "heading-roll-pitch":
        return rz(psi) @ rx(phi) @ ry(theta)
    raise ValueError(seq)


def attitude_angles(C, seq="heading-pitch-roll"):
    """Inverse of attitude_matrix: (psi, theta, phi) [rad], theta or phi in [-90, 90] deg."""
    if seq == "heading-pitch-roll":
        return (np.arctan2(C[1, 0], C[0, 0]), np.arcsin(np.clip(-C[2, 0], -1, 1)),
                np.arctan2(C[2, 1], C[2, 2]))
    if seq == "heading-roll-pitch":
        return (np.arctan2(-C[0, 1], C[1, 1]), np.arctan2(-C[2, 0], C[2, 2]),
                np.arcsin(np.clip(C[2, 1], -1, 1)))
    raise ValueError(seq)


def direction(az, el):
    """NED unit vector of azimuth az (cw from north) and elevation el (up) [rad]."""
    return np.array([np.cos(el) * np.cos(az), np.cos(el) * np.sin(az), -np.sin(el)])


def az_el(v):
    v = np.asarray(v, float) / np.linalg.norm(v)
    return np.arctan2(v[1], v[0]), np.arcsin(np.clip(-v[2], -1, 1))


def optical_axis(gamma, lam):
    """Optical-axis unit vector in the INS body frame (assumption A3)."""
    return rz(gamma) @ ry(lam) @ np.array([1.0, 0.0, 0.0])


def wrap(a, lo=-np.pi):
    return (a - lo) % (2 * np.pi) + lo


def solve_pointing(d, phi, u, seq="heading-pitch-roll"):
    """Heading and pitch [rad] that put body vector u on NED direction d at roll phi (A5).

    The z (down) component fixes pitch: -sin(th) a_x + cos(th) a_z = k = R cos(th + delta); the
    branch with |pitch| <= 90 deg is kept; heading then rotates the azimuth onto that of d."""
    d = np.asarray(d, float) / np.linalg.norm(d)
    if seq == "heading-pitch-roll":
        a, k = rx(phi) @ u, d[2]
    else:
        a, k = u, (d[2] - np.sin(phi) * u[1]) / np.cos(phi)
    R, delta = np.hypot(a[0], a[2]), np.arctan2(a[0], a[2])
    ac = np.arccos(np.clip(k / R, -1.0, 1.0))
    theta = min((wrap(ac - delta), wrap(-ac - delta)), key=abs)
    w = attitude_matrix(0.0, theta, phi, seq) @ u
    psi = az_el(d)[0] - np.arctan2(w[1], w[0])
    return wrap(psi), theta


def reference_frame(att_center, att_roll, mode="mirror_frame", side="right",
                    seq="heading-pitch-roll"):
    """C_r^n of the reference axes from the INS attitudes read at the two reference mirrors (A7)."""
    Cc = attitude_matrix(*att_center, seq)
    if mode == "center_attitude":
        return Cc
    if mode != "mirror_frame":
        raise ValueError(mode)
    x = Cc[:, 0]
    xr = attitude_matrix(*att_roll, seq)[:, 0]
    y = xr - (xr @ x) * x
    y = (1.0 if side == "right" else -1.0) * y / np.linalg.norm(y)
    return np.column_stack([x, y, np.cross(x, y)])


def simulate(azimuth_mirrors_deg=(-45.0, -20.0, 20.0, 45.0, 70.0),
             pitch_mirrors_deg=(-30.0, -15.0, 15.0, 30.0, 60.0),
             azimuth_offset_arcsec=180.0, pitch_offset_arcsec=-108.0,
             setup_heading_deg=37.5, fixture_pitch_deg=0.0, fixture_roll_deg=0.0,
             mount_roll_deg=0.4, mount_roll_jitter_arcsec=20.0, mirror_tolerance_arcsec=15.0,
             theodolite_sigma_arcsec=2.0, ins_heading_sigma_arcsec=8.0,
             ins_pitch_sigma_arcsec=3.0, ins_roll_sigma_arcsec=3.0,
             roll_mirror_side="right", reference_axes="mirror_frame",
             euler_sequence="heading-pitch-roll", ins_heading_sense="cw",
             ins_roll_positive="right_down", theodolite_az_sense="cw",
             theodolite_az_zero_deg=123.4, theodolite_direction="line_of_sight",
             include_reference_rows=True, include_roll=True, seed=3):
    """Simulate one calibration (procedure of section 3.2).  Angles: *_deg in degrees,
    *_arcsec in arc-seconds.  Returns (header, rows, truth); rows are lists matching header."""
    for name, val, ok in (("roll_mirror_side", roll_mirror_side, ("right", "left")),
                          ("reference_axes", reference_axes, ("mirror_frame", "center_attitude")),
                          ("euler_sequence", euler_sequence, ("heading-pitch-roll", "heading-roll-pitch")),
                          ("ins_heading_sense", ins_heading_sense, ("cw", "ccw")),
                          ("ins_roll_positive", ins_roll_positive, ("right_down", "left_down")),
                          ("theodolite_az_sense", theodolite_az_sense, ("cw", "ccw")),
                          ("theodolite_direction", theodolite_direction, ("line_of_sight", "outward_normal"))):
        if val not in ok:
            raise ValueError(f"{name} must be one of {ok}, got {val!r}")
    rng = np.random.default_rng(seed)
    seq = euler_sequence
    gamma, lam = azimuth_offset_arcsec * AS, pitch_offset_arcsec * AS
    u = optical_axis(gamma, lam)
    C_F = attitude_matrix(setup_heading_deg * D, fixture_pitch_deg * D, fixture_roll_deg * D,
                          "heading-pitch-roll")
    side = 1.0 if roll_mirror_side == "right" else -1.0
    naz, npi = len(azimuth_mirrors_deg), len(pitch_mirrors_deg)
    n = 2 + naz + npi
    # ---- hidden errors, drawn in a fixed order for all rows ----
    tol = mirror_tolerance_arcsec * AS
    err_az_set = rng.uniform(-tol, tol, naz)      # elevation error of azimuth-family mirrors
    err_pitch_set = rng.uniform(-tol, tol, npi)   # azimuth error of pitch-family mirrors
    err_roll_mirror = rng.uniform(-tol, tol, 2)   # (azimuth from 90 deg, elevation) of roll mirror
    roll_true = mount_roll_deg * D + rng.normal(0.0, 1.0, n) * mount_roll_jitter_arcsec * AS
    theo_noise = rng.normal(0.0, 1.0, (n, 2)) * theodolite_sigma_arcsec * AS
    ins_noise = rng.normal(0.0, 1.0, (n, 3)) * np.array(
        [ins_heading_sigma_arcsec, ins_pitch_sigma_arcsec, ins_roll_sigma_arcsec]) * AS
    # ---- mirrors: (name, set, line of sight in fixture frame, nominal fixture angles) ----
    mirrors = [("REF_C", "reference_center", direction(0.0, 0.0), (0.0, 0.0)),
               ("REF_R", "reference_roll",
                direction(side * np.pi / 2 + err_roll_mirror[0], err_roll_mirror[1]),
                (side * 90.0, 0.0))]
    for i, a in enumerate(azimuth_mirrors_deg):
        mirrors.append((f"A{i + 1}", "azimuth", direction(a * D, err_az_set[i]), (a, 0.0)))
    for j, b in enumerate(pitch_mirrors_deg):
        mirrors.append((f"P{j + 1}", "pitch", direction(err_pitch_set[j], b * D), (0.0, b)))
    # ---- true geometry and readings ----
    true_att, meas_att, theo, truth_rows = [], [], [], []
    for k, (name, st, dF, nominal) in enumerate(mirrors):
        d = C_F @ dF
        psi, theta = solve_pointing(d, roll_true[k], u, seq)
        true_att.append((psi, theta, roll_true[k]))
        meas_att.append(tuple(np.array([psi, theta, roll_true[k]]) + ins_noise[k]))
        az, el = az_el(d)
        if theodolite_direction == "outward_normal":
            az, el = az + np.pi, -el
        az_r = (az - theodolite_az_zero_deg * D) if theodolite_az_sense == "cw" \
            else (theodolite_az_zero_deg * D - az)
        theo.append((wrap(az_r + theo_noise[k, 0], 0.0), el + theo_noise[k, 1]))
        truth_rows.append({"mirror": name, "set": st, "nominal_fixture_az_el_deg": list(nominal),
                           "true_los_az_deg": float(np.degrees(wrap(az_el(d)[0], 0.0))),
                           "true_los_el_deg": float(np.degrees(az_el(d)[1])),
                           "true_ins_heading_pitch_roll_deg":
                               [float(np.degrees(wrap(psi, 0.0))), float(np.degrees(theta)),
                                float(np.degrees(roll_true[k]))]})
    Cr = reference_frame(meas_att[0], meas_att[1], reference_axes, roll_mirror_side, seq)
    hs = 1.0 if ins_heading_sense == "cw" else -1.0
    rs = 1.0 if ins_roll_positive == "right_down" else -1.0
    header = ["mirror", "set", "theodolite_az_deg", "theodolite_el_deg", "ins_az_deg", "ins_el_deg"]
    header += ["ins_roll_deg"] if include_roll else []
    rows = []
    for k, (name, st, _, _) in enumerate(mirrors):
        if include_reference_rows:
            psi, theta, phi = meas_att[k]
            h = wrap(hs * psi, 0.0)
        else:
            if st.startswith("reference"):
                continue
            psi, theta, phi = attitude_angles(Cr.T @ attitude_matrix(*meas_att[k], seq), seq)
            h = wrap(hs * psi)
        row = [name, st] + [float(np.degrees(x)) for x in (theo[k][0], theo[k][1], h, theta)]
        row += [float(np.degrees(rs * phi))] if include_roll else []
        rows.append(row)
    truth = {
        "given": "BRIEF.md and seed003.txt only",
        "offsets_arcsec": {"azimuth_offset_gamma": azimuth_offset_arcsec,
                           "pitch_offset_lambda": pitch_offset_arcsec},
        "offset_definition": "optical-axis unit vector in INS body frame (x=roll axis forward, y right, "
                             "z down) u = Rz(gamma) Ry(lambda) [1,0,0] = (cos l cos g, cos l sin g, -sin l); "
                             "gamma>0: optical axis right of the INS roll axis; lambda>0: optical axis above it",
        "noise_arcsec_1sigma": {"theodolite_az": theodolite_sigma_arcsec, "theodolite_el": theodolite_sigma_arcsec,
                                "ins_heading": ins_heading_sigma_arcsec, "ins_pitch": ins_pitch_sigma_arcsec,
                                "ins_roll": ins_roll_sigma_arcsec},
        "seed": seed,
        "conventions": {
            "local_frame": "NED (x north, y east, z down); elevation up positive",
            "body_frame": "x forward = INS roll axis, y right, z down",
            "euler_sequence": euler_sequence,
            "euler_sequence_meaning": "heading-pitch-roll: C_b^n=Rz(h)Ry(p)Rx(r); heading-roll-pitch: C_b^n=Rz(h)Rx(r)Ry(p)",
            "ins_heading_sense": ins_heading_sense + " seen from above (cw = from north towards east)",
            "ins_pitch_sense": "nose up positive",
            "ins_roll_positive": ins_roll_positive,
            "ins_heading_range": "[0,360) absolute; (-180,180] relative",
            "theodolite_direction": theodolite_direction + " (line_of_sight = direction from the instrument into "
                                    "the mirror = autocollimator optical axis direction at autocollimation)",
            "theodolite_az_sense": theodolite_az_sense,
            "theodolite_az_zero_deg": theodolite_az_zero_deg,
            "theodolite_az_zero_meaning": "true azimuth (cw from north) at which the horizontal circle reads 0",
            "roll_mirror_side": roll_mirror_side + " (roll mirror line of sight at +90 deg cw (right) or -90 deg "
                                "(left) from the centre line of sight, seen from above by the INS facing the fixture)",
            "reference_axes": reference_axes,
            "reference_axes_meaning": "mirror_frame: x_r = INS body x at centre mirror, y_r = body x at roll "
                                      "mirror orthogonalised (sign so y_r points right), z_r = x_r x y_r; "
                                      "center_attitude: INS attitude read at centre mirror. Relative reading = "
                                      "Euler angles of C_r^T C_b from noisy readings",
            "fixture_mirror_geometry": "fixture frame x = centre line of sight; azimuth mirror a: Rz(a)[1,0,0]; "
                                       "pitch mirror b: Ry(b)[1,0,0] (b up)",
            "include_reference_rows": include_reference_rows, "include_roll": include_roll},
        "scenario": {"azimuth_mirrors_deg": list(map(float, azimuth_mirrors_deg)),
                     "pitch_mirrors_deg": list(map(float, pitch_mirrors_deg)),
                     "setup_heading_deg": setup_heading_deg, "mount_roll_deg": mount_roll_deg,
                     "sources": "from the text: 15 arcsec fixture tolerances, 90 deg roll mirror, 2 arcsec "
                                "theodolite (T3), 10 measured mirrors; all other numbers chosen by the author"},
        "hidden_errors": {
            "fixture_pitch_deg": {"value": fixture_pitch_deg, "definition": "pitch of fixture frame in NED (ZYX)"},
            "fixture_roll_deg": {"value": fixture_roll_deg, "definition": "roll of fixture frame in NED (ZYX), right down +"},
            "azimuth_mirror_elevation_error_arcsec": {
                "value": list(err_az_set / AS), "definition": "elevation of each azimuth mirror above the fixture x-y plane"},
            "pitch_mirror_azimuth_error_arcsec": {
                "value": list(err_pitch_set / AS), "definition": "azimuth of each pitch mirror from the fixture x-z plane"},
            "roll_mirror_error_arcsec": {
                "value": list(err_roll_mirror / AS),
                "definition": "[azimuth beyond +-90 deg (cw +), elevation] of roll mirror line of sight in fixture frame"},
            "mount_roll_jitter_arcsec": {
                "sigma": mount_roll_jitter_arcsec, "value": list((roll_true - mount_roll_deg * D) / AS),
                "definition": "true INS roll at each pointing minus mount_roll_deg (row order REF_C, REF_R, A*, P*)"}},
        "reference_frame_used_C_r_n": Cr.tolist(),
        "mirrors": truth_rows}
    return header, rows, truth


def write_files(out_dir, name, header, rows, truth):
    """Write NAME.csv and NAME.truth.json into out_dir; returns both paths."""
    os.makedirs(out_dir, exist_ok=True)
    csv_path = os.path.join(out_dir, name + ".csv")
    json_path = os.path.join(out_dir, name + ".truth.json")
    with open(csv_path, "w", newline="", encoding="utf-8") as f:
        w = csv.writer(f)
        w.writerow(header)
        for r in rows:
            w.writerow(r[:2] + [f"{x:.8f}" for x in r[2:]])
    with open(json_path, "w", encoding="utf-8") as f:
        json.dump(truth, f, indent=1, ensure_ascii=False)
    return csv_path, json_path


def generate(out_dir, name, **kwargs):
    """simulate(**kwargs) and write NAME.csv / NAME.truth.json into out_dir."""
    return write_files(out_dir, name, *simulate(**kwargs))


if __name__ == "__main__":
    here = os.path.join(os.path.dirname(os.path.abspath(__file__)), "examples")
    generate(here, "cal_ref_roll", include_reference_rows=True, include_roll=True)
    generate(here, "cal_ref_noroll", include_reference_rows=True, include_roll=False)
    generate(here, "cal_rel_roll", include_reference_rows=False, include_roll=True)
    generate(here, "cal_rel_noroll", include_reference_rows=False, include_roll=False)
    generate(here, "cal_ref_roll_exact", include_reference_rows=True, include_roll=True,
             theodolite_sigma_arcsec=0, ins_heading_sigma_arcsec=0, ins_pitch_sigma_arcsec=0,
             ins_roll_sigma_arcsec=0, mount_roll_jitter_arcsec=0)
    generate(here, "cal_rel_tilted_left", include_reference_rows=False, include_roll=True,
             fixture_pitch_deg=0.05, fixture_roll_deg=-0.1, roll_mirror_side="left", seed=11)
    print("examples written to", here)
