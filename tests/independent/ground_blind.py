"""Blind, independent simulator of ground static-base calibration data for a strapdown
wide-field electro-optical sensor.

Provenance
----------
Written from two documents only:

* the seed text ``000_4eae2b9bbe75c428.txt`` (Ding Tao, "捷联光电设备瞄准线校准技术",
  2014, doi:10.7690/bgzdh.2014.01.018), section 1, eqs. (1)-(18) and the simulation set-up of
  section 1.4;
* ``FORMAT_GROUND.md`` (the CSV / truth-JSON layout; kept here as ``ground_format.md``).

Nothing else (no other code, documentation or data) was consulted. Every convention below is
derived from the paper's own equations; where the paper leaves something open, the choice is
listed as an assumption C1, C2, ... with the passage it rests on.

Physics
-------
Frames (paper section 1):

* ``b`` (产品基座系, product base frame): the aircraft body frame translated to the product
  centre; x right, y forward, z up ("右前上方向分别为其 x、y、z 轴": "right, forward, up are
  its x, y, z axes").
* ``a`` (实际产品系, actual product frame): origin at the product centre, optical axis = y,
  x and z parallel to the focal plane ("光轴为 y 轴, x、z 轴平行于图像焦平面").

Mounting angles ψ, θ, γ (实际安装角) are the Euler angles from b to a, rotation order z
(azimuth ψ), then x (pitch θ), then y (roll γ) ("先绕 z 轴旋转方位, 然后绕 x 轴旋转俯仰,
最后绕 y 轴旋转横滚"). The direction cosine matrix is the paper's eq. (5),

    C_b^a = R_y(γ) R_x(θ) R_z(ψ),     r^a = C_b^a r^b,

with the frame-rotation (passive) elementary matrices

    R_z(ψ) = [[cψ, sψ, 0], [-sψ, cψ, 0], [0, 0, 1]]
    R_x(θ) = [[1, 0, 0], [0, cθ, sθ], [0, -sθ, cθ]]
    R_y(γ) = [[cγ, 0, -sγ], [0, 1, 0], [sγ, 0, cγ]]

(multiplying these out reproduces every entry of eq. (5); eq. (7) is the same product without
R_y). In scipy terms: ``C_b^a = Rotation.from_euler("ZXY", [ψ, θ, γ]).as_matrix().T`` — the
intrinsic z-x'-y'' active rotation that carries the b axes onto the a axes, transposed to map
b-coordinates into a-coordinates. The test file checks this identity entry by entry against
eq. (5).

Projection (eqs. (1), (2), (4)): the focal plane is perpendicular to the a-frame y axis at
distance L from the focal point O; a target at r^a = (x_a, y_a, z_a) images at
N = (L x_a / y_a, L, L z_a / y_a). Eq. (1) converts the focal-plane coordinates to pixel
coordinates counted from the image centre,

    x_N = 2 L (f_mx / f_x) tan(fov_yaw / 2),   z_N = 2 L (f_mz / f_z) tan(fov_pitch / 2),

so, with F_x = (NX / 2) / tan(fov_h / 2) and F_z = (NZ / 2) / tan(fov_v / 2) [px],

    px = F_x x_a / y_a,        pz = F_z z_a / y_a.                         (P)

This is identical to the paper's eq. (4) combined with eq. (10): the equivalent angles
ψ_m = arctan(-x_a / y_a), θ_m = arcsin(z_a / |r|) give f_mx = -f_x tan ψ_m / (2 tan(fov_yaw/2))
= F_x x_a / y_a and f_mz = f_z tan θ_m / (2 cos ψ_m tan(fov_pitch/2)) = F_z z_a / y_a.
Consequences of the signs: a positive ψ turns the optical axis to the left (towards -x of b,
eq. (2): the ray is [-sin ψ_m cos θ_m, cos ψ_m cos θ_m, sin θ_m]), so a target straight ahead
appears at px = +F_x tan ψ; a positive θ raises the optical axis, so the target appears at
pz = -F_z tan θ.

A target is visible when y_a > 0 (in front of the focal point) and its noise-free measured
image lies on the detector, |px| <= NX / 2 and |pz| <= NZ / 2. Other targets are dropped and
counted (``n_dropped_behind``, ``n_dropped_outside`` in the truth).

Environment: flat earth, straight rays (no Earth curvature, no atmospheric refraction), a
static sensor (static base), one observation per target.

Noise
-----
* centroid error: independent N(0, pixel_sigma_px²) added to px and to pz;
* survey error: independent N(0, survey_sigma_m²) added to each of x_m, y_m, z_m; the file
  holds surveyed = true + error, while the image is formed from the TRUE position.

Hidden effects (``effects`` dict; all default to absent)
--------------------------------------------------------
Let (u, w) = (x_a / y_a, z_a / y_a) be the ideal normalised image coordinates of the true
target (image distance from the true image centre divided by the true focal length).

* ``radial_k1`` (float k1): radial lens distortion on normalised coordinates,
  (u_d, w_d) = (u, w) (1 + k1 r²), r² = u² + w²; applied to both px and pz.
* ``focal_scale`` (float s > -1): the true focal lengths are F_x (1 + s), F_z (1 + s), while the
  fov_deg / pixels written in the truth (and used by any solver) describe the nominal camera.
* ``principal_point_px`` ((dx, dz)): the image centre is shifted; every measured coordinate is
  offset, px += dx, pz += dz.
* ``lever_arm_m`` ((ax, ay, az)): the projection centre sits at (ax, ay, az) in frame b while
  the survey still refers to the frame-b origin: r^a = C_b^a (r^b - a).

Full measured image (before centroid noise):

    px = F_x (1 + s) u (1 + k1 r²) + dx,     pz = F_z (1 + s) w (1 + k1 r²) + dz.

Assumptions / conventions
-------------------------
C1  Rotation matrix. "本节所述的安装姿态角是一组连续旋转的欧拉角, 其旋转次序均规定为先绕 z
    轴旋转方位, 然后绕 x 轴旋转俯仰, 最后绕 y 轴旋转横滚" ("the mounting angles are Euler
    angles of successive rotations, first about z (azimuth), then about x (pitch), last about y
    (roll)") together with the explicit matrix of eq. (5), which fixes the signs: C_b^a as
    written in eq. (5) maps b-coordinates to a-coordinates (eq. (6): "r_A^a = C_b^a r_A^b").
C2  Image coordinates and their signs: eq. (1) "x_N = 2L f_mx/f_x tan(fov_yaw/2) ... y_N = L
    ... z_N = 2L f_mz/f_z tan(fov_pitch/2)" and "已知其对应的像素坐标为 (f_mx, f_mz)" ("its
    pixel coordinates are (f_mx, f_mz)"): pixel coordinates are counted from the image centre
    ("中心位于 y 轴": "the centre lies on the y axis"), positive along +x_a and +z_a of the
    focal plane placed IN FRONT of O (a non-inverted image). Eq. (4) confirms the signs.
C3  Pixel counts. The paper labels f_z "方位视场总像素数" (total pixels of the azimuth field)
    and f_x "俯仰视场总像素数" (pitch field), but eq. (1) pairs f_x with fov_yaw along x. The
    equations are followed: the horizontal count NX and the horizontal FOV go with px (x_a),
    the vertical ones with pz (z_a), as FORMAT_GROUND.md also states.
C4  Eq. (1) says "N 点在坐标系 b 中的空间坐标" ("coordinates of N in frame b"); from the
    context (Fig. 1: "坐标系 Oxyz 为实际产品系 a") this is read as frame a.
C5  Frame b and the survey origin: "将飞机体系 b_f 原点平移至产品中心, 坐标轴方向不变"
    ("translate the origin of b_f to the product centre, axes unchanged"); the product centre
    is taken to be the projection centre (focal point O), except under ``lever_arm_m``.
C6  Visibility: "通常视场角都小于 π" and ψ_m, θ_m ∈ (-π/2, π/2): only targets with y_a > 0
    are imaged; a target is on the detector when |px| <= NX/2 and |pz| <= NZ/2 (the focal
    plane is "一矩形, 中心位于 y 轴": a rectangle centred on the y axis).
C7  Noise model: the paper adds "图像误差" / "像素误差" (image error, pixel error, df in
    Table 1) to the pixel coordinates and places targets with position errors δ_x, δ_y, δ_h;
    here both are modelled as independent zero-mean normal errors of the stated standard
    deviations (the paper gives bounds "≤", not distributions).
C8  The default mounting angles of the CLI, the 90°×90° field and 512×512 pixels are those of
    section 1.4 ("视场为 90°×90°, 像元为 512×512; 实际安装角 ψ = 30°, θ = 20°, γ = 10°").
C9  Flat earth, straight rays: the paper's geometry (section 1.2, targets on the apron at
    ranges L of 50-100 m) contains neither curvature nor refraction.
C10 Default layout: a grid over most of the field at several ranges (distance from the
    projection centre) between 30 m and 150 m; it is purely geometric and does not enforce
    that targets stand above the apron surface (the paper's own two-point layout puts targets
    at heights 0 and H above the sensor, section 1.2).
"""

