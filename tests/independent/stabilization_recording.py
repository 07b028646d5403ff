"""Blind simulator of a gyro-indirect-stabilised two-axis gimbal (patent CN102288133B).

Provenance: written from the patent text CN102288133B and the data format FORMAT.md only,
without reading any other implementation.  Every frame, sign and formula below was derived
from the patent's physics; numpy and scipy only.

Run:   python stabilization_blind.py OUT.csv --seed N [options]   (writes OUT.csv, OUT.truth.json)

Conventions (and the text they come from)
-----------------------------------------
* Carrier frame b: x right, y forward, z up (FORMAT.md: "x right, y forward, z up").  The
  inertial frame n is the local ENU ground frame, treated as non-rotating (Earth rate neglected,
  as in the patent's model; a real gyro's Earth-rate share would sit in the bias).
* Rotation matrices are PASSIVE direction-cosine matrices (coordinate transforms) of a frame
  turned by +a, right-handed: the patent prints R_z(d)=[[1,d,0],[-d,1,0],[0,0,1]],
  R_x(d)=[[1,0,0],[0,1,d],[0,-d,1]], R_y(d)=[[1,0,-d],[0,1,0],[d,0,1]] ("分别为绕x、y、z轴的
  欧拉角旋转矩阵" = "the Euler-angle rotation matrices about x, y, z"); these are the small-angle
  forms of rot_z/rot_x/rot_y below.  The simulator uses the exact trigonometric matrices.
  rot_a(angle) == scipy Rotation.from_euler(a, angle).as_matrix().T.
* IMU installation angles delta_g = (dgx, dgy, dgz), eq. (1) "ω_bm = R_y(δgy) R_x(δgx) R_z(δgz) ω_b":
  the IMU frame is the carrier frame turned first by dgz about z, then dgx about the new x, then
  dgy about the new y;  C_gb = rot_y(dgy) rot_x(dgx) rot_z(dgz) (exact, not linearised).
* Gimbal: outer azimuth eta about the carrier z, inner pitch eps about the azimuth frame's x,
  line of sight (LOS) = the pitch frame's +y.  From eq. (2) "ω_i = R_x(ε+δpx)(R_z(η+δpz) ω_b + η̇) + ε̇"
  and FORMAT.md (eta > 0 turns the LOS left, eps > 0 up): C_pb = rot_x(eps) rot_z(eta); a +eta
  turns +y towards -x (left), a +eps turns +y towards +z (up).
* Camera installation angles delta_p = (dpx, dpy, dpz) exactly as eq. (2) places them: dpz adds
  to eta (azimuth zero / base yaw offset), dpx adds to eps (pitch offset); dpy, absent from the
  patent's model, is taken as the camera's roll about its own optical axis (image rotation):
  C_cb = rot_y(dpy) rot_x(eps + dpx) rot_z(eta + dpz).
* Carrier attitude: yaw psi (about z, + = nose left), pitch theta (about x, + = nose up), roll
  phi (about y); the same z-x-y order as eq. (1): C_bn = rot_y(phi) rot_x(theta) rot_z(psi)
  (= scipy Rotation.from_euler('ZXY', [psi, theta, phi]).as_matrix().T).  Each angle is
  a*sin(2*pi*f*t + p) (+ optional constant rate * t, used by the tests).
* Indirect stabilisation, eq. (4): eps_dot = -cos(eta) w_x - sin(eta) w_y,
  eta_dot = sec(eps) (-sin(eps) sin(eta) w_x + sin(eps) cos(eta) w_y - cos(eps) w_z), fed with the
  MEASURED rate w = gyro (IMU axes, installation angles unknown to the loop) and the encoder
  angles.  I re-derived eq. (4): it zeroes the x and z components of the pitch frame's inertial
  rate, so with a perfect IMU the LOS is exactly inertially fixed.  The gimbal follows the
  commanded rates ideally; (eta, eps) are integrated with classical RK4 at `substeps` sub-steps
  per sample; the deterministic part of the gyro signal is continuous in time, its white noise
  is held constant over each sample interval (zero-order hold of the sample n_k over [t_k, t_k+1)).
* Gyro: gyro(t_k) = C_gb w_b(t_k) + bias + n_k (point sampling), n_k ~ N(0, s^2) per axis with
  s = density * sqrt(rate)  [density in rad/s/sqrt(Hz), rate in Hz]; with the zero-order hold this
  gives the correct angle random walk density^2 * dt per step.
* Camera: ideal pinhole looking along its +y, square pixels, k = pixels / (2 tan(fov/2)) [px/rad];
  for the target direction v in camera axes: los_x = k v_x / v_y (right), los_z = k v_z / v_y (up),
  i.e. the image as seen by a viewer (no pinhole inversion).  The target is fixed and infinitely
  far: by default the camera LOS direction in n at t = 0 (image centre); a start position
  (x0, z0) [px] puts it at C_cn(0)^T normalise([x0/k, 1, z0/k]).  Note: with a perfect IMU the
  2-axis gimbal keeps the LOS fixed but lets the camera roll about it, so an off-centre target
  circles around the centre; only a centred target stays exactly put.  Image noise: white,
  N(0, image_noise^2) per axis [px].  Encoders report eta, eps exactly, unwrapped [rad].

Departures from the printed formulas (physics trusted over print)
------------------------------------------------------------------
1. Eq. (3) prints ε̇ = [0 0 ε̇]^T; the pitch rate is about the x axis, so ε̇ = [ε̇ 0 0]^T (only this
   reproduces eq. (4) and the printed H_1,x row).
2. Eq. (6) prints H_2,2 = "sinεcosηε ω_bz + cosε ω_by"; the stray ε is a misprint:
   H_2,2 = sin ε cos η ω_bz + cos ε ω_by.  X prints "δ_z", defined as δ_pz - δ_gz.
3. Eq. (6) H_2,1 (coefficient of δpx in Δω_z) is printed as cosε sinη ω_bx - cosε cosη ω_by - sinε ω_bz.
   Linearising eq. (2) with η̇ from eq. (4) inside R_x(ε+δpx) gives
   Δω_z|δpx = -δpx * ω_p,y  with the pitch frame's roll rate ω_p,y = sec ε (-sin η ω_bx + cos η ω_by),
   i.e. H_2,1 = sec ε (sin η ω_bx - cos η ω_by).  The printed form equals -[cos ε(-sin η ω_bx + cos η ω_by)
   + sin ε ω_bz]: it uses a roll rate without the azimuth rate's share sin ε * η̇ (printed = mine +
   sin ε * η̇, and η̇ ≈ -ω_bz is not small).  The other printed H entries agree with my derivation.
   This simulator integrates the exact kinematics, so it follows the physics, not the printed
   H_2,1 (see test_first_order_model).  With my H_2,1, least squares on the simulated image drift
   recovers X to <0.02' (test_linear_model_recovers_truth); with the printed one, dpx comes out
   ~50 % off at eps = 40 deg.
4. Not a misprint but a model limit: the patent's Δω_x, Δω_z are camera rates; an off-centre image
   point also moves by the camera's roll about the LOS (x' = w_z - w_y z, z' = -w_x + w_y x in rad).
   The simulator's pinhole projection contains this exactly; the patent's eq. (6) does not.
"""
# FORMAT.md, the data format its author was given with the patent text, is kept beside this file
# as stabilization_format.md.
import argparse
import json
import math

