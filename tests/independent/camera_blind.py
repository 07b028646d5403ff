"""Blind generator of planar-target camera-calibration data (model.csv, views.csv, truth.json).

Provenance: written from FORMAT.md and the published Zhang/Brown-Conrady models only, without
reading any other implementation (Zhang 1998/2000 planar calibration; the Brown-Conrady
distortion model with the coefficient naming used by OpenCV).

Conventions (all also written into truth.json):
* Target: an nx x ny grid of corners (default 16 x 16, pitch 10 mm) in the plane Z = 0.
  Point id = row * nx + col (0-based), X = col * pitch, Y = row * pitch, unit on every row.
* Pose: X_cam = R @ X_target + t (target -> camera). Camera frame: x right, y down, z forward
  (along the optical axis). R is stored as a 3x3 matrix and as a rotation vector (axis * angle
  [rad], Rodrigues, as in OpenCV's rvec); t in the target's unit.
* Projection: x = X_cam/Z_cam, y = Y_cam/Z_cam (normalised coordinates); the distortion acts on
  these normalised coordinates:
      r2 = x^2 + y^2,  radial = 1 + k1 r2 + k2 r2^2 + k3 r2^3
      xd = x radial + 2 p1 x y + p2 (r2 + 2 x^2)
      yd = y radial + p1 (r2 + 2 y^2) + 2 p2 x y
  then u = fx xd + skew yd + cx,  v = fy yd + cy,  i.e. [u v 1]^T = K [xd yd 1]^T with
  K = [[fx, skew, cx], [0, fy, cy], [0, 0, 1]].  (OpenCV distCoeffs order: k1, k2, p1, p2, k3.)
* Pixels: u right, v down, origin at the top-left of the image (FORMAT.md). Pixel CENTRES are at
  INTEGER coordinates (OpenCV convention): the top-left pixel's centre is (0, 0), the image
  covers [-0.5, width-0.5] x [-0.5, height-0.5]; default cx, cy = (width-1)/2, (height-1)/2.
* Visibility (decided on the noiseless projection): Z_cam > 0, inside the image rectangle above,
  and normalised radius below the first turning point of r (1 + k1 r^2 + k2 r^4 + k3 r^6) (so a
  strongly distorted point that folds back into the image is not kept).
* Noise: i.i.d. Gaussian, sigma = noise_px [px] on u and on v separately, added after visibility.
* Blunders: `blunders` visible observations chosen at random get an extra displacement of exactly
  `blunder_px` [px] in a uniformly random direction (after noise); recorded in truth.json by
  view and id with (du, dv). Views are numbered 0..n_views-1.
* Poses: the target's centre sits at distance d chosen so that the target spans a random
  50-80 % of the image height, shifted sideways at random while staying mostly in the image,
  tilted by 10-45 deg (angle between target normal and optical axis) about a random axis in the
  image plane, with an in-plane rotation of +-45 deg. A pose is redrawn if < 50 % of points show.
"""
import argparse
import json
import os

import numpy as np
from scipy.spatial.transform import Rotation

PIXEL_ORIGIN = ("top-left; u right, v down; pixel centres at integer coordinates (centre of the "
                "top-left pixel is (0,0), image spans [-0.5,width-0.5]x[-0.5,height-0.5])")
CAMERA_MODEL = "pinhole with skew: [u,v,1]^T = K [xd,yd,1]^T, K=[[fx,skew,cx],[0,fy,cy],[0,0,1]]"
DIST_MODEL = ("Brown-Conrady (OpenCV): on normalised x=X/Z,y=Y/Z; r2=x^2+y^2; "
              "xd=x(1+k1 r2+k2 r2^2+k3 r2^3)+2p1xy+p2(r2+2x^2); "
              "yd=y(1+k1 r2+k2 r2^2+k3 r2^3)+p1(r2+2y^2)+2p2xy")
POSE_CONV = "X_cam = R X_target + t; camera x right, y down, z forward; rvec = Rodrigues axis*angle [rad]"


def distort(x, y, k1=0.0, k2=0.0, k3=0.0, p1=0.0, p2=0.0):
    """Brown-Conrady distortion of normalised coordinates (x, y) -> (xd, yd)."""
    x, y = np.asarray(x, float), np.asarray(y, float)
    r2 = x * x + y * y
    radial = 1.0 + k1 * r2 + k2 * r2 ** 2 + k3 * r2 ** 3
    xd = x * radial + 2.0 * p1 * x * y + p2 * (r2 + 2.0 * x * x)
    yd = y * radial + p1 * (r2 + 2.0 * y * y) + 2.0 * p2 * x * y
    return xd, yd