from __future__ import annotations

import argparse
import csv
import json
import math
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

KNOWN_EFFECTS = {
    "radial_k1": (
        "radial lens distortion on normalised image coordinates: (u_d, w_d) = (u, w)(1 + k1 r^2),"
        " r^2 = u^2 + w^2, u = x_a/y_a, w = z_a/y_a; applied to px and pz"
    ),
    "principal_point_px": (
        "shift (dx, dz) [px] of the image centre: measured px += dx, pz += dz"
    ),
    "focal_scale": (
        "true focal length = nominal x (1 + s) on both axes; fov_deg/pixels describe the"
        " nominal camera"
    ),
    "lever_arm_m": (
        "projection centre at (ax, ay, az) [m] in frame b; the survey refers to the b origin:"
        " r_a = C_b^a (r_b - a)"
    ),
}

CSV_HEADER = ["target", "x_m", "y_m", "z_m", "px", "pz", "t_s"]


def dcm_b_to_a(psi_deg: float, theta_deg: float, gamma_deg: float) -> np.ndarray:
    """C_b^a of the paper's eq. (5): r^a = C_b^a r^b (order z-psi, x-theta, y-gamma)."""
    rot = Rotation.from_euler("ZXY", [psi_deg, theta_deg, gamma_deg], degrees=True)
    return rot.as_matrix().T


