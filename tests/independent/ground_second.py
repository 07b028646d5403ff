"""Second, independent simulator of ground static-base boresight-calibration data.

Given: only BRIEF.md (task + CSV/JSON format) and seed000.txt (Ding Tao 2014, "Aiming line
calibration technique of strapdown photoelectric equipment", section 1, eqs. (1)-(18), set-up 1.4).
No other code or document was read.

Forward model (paper, exact when every hidden effect is off and the noise is zero):
  target r^b (base frame b: x right, y forward, z up, origin at the projection centre)
  -> r^a = C_b^a r^b                                eqs. (5), (6)
  -> equivalent angles psi_m = arctan(-x_a / y_a),  theta_m = arcsin(z_a / |r|)   eq. (10)
  -> px = -f_x tan(psi_m),  pz = f_z tan(theta_m) / cos(psi_m)                 eq. (4)
     with f_x = (NX/2)/tan(FOV_x/2), f_z = (NZ/2)/tan(FOV_z/2) [px]  (eq. (4): f_x/(2 tan(fov/2)))
  (algebraically px = f_x x_a/y_a, pz = f_z z_a/y_a: an upright pinhole, image plane at y = L, eq. (1)).

Assumptions (choice, and the passage it rests on):
 A1 C_b^a = R_y(gamma) R_x(theta) R_z(psi), passive frame rotations, angles in (-90, 90) deg:
    "先绕 z 轴旋转方位, 然后绕 x 轴旋转俯仰, 最后绕 y 轴旋转横滚" and the explicit matrix eq. (5)
    (= scipy Rotation.from_euler('ZXY', [psi, theta, gamma]).as_matrix().T). Positive psi turns the
    optical axis to the left (towards -x), positive theta raises it, positive gamma is a right-hand
    roll about the optical axis.
 A2 f_x is the pixel count along the image x axis (spanning fov_yaw), f_z along z (fov_pitch).
    The prose of 1.1 swaps the two names ("方位视场总像素数 f_z"), but eq. (1) x_N = 2L f_mx/f_x
    tan(fov_yaw/2) only makes sense with f_x horizontal; the brief's f_x formula agrees.
 A3 px, pz are measured from the image centre, px positive towards +x_a (right), pz positive
    towards +z_a (up), no image inversion: eq. (1) places N at (x_N, L, z_N) with the same signs.
 A4 "Normalised image coordinates" for the distortion are (x_a/y_a, z_a/y_a) = (px/f_x, pz/f_z).
 A5 The survey is modelled as: the layout gives the TRUE positions; the CSV holds true + N(0, s^2)
    on each coordinate (brief: isotropic sigma) plus an optional common height-datum error
    (the paper's "高度基准误差 delta_h", section 1.3/1.4).
 A6 Targets are observed one at a time in sweep order (station by station; at each station the
    low target, then the raised one, as the paper raises A to get B), equally spaced in time.
 A7 The default layout centres its bearings on the nominal azimuth psi (the paper: the ideal
    mounting is known, "均已知其理想安装姿态") and keeps the paper's forward-axis points A, B
    (bearing 0) when they are visible; targets outside fov_fill of the half-field are dropped.
 A8 Eq. (18) is not used by the simulator. As printed it gives half the rotation angle
    (arccos(q0)); the tests find that Table 1 is reproduced (to 1 %) as the worst case over the
    error signs of section 1.3 with Delta = arccos((1 + tr D)/4), i.e. eq. (18) without its root.
 A9 Targets on a flat range sit near sensor height, so the default image coverage is a band
    (elevations of a few degrees); pass targets_b for any other layout.

Scenario numbers. From the text: FOV 90 x 90 deg, 512 x 512 px, psi/theta/gamma = 30/20/10 deg,
ranges 50 and 100 m, target height difference H in 1..3 m (default 2 m), pixel error 0.5 px,
survey placement errors <= 0.1 m (default sigma 0.03 m, i.e. 0.1 m as ~3 sigma: mine).
Mine: 9 bearings spread over 0.8 of the horizontal field, heights (0, H), session 5400 s,
t0 = 0 s, fov_fill 0.85, effect magnitudes (all default 0 = off).

Hidden effects (each off by default, value and one-line definition written to the truth JSON):
  focal_drift_per_hour  f(t) = f0 (1 + d (t - t0)/3600), both axes          [1/h]
  radial_k2             r' = r (1 + k2 r^4), r in normalised coordinates     [-]
  centroid_bias_px      centroid moved toward the image centre by b * R_ref / range  [px]
  principal_point_px    the optical axis pierces the detector at (cx, cz) from the image centre [px]
  height_datum_m        common error added to every surveyed z (wrong sensor-height reference) [m]
"""
import csv
import json
import os