import numpy as np

HEADER = "t_s,gyro_x,gyro_y,gyro_z,eta_rad,eps_rad,los_x_px,los_z_px"
COLUMNS = HEADER.split(",")
ARCMIN = math.pi / (180.0 * 60.0)          # rad per arc-minute
DEG_PER_H = math.pi / 180.0 / 3600.0       # rad/s per deg/h
DEG_PER_SQRT_H = math.pi / 180.0 / 60.0    # rad/s/sqrt(Hz) per deg/sqrt(h)


def rot_x(a):
    """Passive DCM of a frame turned by a [rad] about x; a scalar or array -> (..., 3, 3)."""
    a = np.asarray(a, float)
    c, s, o, z = np.cos(a), np.sin(a), np.ones_like(a), np.zeros_like(a)
    return np.stack([np.stack([o, z, z], -1), np.stack([z, c, s], -1), np.stack([z, -s, c], -1)], -2)


def rot_y(a):
    """Passive DCM about y [rad] (patent: [[1,0,-d],[0,1,0],[d,0,1]])."""
    a = np.asarray(a, float)
    c, s, o, z = np.cos(a), np.sin(a), np.ones_like(a), np.zeros_like(a)
    return np.stack([np.stack([c, z, -s], -1), np.stack([z, o, z], -1), np.stack([s, z, c], -1)], -2)