def focal_lengths_px(fov_deg=(90.0, 90.0), pixels=(512, 512)) -> tuple[float, float]:
    """Nominal focal lengths (F_x, F_z) [px] from eq. (1): F = (N / 2) / tan(FOV / 2)."""
    fx = (pixels[0] / 2.0) / math.tan(math.radians(fov_deg[0]) / 2.0)
    fz = (pixels[1] / 2.0) / math.tan(math.radians(fov_deg[1]) / 2.0)
    return fx, fz


def _check_effects(effects) -> dict:
    """Validate and normalise the effects dict; unknown names raise ValueError."""
    out: dict = {}
    if not effects:
        return out
    for name, value in effects.items():
        if name not in KNOWN_EFFECTS:
            raise ValueError(f"unknown effect {name!r}; known: {sorted(KNOWN_EFFECTS)}")
        if name in ("radial_k1", "focal_scale"):
            v = float(value)
            if not math.isfinite(v):
                raise ValueError(f"effect {name!r} must be finite")
            if name == "focal_scale" and v <= -1.0:
                raise ValueError("effect 'focal_scale' must be > -1")
            out[name] = v
        else:
            n = 2 if name == "principal_point_px" else 3
            arr = np.asarray(value, dtype=float).reshape(-1)
            if arr.size != n or not np.all(np.isfinite(arr)):
                raise ValueError(f"effect {name!r} needs {n} finite numbers")
            out[name] = [float(a) for a in arr]
    return out


def project(targets_b, *, psi_deg, theta_deg, gamma_deg, fov_deg=(90.0, 90.0),
            pixels=(512, 512), effects=None):
    """Noise-free measured image coordinates of TRUE target positions (frame b).

    Returns (px, pz, y_a): arrays of length n; px, pz are NaN where y_a <= 0.
    """
    eff = _check_effects(effects)
    r_b = np.atleast_2d(np.asarray(targets_b, dtype=float))
    if r_b.ndim != 2 or r_b.shape[1] != 3:
        raise ValueError("targets must be an (n, 3) array")
    lever = np.asarray(eff.get("lever_arm_m", [0.0, 0.0, 0.0]))
    c = dcm_b_to_a(psi_deg, theta_deg, gamma_deg)
    r_a = (r_b - lever) @ c.T
    ya = r_a[:, 1]
    front = ya > 0
    with np.errstate(divide="ignore", invalid="ignore"):
        u = np.where(front, r_a[:, 0] / ya, np.nan)
        w = np.where(front, r_a[:, 2] / ya, np.nan)
    k1 = eff.get("radial_k1", 0.0)
    scale = 1.0 + k1 * (u * u + w * w)
    fx, fz = focal_lengths_px(fov_deg, pixels)
    s = eff.get("focal_scale", 0.0)
    dx, dz = eff.get("principal_point_px", [0.0, 0.0])
    px = fx * (1.0 + s) * u * scale + dx
    pz = fz * (1.0 + s) * w * scale + dz
    return px, pz, ya