import numpy as np

CSV_HEADER = ["target", "x_m", "y_m", "z_m", "px", "pz", "t_s"]


def dcm_b_to_a(psi, theta, gamma):
    """C_b^a of eq. (5) (angles in radians)."""
    cp, sp, ct, st, cg, sg = (np.cos(psi), np.sin(psi), np.cos(theta), np.sin(theta),
                              np.cos(gamma), np.sin(gamma))
    return np.array([
        [cg * cp - sg * st * sp, cg * sp + sg * st * cp, -sg * ct],
        [-ct * sp, ct * cp, st],
        [sg * cp + cg * st * sp, sg * sp - cg * st * cp, cg * ct]])


def focal_lengths_px(fov_deg, pixels):
    """Ideal pinhole focal lengths (f_x, f_z) [px] from full FOV [deg] and pixel counts."""
    fov = np.radians(np.asarray(fov_deg, float))
    n = np.asarray(pixels, float)
    return tuple((n / 2.0) / np.tan(fov / 2.0))


def equivalent_angles(r_a):
    """Eq. (10): equivalent measurement angles (psi_m, theta_m) [rad] of points r_a (N x 3)."""
    r_a = np.atleast_2d(r_a)
    psi_m = np.arctan(-r_a[:, 0] / r_a[:, 1])
    theta_m = np.arcsin(r_a[:, 2] / np.linalg.norm(r_a, axis=1))
    return psi_m, theta_m


def pixels_from_angles(psi_m, theta_m, fov_deg, pixels):
    """Eq. (4): image coordinates (px, pz) [px] from equivalent angles [rad]."""
    fx, fz = focal_lengths_px(fov_deg, pixels)
    return -fx * np.tan(psi_m), fz * np.tan(theta_m) / np.cos(psi_m)


def paper_forward(points_b, psi_deg, theta_deg, gamma_deg, fov_deg, pixels):
    """The paper's forward model: base-frame points [m] -> ideal (px, pz) [px] and r^a [m]."""
    C = dcm_b_to_a(*np.radians([psi_deg, theta_deg, gamma_deg]))
    r_a = np.atleast_2d(np.asarray(points_b, float)) @ C.T          # eq. (6)
    if np.any(r_a[:, 1] <= 0):
        raise ValueError("a target is behind the sensor (y_a <= 0)")
    px, pz = pixels_from_angles(*equivalent_angles(r_a), fov_deg, pixels)
    return px, pz, r_a


def default_layout(psi_deg, theta_deg, gamma_deg, fov_deg, pixels, ranges_m=(50.0, 100.0),
                   heights_m=(0.0, 2.0), n_bearings=9, fov_fill=0.85):
    """Stations at horizontal range R and bearing beta (positive to the left, like psi):
    x = -R sin(beta), y = R cos(beta), z = h. Returns (names, points N x 3 [m])."""
    half = 0.8 * fov_deg[0] / 2.0
    bearings = list(psi_deg + np.linspace(-half, half, n_bearings))
    if 0.0 not in bearings:
        bearings.append(0.0)                                     # the paper's points A, B
    names, pts = [], []
    for beta in sorted(bearings):
        b = np.radians(beta)
        for rng in ranges_m:
            station = [(f"T{len(pts) + k:03d}_brg{beta:+.1f}_rng{rng:g}_h{h:g}",
                        [-rng * np.sin(b), rng * np.cos(b), h]) for k, h in enumerate(heights_m)]
            p = np.array([s[1] for s in station])
            C = dcm_b_to_a(*np.radians([psi_deg, theta_deg, gamma_deg]))
            if np.any(p @ C.T[:, 1] <= 0):
                continue
            px, pz, _ = paper_forward(p, psi_deg, theta_deg, gamma_deg, fov_deg, pixels)
            if (np.all(np.abs(px) <= fov_fill * pixels[0] / 2)
                    and np.all(np.abs(pz) <= fov_fill * pixels[1] / 2)):
                names += [s[0] for s in station]
                pts += [s[1] for s in station]
    return names, np.array(pts, float)