def rot_z(a):
    """Passive DCM about z [rad] (patent: [[1,d,0],[-d,1,0],[0,0,1]])."""
    a = np.asarray(a, float)
    c, s, o, z = np.cos(a), np.sin(a), np.ones_like(a), np.zeros_like(a)
    return np.stack([np.stack([c, s, z], -1), np.stack([-s, c, z], -1), np.stack([z, z, o], -1)], -2)


def imu_dcm(delta_g):
    """C_gb (carrier -> IMU axes) from delta_g = (dgx, dgy, dgz) [rad], eq. (1) exact."""
    dgx, dgy, dgz = delta_g
    return rot_y(dgy) @ rot_x(dgx) @ rot_z(dgz)


def camera_dcm(eta, eps, delta_p):
    """C_cb (carrier -> camera axes) for gimbal angles eta, eps [rad] and delta_p=(dpx,dpy,dpz)."""
    dpx, dpy, dpz = delta_p
    return rot_y(dpy) @ rot_x(np.asarray(eps) + dpx) @ rot_z(np.asarray(eta) + dpz)


def carrier_euler(t, amp, freq, phase, drift=(0.0, 0.0, 0.0)):
    """Yaw, pitch, roll [rad] and their time derivatives [rad/s] at times t [s].

    amp [rad], freq [Hz], phase [rad], drift [rad/s] are (yaw, pitch, roll) triples.
    Returns (ang, dang), each of shape t.shape + (3,)."""
    t = np.asarray(t, float)[..., None]
    w = 2.0 * np.pi * np.asarray(freq, float)
    arg = w * t + np.asarray(phase, float)
    ang = np.asarray(amp, float) * np.sin(arg) + np.asarray(drift, float) * t
    dang = np.asarray(amp, float) * w * np.cos(arg) + np.asarray(drift, float)
    return ang, dang


def carrier_dcm(t, amp, freq, phase, drift=(0.0, 0.0, 0.0)):
    """C_bn(t) = rot_y(roll) rot_x(pitch) rot_z(yaw): inertial (ENU) -> carrier axes."""
    ang, _ = carrier_euler(t, amp, freq, phase, drift)
    return rot_y(ang[..., 2]) @ rot_x(ang[..., 1]) @ rot_z(ang[..., 0])


def carrier_rate(t, amp, freq, phase, drift=(0.0, 0.0, 0.0)):
    """Carrier inertial angular rate in carrier axes, w_b [rad/s], shape t.shape + (3,).

    w_b = R_y(phi) R_x(theta) [0,0,psi_dot] + R_y(phi) [theta_dot,0,0] + [0,phi_dot,0]."""
    ang, dang = carrier_euler(t, amp, freq, phase, drift)
    th, ph = ang[..., 1], ang[..., 2]
    dps, dth, dph = dang[..., 0], dang[..., 1], dang[..., 2]
    return np.stack([np.cos(ph) * dth - np.sin(ph) * np.cos(th) * dps,
                     np.sin(th) * dps + dph,
                     np.sin(ph) * dth + np.cos(ph) * np.cos(th) * dps], -1)


def gimbal_rates(eta, eps, w):
    """Patent eq. (4): (eta_dot, eps_dot) [rad/s] from encoder angles [rad] and a rate w [rad/s]."""
    se, ce, sh, ch = math.sin(eps), math.cos(eps), math.sin(eta), math.cos(eta)
    eps_dot = -ch * w[0] - sh * w[1]
    eta_dot = (-se * sh * w[0] + se * ch * w[1] - ce * w[2]) / ce
    return eta_dot, eps_dot