def default_layout(psi_deg=30.0, theta_deg=20.0, gamma_deg=10.0, *, fov_deg=(90.0, 90.0),
                   pixels=(512, 512), ranges_m=(35.0, 80.0, 140.0), n_side=5,
                   fill=0.85) -> np.ndarray:
    """TRUE target positions in frame b: an n_side x n_side grid of image directions spanning
    ``fill`` of the half-field on each axis (nominal camera), at each range [m] (distance from
    the projection centre). Successive ranges are offset by a fraction of a grid step so that
    targets at different ranges do not share a line of sight.
    """
    fx, fz = focal_lengths_px(fov_deg, pixels)
    c = dcm_b_to_a(psi_deg, theta_deg, gamma_deg)
    grid = np.linspace(-1.0, 1.0, int(n_side))
    step = grid[1] - grid[0] if n_side > 1 else 0.0
    pts = []
    for k, rng in enumerate(ranges_m):
        off = (k / max(len(ranges_m), 1) - 0.5) * 0.5 * step
        for gz in grid:
            for gx in grid:
                ix = float(np.clip(gx + off, -1.0, 1.0))
                iz = float(np.clip(gz - off, -1.0, 1.0))
                px = ix * fill * pixels[0] / 2.0
                pz = iz * fill * pixels[1] / 2.0
                d_a = np.array([px / fx, 1.0, pz / fz])
                d_a *= rng / np.linalg.norm(d_a)
                pts.append(c.T @ d_a)
    return np.array(pts)