def apply_image_effects(px0, pz0, t_s, ranges, fov_deg, pixels, t0_s=0.0, focal_drift_per_hour=0.0,
                        radial_k2=0.0, centroid_bias_px=0.0, centroid_bias_ref_range_m=50.0,
                        principal_point_px=(0.0, 0.0)):
    """Hidden image effects applied to ideal coordinates (px0, pz0) [px]; exact identity when off."""
    fx, fz = focal_lengths_px(fov_deg, pixels)
    xn, zn = px0 / fx, pz0 / fz                                  # normalised coordinates (A4)
    if radial_k2:
        s = 1.0 + radial_k2 * (xn ** 2 + zn ** 2) ** 2           # r' = r (1 + k2 r^4)
        xn, zn = xn * s, zn * s
    scale = 1.0 + focal_drift_per_hour * (np.asarray(t_s, float) - t0_s) / 3600.0
    px, pz = fx * scale * xn, fz * scale * zn
    if focal_drift_per_hour == 0 and radial_k2 == 0:
        px, pz = np.array(px0, float), np.array(pz0, float)      # bit-exact paper model
    px = px + principal_point_px[0]
    pz = pz + principal_point_px[1]
    if centroid_bias_px:
        rad = np.hypot(px, pz)
        shift = centroid_bias_px * centroid_bias_ref_range_m / np.asarray(ranges, float)
        shift = np.minimum(shift, rad)                           # never overshoot the centre
        with np.errstate(invalid="ignore", divide="ignore"):
            ux = np.where(rad > 0, px / rad, 0.0)
            uz = np.where(rad > 0, pz / rad, 0.0)
        px, pz = px - shift * ux, pz - shift * uz
    return px, pz