def simulate(duration=60.0, rate=100.0,
             delta_g=(30 * ARCMIN, -18 * ARCMIN, 48 * ARCMIN),
             delta_p=(-24 * ARCMIN, 12 * ARCMIN, 36 * ARCMIN),
             gyro_bias=(1 * DEG_PER_H, -1 * DEG_PER_H, 1 * DEG_PER_H),
             gyro_noise_density=0.01 * DEG_PER_SQRT_H,
             image_noise=0.1, fov=math.radians(5.0), pixels=1024,
             rock_amp=(math.radians(5.0),) * 3, rock_freq=(0.25, 0.4, 0.32),
             rock_phase=(0.0, math.radians(30.0), math.radians(60.0)), rock_drift=(0.0, 0.0, 0.0),
             eta0=math.radians(20.0), eps0=math.radians(10.0), start_px=None, substeps=10, rng=None):
    """Simulate one recording.

    Units: duration [s], rate [Hz], angles [rad], gyro_bias [rad/s] per IMU axis,
    gyro_noise_density [rad/s/sqrt(Hz)] (per-sample sigma = density*sqrt(rate)), image_noise [px],
    fov [rad] across `pixels` [px], rocking (yaw, pitch, roll) amplitudes [rad], frequencies [Hz],
    phases [rad], drift [rad/s]; eta0, eps0 [rad]; start_px (x0, z0) [px] or None (centre).
    Returns (columns: dict name -> array, truth: dict)."""
    rng = np.random.default_rng() if rng is None else rng
    n = int(round(duration * rate)) + 1
    dt = 1.0 / rate
    t = np.arange(n) * dt
    kin = (rock_amp, rock_freq, rock_phase, rock_drift)
    c_gb = imu_dcm(delta_g)
    bias = np.asarray(gyro_bias, float)
    sigma_g = gyro_noise_density * math.sqrt(rate)
    noise_g = rng.normal(0.0, 1.0, (n, 3)) * sigma_g
    gyro = carrier_rate(t, *kin) @ c_gb.T + bias + noise_g

    # gimbal loop: RK4 on a fine grid of half sub-steps; deterministic rate continuous, noise ZOH
    h = dt / substeps
    tf = (np.arange((n - 1) * 2 * substeps + 1) * (h / 2.0))
    wf = carrier_rate(tf, *kin) @ c_gb.T + bias
    eta = np.empty(n)
    eps = np.empty(n)
    y0, y1 = float(eta0), float(eps0)
    eta[0], eps[0] = y0, y1
    for k in range(n - 1):
        nk = noise_g[k]
        for j in range(substeps):
            m = (k * substeps + j) * 2
            wa, wb, wc = wf[m] + nk, wf[m + 1] + nk, wf[m + 2] + nk
            k1 = gimbal_rates(y0, y1, wa)
            k2 = gimbal_rates(y0 + 0.5 * h * k1[0], y1 + 0.5 * h * k1[1], wb)
            k3 = gimbal_rates(y0 + 0.5 * h * k2[0], y1 + 0.5 * h * k2[1], wb)
            k4 = gimbal_rates(y0 + h * k3[0], y1 + h * k3[1], wc)
            y0 += h / 6.0 * (k1[0] + 2 * k2[0] + 2 * k3[0] + k4[0])
            y1 += h / 6.0 * (k1[1] + 2 * k2[1] + 2 * k3[1] + k4[1])
        eta[k + 1], eps[k + 1] = y0, y1

    # camera: fixed distant target, pinhole projection
    kpx = pixels / (2.0 * math.tan(fov / 2.0))
    c_cn = camera_dcm(eta, eps, delta_p) @ carrier_dcm(t, *kin)
    v0 = np.array([0.0, 1.0, 0.0]) if start_px is None else \
        np.array([start_px[0] / kpx, 1.0, start_px[1] / kpx])
    u_n = c_cn[0].T @ (v0 / np.linalg.norm(v0))
    v = c_cn @ u_n
    los = kpx * v[:, [0, 2]] / v[:, [1]] + rng.normal(0.0, image_noise, (n, 2))

    columns = dict(zip(COLUMNS, [t, gyro[:, 0], gyro[:, 1], gyro[:, 2], eta, eps, los[:, 0], los[:, 1]]))
    dgx, dgy, dgz = (float(a) for a in delta_g)
    dpx, dpy, dpz = (float(a) for a in delta_p)
    truth = {
        "provenance": "written from the patent text CN102288133B and the data format FORMAT.md "
                      "only, without reading any other implementation",
        "delta_g_rad": {"x": dgx, "y": dgy, "z": dgz},
        "delta_p_rad": {"x": dpx, "y": dpy, "z": dpz},
        "patent_X_rad": {"delta_px": dpx, "delta_gx": dgx, "delta_gy": dgy, "delta_z=dpz-dgz": dpz - dgz},
        "gyro_bias_rad_s": bias.tolist(),
        "gyro_noise_density_rad_s_sqrtHz": gyro_noise_density,
        "gyro_noise_sigma_per_sample_rad_s": sigma_g,
        "image_noise_px": image_noise,
        "camera": {"fov_rad": fov, "pixels": pixels, "k_px_per_rad": kpx,
                   "target_dir_enu": u_n.tolist(), "start_px": None if start_px is None else list(start_px)},
        "rocking": {"order": "yaw, pitch, roll", "amp_rad": list(map(float, rock_amp)),
                    "freq_hz": list(map(float, rock_freq)), "phase_rad": list(map(float, rock_phase)),
                    "drift_rad_s": list(map(float, rock_drift))},
        "eta0_rad": float(eta0), "eps0_rad": float(eps0),
        "duration_s": duration, "rate_hz": rate, "n_samples": n, "substeps": substeps,
        "conventions": {
            "frames": "carrier/IMU/camera x right, y forward (LOS), z up; inertial = ENU, non-rotating",
            "dcm": "passive (frame-turn) matrices, rot_a(x) = scipy from_euler(a, x).as_matrix().T",
            "imu": "C_gb = rot_y(dgy) rot_x(dgx) rot_z(dgz)  (eq. 1, exact)",
            "camera": "C_cb = rot_y(dpy) rot_x(eps+dpx) rot_z(eta+dpz)  (eq. 2; dpy = roll about LOS)",
            "carrier": "C_bn = rot_y(roll) rot_x(pitch) rot_z(yaw), angle = amp sin(2 pi f t + phase)",
            "gimbal": "eq. (4) fed with measured gyro, RK4, gyro noise zero-order-held per sample",
            "gyro_noise": "per-sample sigma = density * sqrt(rate)",
            "image": "los_x = k vx/vy, los_z = k vz/vy, k = pixels/(2 tan(fov/2))",
        },
    }
    return columns, truth