def simulate(path_stem, *, psi_deg, theta_deg, gamma_deg, fov_deg=(90.0, 90.0),
             pixels=(512, 512), targets_m=None, pixel_sigma_px=0.3, survey_sigma_m=0.01,
             seed=0, effects=None) -> dict:
    """Write ``path_stem.csv`` and ``path_stem.truth.json``; return the truth dict."""
    eff = _check_effects(effects)
    if pixel_sigma_px < 0 or survey_sigma_m < 0:
        raise ValueError("noise standard deviations must be >= 0")
    if targets_m is None:
        targets_m = default_layout(psi_deg, theta_deg, gamma_deg, fov_deg=fov_deg,
                                   pixels=pixels)
    r_b = np.atleast_2d(np.asarray(targets_m, dtype=float))
    px0, pz0, ya = project(r_b, psi_deg=psi_deg, theta_deg=theta_deg, gamma_deg=gamma_deg,
                           fov_deg=fov_deg, pixels=pixels, effects=eff)
    behind = ~(ya > 0)
    with np.errstate(invalid="ignore"):
        inside = (np.abs(px0) <= pixels[0] / 2.0) & (np.abs(pz0) <= pixels[1] / 2.0)
    outside = ~behind & ~inside
    keep = np.flatnonzero(~behind & inside)

    rng = np.random.default_rng(seed)
    n = keep.size
    pix_err = rng.normal(0.0, 1.0, size=(n, 2)) * pixel_sigma_px
    sur_err = rng.normal(0.0, 1.0, size=(n, 3)) * survey_sigma_m
    px = px0[keep] + pix_err[:, 0]
    pz = pz0[keep] + pix_err[:, 1]
    surveyed = r_b[keep] + sur_err
    names = [f"T{i:03d}" for i in keep]

    stem = Path(path_stem)
    stem.parent.mkdir(parents=True, exist_ok=True)
    csv_path = stem.with_name(stem.name + ".csv")
    with open(csv_path, "w", newline="", encoding="utf-8") as fh:
        wr = csv.writer(fh)
        wr.writerow(CSV_HEADER)
        for j in range(n):
            wr.writerow([names[j], repr(float(surveyed[j, 0])), repr(float(surveyed[j, 1])),
                         repr(float(surveyed[j, 2])), repr(float(px[j])), repr(float(pz[j])),
                         repr(float(j))])

    fx, fz = focal_lengths_px(fov_deg, pixels)
    truth = {
        "fov_deg": [float(fov_deg[0]), float(fov_deg[1])],
        "pixels": [int(pixels[0]), int(pixels[1])],
        "pixel_sigma_px": float(pixel_sigma_px),
        "survey_sigma_m": float(survey_sigma_m),
        "psi_deg": float(psi_deg),
        "theta_deg": float(theta_deg),
        "gamma_deg": float(gamma_deg),
        "seed": int(seed),
        "effects": {k: {"value": v, "definition": KNOWN_EFFECTS[k]} for k, v in eff.items()},
        "conventions": (
            "C_b^a = R_y(gamma) R_x(theta) R_z(psi) (paper eq. 5), r_a = C_b^a (r_b - lever);"
            " px = F_x x_a/y_a, pz = F_z z_a/y_a from the image centre (eqs. 1, 4);"
            " F = (N/2)/tan(FOV/2); flat earth, straight rays"
        ),
        "nominal_focal_px": [fx, fz],
        "C_b_a": dcm_b_to_a(psi_deg, theta_deg, gamma_deg).tolist(),
        "n_targets_given": int(r_b.shape[0]),
        "n_written": int(n),
        "n_dropped_behind": int(behind.sum()),
        "n_dropped_outside": int(outside.sum()),
        "targets": [
            {"target": names[j], "true_m": [float(a) for a in r_b[keep[j]]],
             "px_true": float(px0[keep[j]]), "pz_true": float(pz0[keep[j]])}
            for j in range(n)
        ],
        "csv": csv_path.name,
    }
    json_path = stem.with_name(stem.name + ".truth.json")
    with open(json_path, "w", encoding="utf-8") as fh:
        json.dump(truth, fh, indent=1, ensure_ascii=False)
    return truth


def _parse_effect(text: str) -> tuple[str, object]:
    if "=" not in text:
        raise ValueError(f"--effect needs NAME=VALUE, got {text!r}")
    name, value = text.split("=", 1)
    name = name.strip()
    if name not in KNOWN_EFFECTS:
        raise ValueError(f"unknown effect {name!r}; known: {sorted(KNOWN_EFFECTS)}")
    nums = [float(v) for v in value.split(",")]
    return name, (nums[0] if len(nums) == 1 else nums)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description="Blind simulator of ground calibration data sets.")
    ap.add_argument("outdir")
    ap.add_argument("--n", type=int, default=1, help="number of data sets")
    ap.add_argument("--seed", type=int, default=0, help="seed of the first data set")
    ap.add_argument("--psi", type=float, default=30.0)
    ap.add_argument("--theta", type=float, default=20.0)
    ap.add_argument("--gamma", type=float, default=10.0)
    ap.add_argument("--jitter-deg", type=float, default=0.0,
                    help="add a uniform random offset in [-J, J] deg to each angle per set")
    ap.add_argument("--pixel-sigma", type=float, default=0.3)
    ap.add_argument("--survey-sigma", type=float, default=0.01)
    ap.add_argument("--effect", action="append", default=[],
                    help="NAME=VALUE, vector values comma separated (e.g. lever_arm_m=0.1,0,0)")
    args = ap.parse_args(argv)
    effects = dict(_parse_effect(e) for e in args.effect)
    out = Path(args.outdir)
    for i in range(args.n):
        seed = args.seed + i
        ang = np.array([args.psi, args.theta, args.gamma])
        if args.jitter_deg > 0:
            ang = ang + np.random.default_rng([seed, 1]).uniform(
                -args.jitter_deg, args.jitter_deg, 3)
        simulate(out / f"ground_{i:03d}", psi_deg=float(ang[0]), theta_deg=float(ang[1]),
                 gamma_deg=float(ang[2]), pixel_sigma_px=args.pixel_sigma,
                 survey_sigma_m=args.survey_sigma, seed=seed, effects=effects)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