def simulate_ground(out_dir, name="ground", *, psi_deg=30.0, theta_deg=20.0, gamma_deg=10.0,
                    fov_deg=(90.0, 90.0), pixels=(512, 512), pixel_sigma_px=0.5,
                    survey_sigma_m=0.03, seed=0, targets_b=None, target_names=None,
                    ranges_m=(50.0, 100.0), heights_m=(0.0, 2.0), n_bearings=9, fov_fill=0.85,
                    session_s=5400.0, t0_s=0.0, focal_drift_per_hour=0.0, radial_k2=0.0,
                    centroid_bias_px=0.0, centroid_bias_ref_range_m=50.0,
                    principal_point_px=(0.0, 0.0), height_datum_m=0.0):
    """Simulate one ground static-base calibration data set; write NAME.csv and NAME.truth.json.

    Angles [deg]; fov_deg (horizontal, vertical) [deg]; pixels (NX, NZ); pixel_sigma_px [px] per
    image coordinate; survey_sigma_m [m] per surveyed coordinate; targets_b (N x 3) TRUE target
    positions in frame b [m] (None: default_layout from ranges_m [m], heights_m [m], n_bearings,
    fov_fill); session_s, t0_s [s]; hidden effects as in the module header.
    Returns a dict with the paths and the arrays written.
    """
    fov_deg = tuple(float(v) for v in fov_deg)
    pixels = tuple(int(v) for v in pixels)
    if targets_b is None:
        names, true_b = default_layout(psi_deg, theta_deg, gamma_deg, fov_deg, pixels,
                                       ranges_m, heights_m, n_bearings, fov_fill)
    else:
        true_b = np.atleast_2d(np.asarray(targets_b, float))
        names = (list(target_names) if target_names is not None
                 else [f"T{k:03d}" for k in range(len(true_b))])
    n = len(true_b)
    if n == 0:
        raise ValueError("no target inside the field of view")
    if len(set(names)) != n:
        raise ValueError("target names must be unique")
    t_s = t0_s + (np.linspace(0.0, session_s, n) if n > 1 else np.zeros(1))

    rng = np.random.default_rng(seed)
    e_pix = rng.standard_normal((n, 2)) * pixel_sigma_px        # always drawn: fixed stream
    e_sur = rng.standard_normal((n, 3)) * survey_sigma_m

    px0, pz0, r_a = paper_forward(true_b, psi_deg, theta_deg, gamma_deg, fov_deg, pixels)
    ranges = np.linalg.norm(true_b, axis=1)
    px, pz = apply_image_effects(px0, pz0, t_s, ranges, fov_deg, pixels, t0_s,
                                 focal_drift_per_hour, radial_k2, centroid_bias_px,
                                 centroid_bias_ref_range_m, principal_point_px)
    px, pz = px + e_pix[:, 0], pz + e_pix[:, 1]
    if np.any(np.abs(px) > pixels[0] / 2) or np.any(np.abs(pz) > pixels[1] / 2):
        raise ValueError("a target image falls outside the detector")
    surveyed = true_b + e_sur
    surveyed[:, 2] += height_datum_m

    os.makedirs(out_dir, exist_ok=True)
    csv_path = os.path.join(out_dir, f"{name}.csv")
    with open(csv_path, "w", newline="", encoding="utf-8") as fh:
        w = csv.writer(fh)
        w.writerow(CSV_HEADER)
        for k in range(n):
            w.writerow([names[k]] + [repr(float(v)) for v in
                                     (*surveyed[k], px[k], pz[k], t_s[k])])

    fx, fz = focal_lengths_px(fov_deg, pixels)
    effects = {
        "focal_drift_per_hour": {
            "value": float(focal_drift_per_hour), "units": "1/h",
            "definition": "f_x(t), f_z(t) = f (1 + value * (t_s - t0_s)/3600): linear thermal drift"},
        "radial_k2": {
            "value": float(radial_k2), "units": "-",
            "definition": "r' = r (1 + k2 r^4), r = |(px/f_x, pz/f_z)| ideal, no r^2 term"},
        "centroid_bias_px": {
            "value": float(centroid_bias_px), "units": "px",
            "ref_range_m": float(centroid_bias_ref_range_m),
            "definition": "image centroid moved toward the image centre by value * ref_range_m / |r|"},
        "principal_point_px": {
            "value": [float(v) for v in principal_point_px], "units": "px",
            "definition": "optical axis meets the detector at (px, pz) = value, not at the centre"},
        "height_datum_m": {
            "value": float(height_datum_m), "units": "m",
            "definition": "common error added to every surveyed z (sensor-height reference error)"},
    }
    for e in effects.values():
        e["enabled"] = bool(np.any(np.asarray(e["value"]) != 0))
    truth = {
        "name": name, "fov_deg": list(fov_deg), "pixels": list(pixels),
        "focal_px": [float(fx), float(fz)],
        "pixel_sigma_px": float(pixel_sigma_px), "survey_sigma_m": float(survey_sigma_m),
        "psi_deg": float(psi_deg), "theta_deg": float(theta_deg), "gamma_deg": float(gamma_deg),
        "euler_convention": "C_b^a = R_y(gamma) R_x(theta) R_z(psi), eq. (5); "
                            "scipy from_euler('ZXY', [psi, theta, gamma]).as_matrix().T",
        "seed": int(seed), "t0_s": float(t0_s), "session_s": float(session_s),
        "n_observations": n, "hidden_effects": effects,
        "true_targets_b_m": {names[k]: [float(v) for v in true_b[k]] for k in range(n)},
    }
    json_path = os.path.join(out_dir, f"{name}.truth.json")
    with open(json_path, "w", encoding="utf-8") as fh:
        json.dump(truth, fh, indent=2)
    return {"csv": csv_path, "truth": json_path, "names": names, "true_b": true_b,
            "surveyed_b": surveyed, "px": px, "pz": pz, "px_ideal": px0, "pz_ideal": pz0,
            "t_s": t_s, "r_a": r_a}


if __name__ == "__main__":
    here = os.path.join(os.path.dirname(os.path.abspath(__file__)), "examples")
    simulate_ground(here, "ground_clean", seed=0)
    simulate_ground(here, "ground_effects", seed=1, focal_drift_per_hour=2e-3, radial_k2=-0.02)