def write_csv(path, columns):
    """Write the columns (dict name -> array) to `path` with the exact FORMAT.md header."""
    data = np.column_stack([np.asarray(columns[c], float) for c in COLUMNS])
    np.savetxt(path, data, delimiter=",", header=HEADER, comments="", fmt="%.15g")


def main(argv=None):
    """Command line: angles in arc-minutes, rocking in degrees, bias in deg/h, ARW in deg/sqrt(h)."""
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("out")
    p.add_argument("--seed", type=int, required=True)
    p.add_argument("--duration", type=float, default=60.0, help="[s]")
    p.add_argument("--rate", type=float, default=100.0, help="[Hz]")
    p.add_argument("--imu-arcmin", type=float, nargs=3, default=[30.0, -18.0, 48.0], metavar=("GX", "GY", "GZ"))
    p.add_argument("--cam-arcmin", type=float, nargs=3, default=[-24.0, 12.0, 36.0], metavar=("PX", "PY", "PZ"))
    p.add_argument("--gyro-bias-dph", type=float, nargs=3, default=[1.0, -1.0, 1.0], help="[deg/h] per IMU axis")
    p.add_argument("--gyro-arw-dpsh", type=float, default=0.01, help="noise density [deg/sqrt(h)]")
    p.add_argument("--image-noise-px", type=float, default=0.1)
    p.add_argument("--fov-deg", type=float, default=5.0)
    p.add_argument("--pixels", type=int, default=1024)
    p.add_argument("--rock-amp-deg", type=float, nargs=3, default=[5.0, 5.0, 5.0], help="yaw pitch roll")
    p.add_argument("--rock-freq-hz", type=float, nargs=3, default=[0.25, 0.4, 0.32])
    p.add_argument("--rock-phase-deg", type=float, nargs=3, default=[0.0, 30.0, 60.0])
    p.add_argument("--eta0-deg", type=float, default=20.0)
    p.add_argument("--eps0-deg", type=float, default=10.0)
    p.add_argument("--start-px", type=float, nargs=2, default=None, metavar=("X0", "Z0"))
    p.add_argument("--substeps", type=int, default=10)
    a = p.parse_args(argv)
    columns, truth = simulate(
        duration=a.duration, rate=a.rate,
        delta_g=[x * ARCMIN for x in a.imu_arcmin], delta_p=[x * ARCMIN for x in a.cam_arcmin],
        gyro_bias=[x * DEG_PER_H for x in a.gyro_bias_dph], gyro_noise_density=a.gyro_arw_dpsh * DEG_PER_SQRT_H,
        image_noise=a.image_noise_px, fov=math.radians(a.fov_deg), pixels=a.pixels,
        rock_amp=np.radians(a.rock_amp_deg), rock_freq=a.rock_freq_hz, rock_phase=np.radians(a.rock_phase_deg),
        eta0=math.radians(a.eta0_deg), eps0=math.radians(a.eps0_deg), start_px=a.start_px,
        substeps=a.substeps, rng=np.random.default_rng(a.seed))
    truth["seed"] = a.seed
    write_csv(a.out, columns)
    base = a.out[:-4] if a.out.endswith(".csv") else a.out
    with open(base + ".truth.json", "w") as f:
        json.dump(truth, f, indent=2)


if __name__ == "__main__":
    main()