def project(P_target, R, t, fx, fy, cx, cy, skew=0.0, k1=0.0, k2=0.0, k3=0.0, p1=0.0, p2=0.0):
    """Project target points (N,3) -> (u, v, x, y, Z): pixels, normalised coords, depth."""
    Pc = np.asarray(P_target, float) @ np.asarray(R, float).T + np.asarray(t, float)
    Z = Pc[:, 2]
    with np.errstate(divide="ignore", invalid="ignore"):
        x, y = Pc[:, 0] / Z, Pc[:, 1] / Z
    xd, yd = distort(x, y, k1, k2, k3, p1, p2)
    return fx * xd + skew * yd + cx, fy * yd + cy, x, y, Z


def radial_limit(k1, k2, k3, rmax=10.0):
    """First normalised radius where r*(1+k1 r^2+k2 r^4+k3 r^6) stops increasing (inf if none)."""
    r = np.linspace(0.0, rmax, 20001)
    dg = 1.0 + 3 * k1 * r ** 2 + 5 * k2 * r ** 4 + 7 * k3 * r ** 6
    bad = np.nonzero(dg <= 0.0)[0]
    return float(r[bad[0]]) if bad.size else np.inf


def target_points(nx=16, ny=16, pitch=10.0):
    ids = np.arange(nx * ny)
    return ids, np.column_stack([(ids % nx) * pitch, (ids // nx) * pitch, np.zeros(ids.size)])


def _random_pose(rng, size, centre, fx, fy, cx, cy, width, height, tilt_deg, inplane_deg, fill):
    frac = rng.uniform(*fill)
    d = max(fx, fy) * size / (frac * height)           # distance giving the wanted apparent size
    span = frac * height                               # approx. apparent size in px
    du = rng.uniform(-1, 1) * 0.4 * max(width - span, 0.0)
    dv = rng.uniform(-1, 1) * 0.4 * max(height - span, 0.0)
    C = np.array([du * d / fx, dv * d / fy, d])        # target centre in the camera frame
    tilt = np.deg2rad(rng.uniform(*tilt_deg))
    phi = rng.uniform(0.0, 2 * np.pi)
    R_tilt = Rotation.from_rotvec(tilt * np.array([np.cos(phi), np.sin(phi), 0.0]))
    R_in = Rotation.from_rotvec([0.0, 0.0, np.deg2rad(rng.uniform(-inplane_deg, inplane_deg))])
    R = (R_tilt * R_in).as_matrix()
    return R, C - R @ centre, np.rad2deg(tilt)


def generate(*, fx=600.0, fy=600.0, cx=None, cy=None, skew=0.0, width=640, height=480,
             k1=0.0, k2=0.0, k3=0.0, p1=0.0, p2=0.0, n_views=None, noise_px=0.1,
             blunders=0, blunder_px=20.0, rng=None, nx=16, ny=16, pitch=10.0, unit="mm",
             tilt_deg=(10.0, 45.0), inplane_deg=45.0, fill=(0.5, 0.8), min_visible=0.5):
    """Return (model_rows, view_rows, truth).

    model_rows: list of (id, X, Y, unit); view_rows: list of (view, id, u, v); truth: dict.
    rng: numpy Generator, an int seed, or None. n_views None -> random 5..8.
    """
    if unit not in ("mm", "m", "in"):
        raise ValueError("unit must be mm, m or in")
    seed = rng if isinstance(rng, (int, np.integer)) else None
    rng = rng if isinstance(rng, np.random.Generator) else np.random.default_rng(rng)
    cx = (width - 1) / 2.0 if cx is None else float(cx)
    cy = (height - 1) / 2.0 if cy is None else float(cy)
    n_views = int(rng.integers(5, 9)) if n_views is None else int(n_views)
    dist = dict(k1=float(k1), k2=float(k2), k3=float(k3), p1=float(p1), p2=float(p2))
    intr = dict(fx=float(fx), fy=float(fy), cx=cx, cy=cy, skew=float(skew))
    ids, P = target_points(nx, ny, pitch)
    centre = np.array([(nx - 1) * pitch / 2.0, (ny - 1) * pitch / 2.0, 0.0])
    size = max(nx - 1, ny - 1) * pitch
    r_lim = radial_limit(k1, k2, k3)
    model_rows = [(int(i), float(X), float(Y), unit) for i, (X, Y, _) in zip(ids, P)]
    views, obs = [], []                                # obs: (view, id, u_true, v_true)
    for vw in range(n_views):
        for _ in range(1000):
            R, t, tilt = _random_pose(rng, size, centre, fx, fy, cx, cy, width, height,
                                      tilt_deg, inplane_deg, fill)
            u, v, x, y, Z = project(P, R, t, **intr, **dist)
            with np.errstate(invalid="ignore"):
                ok = ((Z > 0) & (np.hypot(x, y) < r_lim) & (u >= -0.5) & (u <= width - 0.5)
                      & (v >= -0.5) & (v <= height - 0.5))
            if ok.sum() >= max(4, min_visible * ids.size):
                break
        else:
            raise RuntimeError("could not find a pose with enough visible points")
        views.append(dict(view=vw, rvec=Rotation.from_matrix(R).as_rotvec().tolist(),
                          R=R.tolist(), t=t.tolist(), tilt_deg=float(tilt),
                          n_points=int(ok.sum())))
        obs += [(vw, int(i), uu, vv) for i, uu, vv in zip(ids[ok], u[ok], v[ok])]
    n = len(obs)
    uv = np.array([[o[2], o[3]] for o in obs]) + noise_px * rng.standard_normal((n, 2))
    blunder_list = []
    if blunders:
        if blunders > n:
            raise ValueError("more blunders than observations")
        for k in rng.choice(n, size=int(blunders), replace=False):
            ang = rng.uniform(0.0, 2 * np.pi)
            d_uv = blunder_px * np.array([np.cos(ang), np.sin(ang)])
            uv[k] += d_uv
            blunder_list.append(dict(view=obs[k][0], id=obs[k][1], du=float(d_uv[0]),
                                     dv=float(d_uv[1]), size_px=float(blunder_px)))
    view_rows = [(o[0], o[1], float(a), float(b)) for o, (a, b) in zip(obs, uv)]
    K = [[intr["fx"], intr["skew"], cx], [0.0, intr["fy"], cy], [0.0, 0.0, 1.0]]
    truth = dict(
        generator="camera_blind.py (blind second author; from FORMAT.md and published "
                  "Zhang/Brown-Conrady models only)",
        camera_model=CAMERA_MODEL, intrinsics=intr, K=K,
        image_size=dict(width=int(width), height=int(height)),
        distortion_model=DIST_MODEL, distortion=dist,
        opencv_dist_coeffs=[dist["k1"], dist["k2"], dist["p1"], dist["p2"], dist["k3"]],
        pixel_origin=PIXEL_ORIGIN, pose_convention=POSE_CONV,
        target=dict(type="grid of corners", nx=int(nx), ny=int(ny), pitch=float(pitch),
                    unit=unit, id_rule="id = row*nx + col; X = col*pitch, Y = row*pitch, Z = 0"),
        noise_px=float(noise_px),
        noise_model="i.i.d. Gaussian, sigma=noise_px on u and on v, after visibility test",
        blunders=blunder_list, blunder_px=float(blunder_px), n_views=n_views,
        n_observations=n, views=views, seed=seed)
    return model_rows, view_rows, truth


def _paths(dir_or_prefix):
    if os.path.isdir(dir_or_prefix) or dir_or_prefix.endswith(os.sep):
        os.makedirs(dir_or_prefix, exist_ok=True)
        return [os.path.join(dir_or_prefix, f) for f in ("model.csv", "views.csv", "truth.json")]
    return [dir_or_prefix + f for f in ("model.csv", "views.csv", "truth.json")]


def write(dir_or_prefix, model_rows=None, view_rows=None, truth=None, **generate_kwargs):
    """Write model.csv, views.csv, truth.json into a directory (or with a file-name prefix).

    Pass the three results of generate(), or none of them and generate() keyword arguments.
    """
    if model_rows is None:
        model_rows, view_rows, truth = generate(**generate_kwargs)
    pm, pv, pt = _paths(dir_or_prefix)
    with open(pm, "w", newline="") as f:
        f.write("id,X,Y,unit\n")
        f.writelines(f"{i},{X!r},{Y!r},{u}\n" for i, X, Y, u in model_rows)
    with open(pv, "w", newline="") as f:
        f.write("view,id,u,v\n")
        f.writelines(f"{w},{i},{u!r},{v!r}\n" for w, i, u, v in view_rows)
    with open(pt, "w") as f:
        json.dump(truth, f, indent=1)
    return pm, pv, pt


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("outdir")
    ap.add_argument("--seed", type=int, default=0)
    for name, default in [("fx", 600.0), ("fy", 600.0), ("cx", None), ("cy", None),
                          ("skew", 0.0), ("k1", 0.0), ("k2", 0.0), ("k3", 0.0), ("p1", 0.0),
                          ("p2", 0.0), ("noise-px", 0.1), ("blunder-px", 20.0), ("pitch", 10.0)]:
        ap.add_argument("--" + name, type=float, default=default)
    for name, default in [("width", 640), ("height", 480), ("views", None), ("blunders", 0),
                          ("nx", 16), ("ny", 16)]:
        ap.add_argument("--" + name, type=int, default=default)
    ap.add_argument("--unit", default="mm", choices=["mm", "m", "in"])
    a = ap.parse_args(argv)
    os.makedirs(a.outdir, exist_ok=True)
    paths = write(a.outdir, fx=a.fx, fy=a.fy, cx=a.cx, cy=a.cy, skew=a.skew, width=a.width,
                  height=a.height, k1=a.k1, k2=a.k2, k3=a.k3, p1=a.p1, p2=a.p2,
                  n_views=a.views, noise_px=a.noise_px, blunders=a.blunders,
                  blunder_px=a.blunder_px, rng=a.seed, nx=a.nx, ny=a.ny, pitch=a.pitch,
                  unit=a.unit)
    print("\n".join(paths))


if __name__ == "__main__":
    main()
