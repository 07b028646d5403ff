"""Second, independent simulator of a gyro-indirectly-stabilised gimbal calibration run.

What I was given: BRIEF.md (task + CSV format) and the patent text CN102288133B
(seed001.txt / seed001.plain.txt). Nothing else was read; no other implementation was used.

The run (patent, steps 1-2 of the claim): an IMU and a two-axis gimbal carrying a camera sit on one
carrier; the camera is aimed at a fixed distant target; the carrier rocks; the gimbal rates are
computed from the IMU's *measured* rate with eq. (4) ("间接稳定", "由陀螺测量得到 ... 由 w_bm 来替代");
installation angles turn into line-of-sight (LOS) drift that the camera sees.

Kinematics (derived from the text, not from the printed linearised A / H of eqs. (5)-(6)):
  frames       n: level frame = carrier frame at t=0;  b: carrier (x right, y forward, z up);
               g: IMU;  c: camera (x right, y = LOS, z up).
  rotations    Rx, Ry, Rz are *passive* (frame) matrices, R(a) = I - a[e x] for small a, exactly the
               patent's printed small-angle matrices of eq. (1); here used with finite angles.
  IMU          w_bm = Ry(dgy) Rx(dgx) Rz(dgz) w_b                                   (eq. 1, exact)
  camera       C_cb = Ry(dpy) Rx(eps + dpx) Rz(eta + dpz)  (eq. 2's structure, dpy added)
  gimbal law   eps_dot = -cos(eta) w1 - sin(eta) w2
               eta_dot = sec(eps)(-sin(eps) sin(eta) w1 + sin(eps) cos(eta) w2 - cos(eps) w3)
               with w = w_bm and (eta, eps) = encoder angles                        (eqs. 3-4)
  carrier      C_nb -> C_bn = Ry(phi) Rx(theta) Rz(psi); psi heading (z), theta pitch (x), phi roll
               (y); each  A sin(2 pi f t + p);  w_b = Ry(phi)Rx(theta)[0,0,psi'] + Ry(phi)[theta',0,0]
               + [0,phi',0]  (exact, analytic).
  image        target direction u_n = LOS at t=0; u_c = C_cn(t) u_n; pixel = f_px (u_x/u_y, u_z/u_y),
               f_px = (pixels/2)/tan(fov/2).  A target leaving the field of view gives NaN pixels.

Assumptions (with the passage each rests on):
  A1 Passive matrices, order z-x-y for the IMU: eq. (1) and its printed R_x, R_y, R_z.
  A2 eq. (3) prints eps_dot_vec = [0 0 eps_dot]^T; the pitch axis is the camera frame's x axis
     (eq. 2 applies R_x(eps)), so I use [eps_dot 0 0]^T.  With it, eq. (4) makes the LOS's x and z
     rates vanish exactly when w_bm = w_b and dp = 0 (checked in the tests) - this confirms A2 and
     the sign conventions of the brief (eta > 0 left, eps > 0 up).
  A3 dpz adds to eta and dpx adds to eps (eq. 2 "R_x(eps+dpx) ... R_z(eta+dpz)"): read as a yaw of
     the gimbal base about the carrier z axis / a tilt of the camera about the pitch axis (equally:
     encoder zero offsets). dpy (not in eq. 2; named in dp = [dpx dpy dpz]) = camera roll about its
     LOS, applied last; it only rotates the image.
  A4 The controller sees the carrier only through w_bm ("由陀螺测量得到") and uses the encoder angles.
     Default loop='continuous': an ideal servo follows eq. (4) continuously with the noise-free IMU
     rate; noise is read-out noise added to the recorded columns only (then zero angles give an
     exactly still image). loop='zoh': a sampled controller at the common sample rate uses the
     recorded (noisy) gyro and encoder values and holds the rates for one sample.
  A5 The target is infinitely far, on the true LOS at t=0 ("将摄像机视轴瞄准一个固定的目标",
     error "相对于初始瞄准点"); the image is the target's position, so an upward LOS drift moves it
     down (z_px < 0).
  A6 Finite installation angles are kept exact (no linearisation anywhere). My exact kinematics
     agree to first order with printed eq. (5) rows 1 and 3 except the dpx column of row 3:
     exact is -dpx (-sin(eta) w_bx + cos(eta) w_by)/cos(eps); the print has
     dpx (cos(eps) sin(eta) w_bx - cos(eps) cos(eta) w_by - sin(eps) w_bz).  The printed H_2,2
     "sin(eps)cos(eta) eps w_bz" has a stray eps.  I follow the kinematics.
  A7 White Gaussian noise, independent per sample and axis, from numpy default_rng(seed); the
     gyro value is a point sample at t_s (brief).

Numbers: NONE come from the patent (it gives no scenario values). All are mine and are arguments:
  duration 60 s, 100 Hz; heading/pitch/roll rocking 4/6/8 deg at 0.13/0.21/0.17 Hz (incommensurate,
  so all axes excite); gimbal start eta0 = 30 deg, eps0 = 15 deg (non-zero so that every term of
  eq. (5)/(6) is excited); camera fov 5 deg over 1024 px; noise gyro 2e-5 rad/s, encoders 5e-6 rad,
  image 0.3 px; example installation angles dg = (0.3, -0.4, 0.5) deg, dp = (0.6, 0.2, -0.35) deg.
"""
import json
import numpy as np
from scipy.integrate import solve_ivp

DEG = np.pi / 180.0
HEADER = "t_s,gyro_x,gyro_y,gyro_z,eta_rad,eps_rad,los_x_px,los_z_px"


# ---------------------------------------------------------------- rotations (passive, frame) --
def rot_x(a):
    c, s = np.cos(a), np.sin(a)
    return np.array([[1.0, 0.0, 0.0], [0.0, c, s], [0.0, -s, c]])


def rot_y(a):
    c, s = np.cos(a), np.sin(a)
    return np.array([[c, 0.0, -s], [0.0, 1.0, 0.0], [s, 0.0, c]])


def rot_z(a):
    c, s = np.cos(a), np.sin(a)
    return np.array([[c, s, 0.0], [-s, c, 0.0], [0.0, 0.0, 1.0]])


def imu_matrix(delta_g):
    """C_gb of eq. (1): w_bm = Ry(dgy) Rx(dgx) Rz(dgz) w_b."""
    dgx, dgy, dgz = delta_g
    return rot_y(dgy) @ rot_x(dgx) @ rot_z(dgz)


def camera_matrix(eta, eps, delta_p):
    """C_cb: carrier coordinates -> camera coordinates (A3)."""
    dpx, dpy, dpz = delta_p
    return rot_y(dpy) @ rot_x(eps + dpx) @ rot_z(eta + dpz)


# ------------------------------------------------------------------------------ carrier ------
def carrier_euler(t, amp, freq, phase):
    """(psi, theta, phi) and their rates at times t; each shape (3, N)."""
    t = np.atleast_1d(np.asarray(t, float))
    amp, freq, phase = (np.asarray(v, float)[:, None] for v in (amp, freq, phase))
    w = 2.0 * np.pi * freq
    arg = w * t[None, :] + phase
    return amp * np.sin(arg), amp * w * np.cos(arg)


def carrier_attitude(psi, theta, phi):
    """C_bn (level frame -> carrier frame)."""
    return rot_y(phi) @ rot_x(theta) @ rot_z(psi)


def carrier_rate(ang, rate):
    """Body rate w_b (carrier axes) from the Euler angles and rates, one column per time."""
    psi, theta, phi = ang
    dpsi, dtheta, dphi = rate
    cth, sth, cph, sph = np.cos(theta), np.sin(theta), np.cos(phi), np.sin(phi)
    # Rx(theta)[0,0,dpsi] = [0, sth dpsi, cth dpsi]; then Ry(phi) and the other two terms
    v = np.vstack([dtheta, sth * dpsi, cth * dpsi])
    wx = cph * v[0] - sph * v[2]
    wz = sph * v[0] + cph * v[2]
    return np.vstack([wx, v[1] + dphi, wz])


# ------------------------------------------------------------------------ gimbal law ---------
def gimbal_rates(eta, eps, w):
    """Eq. (4): (eta_dot, eps_dot) from encoder angles and the rate w used by the controller."""
    w1, w2, w3 = w
    se, ce, sn, cn = np.sin(eps), np.cos(eps), np.sin(eta), np.cos(eta)
    eps_dot = -cn * w1 - sn * w2
    eta_dot = (-se * sn * w1 + se * cn * w2 - ce * w3) / ce
    return eta_dot, eps_dot


def camera_rate(eta, eps, omega_b, delta_g, delta_p):
    """Exact camera angular rate (camera axes) when the gimbal follows eq. (4) driven by w_bm.

    eq. (2) with A2 (pitch rate about x) and the camera roll dpy (diagnostics and tests)."""
    eta_dot, eps_dot = gimbal_rates(eta, eps, imu_matrix(delta_g) @ omega_b)
    dpx, dpy, dpz = delta_p
    inner = rot_z(eta + dpz) @ omega_b + np.array([0.0, 0.0, eta_dot])
    return rot_y(dpy) @ (rot_x(eps + dpx) @ inner + np.array([eps_dot, 0.0, 0.0]))


def focal_px(fov_rad, pixels):
    return 0.5 * pixels / np.tan(0.5 * fov_rad)


# ---------------------------------------------------------------------------- simulate -------
def simulate(delta_g=(0.0, 0.0, 0.0), delta_p=(0.0, 0.0, 0.0), *,
             duration_s=60.0, rate_hz=100.0,
             rock_amp_rad=(4 * DEG, 6 * DEG, 8 * DEG), rock_freq_hz=(0.13, 0.21, 0.17),
             rock_phase_rad=(0.0, 0.0, 0.0),
             eta0_rad=30 * DEG, eps0_rad=15 * DEG,
             fov_rad=5 * DEG, pixels=1024,
             gyro_noise_rad_s=2e-5, encoder_noise_rad=5e-6, image_noise_px=0.3,
             seed=0, loop="continuous"):
    """Simulate one calibration run; returns a dict of arrays (the CSV columns) and a truth dict.

    delta_g = (dgx, dgy, dgz) [rad] IMU installation angles, eq. (1);
    delta_p = (dpx, dpy, dpz) [rad] camera installation angles (dpx pitch, dpy roll about LOS,
    dpz azimuth), eq. (2)/A3.  rock_* are (heading about z, pitch about x, roll about y) of the
    carrier; amplitudes [rad], frequencies [Hz], phases [rad].  eta0/eps0 [rad] gimbal start angles.
    fov_rad [rad] over `pixels` px (square pixels, same on both axes).  Noise: 1-sigma gyro
    [rad/s], encoders [rad], image [px]; seed for numpy default_rng.  loop: 'continuous' or 'zoh'.
    """
    if loop not in ("continuous", "zoh"):
        raise ValueError("loop must be 'continuous' or 'zoh'")
    n = int(round(duration_s * rate_hz)) + 1
    dt = 1.0 / rate_hz
    t = np.arange(n) * dt
    amp, freq, phase = (np.asarray(v, float) for v in (rock_amp_rad, rock_freq_hz, rock_phase_rad))
    G = imu_matrix(delta_g)
    rng = np.random.default_rng(seed)
    gyro_noise = rng.normal(0.0, 1.0, (n, 3)) * gyro_noise_rad_s
    enc_noise = rng.normal(0.0, 1.0, (n, 2)) * encoder_noise_rad
    img_noise = rng.normal(0.0, 1.0, (n, 2)) * image_noise_px

    ang, rate = carrier_euler(t, amp, freq, phase)
    omega_b = carrier_rate(ang, rate)                     # (3, n) true carrier rate
    gyro_true = (G @ omega_b).T                           # (n, 3) point samples of w_bm
    gyro_meas = gyro_true + gyro_noise

    if loop == "continuous":
        def rhs(tt, y):
            a, r = carrier_euler(tt, amp, freq, phase)
            w = G @ carrier_rate(a, r)[:, 0]
            return list(gimbal_rates(y[0], y[1], w))
        fmax = float(np.max(np.abs(freq))) if freq.size else 1.0
        sol = solve_ivp(rhs, (t[0], t[-1]), [eta0_rad, eps0_rad], method="DOP853", t_eval=t,
                        rtol=1e-12, atol=1e-13, max_step=0.05 / max(fmax, 1e-3))
        if not sol.success:
            raise RuntimeError(sol.message)
        eta, eps = sol.y
    else:
        eta = np.empty(n)
        eps = np.empty(n)
        eta[0], eps[0] = eta0_rad, eps0_rad
        for k in range(n - 1):   # sampled controller: reads recorded gyro + encoders, holds rates
            ed, pd = gimbal_rates(eta[k] + enc_noise[k, 0], eps[k] + enc_noise[k, 1], gyro_meas[k])
            eta[k + 1] = eta[k] + dt * ed
            eps[k + 1] = eps[k] + dt * pd
    if np.any(np.abs(eps + delta_p[0]) > 85 * DEG):
        raise ValueError("gimbal pitch approaches the eq. (4) singularity (|eps| -> 90 deg)")

    # image: target = LOS direction at t = 0, fixed in the level frame (A5)
    fpx = focal_px(fov_rad, pixels)
    C_cn0 = camera_matrix(eta[0], eps[0], delta_p) @ carrier_attitude(*ang[:, 0])
    u_n = C_cn0.T @ np.array([0.0, 1.0, 0.0])
    los = np.empty((n, 2))
    for k in range(n):
        u_c = camera_matrix(eta[k], eps[k], delta_p) @ (carrier_attitude(*ang[:, k]) @ u_n)
        los[k] = fpx * u_c[0] / u_c[1], fpx * u_c[2] / u_c[1]
        if u_c[1] <= 0:
            los[k] = np.nan
    out = (np.abs(los) > 0.5 * pixels).any(axis=1) | np.isnan(los).any(axis=1)
    los[out] = np.nan
    los_meas = los + img_noise

    data = dict(t_s=t, gyro=gyro_meas, eta_rad=eta + enc_noise[:, 0], eps_rad=eps + enc_noise[:, 1],
                los_px=los_meas,
                # noise-free values (not written to the CSV; for tests and diagnostics)
                true_gyro=gyro_true, true_eta=eta, true_eps=eps, true_los_px=los,
                omega_b=omega_b.T, carrier_euler=ang.T)
    dg, dp = [float(v) for v in delta_g], [float(v) for v in delta_p]
    truth = {
        "given": "BRIEF.md and patent CN102288133B text only",
        "delta_g_rad": dict(zip(("gx", "gy", "gz"), dg)),
        "delta_p_rad": dict(zip(("px", "py", "pz"), dp)),
        "delta_z_rad (= dpz - dgz, patent eq. 6)": dp[2] - dg[2],
        "delta_g_deg": [v / DEG for v in dg], "delta_p_deg": [v / DEG for v in dp],
        "camera": {"fov_rad": float(fov_rad), "pixels": int(pixels), "focal_px": float(fpx)},
        "noise_1sigma": {"gyro_rad_s": gyro_noise_rad_s, "encoder_rad": encoder_noise_rad,
                         "image_px": image_noise_px, "seed": seed},
        "scenario": {"duration_s": duration_s, "rate_hz": rate_hz, "samples": n,
                     "rock_heading_pitch_roll_amp_rad": amp.tolist(),
                     "rock_freq_hz": freq.tolist(), "rock_phase_rad": phase.tolist(),
                     "eta0_rad": eta0_rad, "eps0_rad": eps0_rad, "loop": loop},
        "frames_out_of_view": int(out.sum()),
        "conventions": "passive matrices; w_bm = Ry(dgy)Rx(dgx)Rz(dgz) w_b; "
                       "C_cb = Ry(dpy)Rx(eps+dpx)Rz(eta+dpz); C_bn = Ry(roll)Rx(pitch)Rz(heading); "
                       "pixels = f_px*(x/y, z/y) of the target in camera axes",
    }
    return data, truth


def write_recording(csv_path, json_path, data, truth):
    """Write the CSV (brief's format) and the truth JSON."""
    cols = np.column_stack([data["t_s"], data["gyro"], data["eta_rad"], data["eps_rad"],
                            data["los_px"]])
    np.savetxt(csv_path, cols, delimiter=",", header=HEADER, comments="", fmt="%.12e")
    with open(json_path, "w") as f:
        json.dump(truth, f, indent=2)


def simulate_recording(csv_path, json_path, delta_g=(0.0, 0.0, 0.0), delta_p=(0.0, 0.0, 0.0),
                       **kwargs):
    """Simulate one run (see `simulate` for arguments and units) and write CSV + truth JSON."""
    data, truth = simulate(delta_g, delta_p, **kwargs)
    write_recording(csv_path, json_path, data, truth)
    return data, truth


if __name__ == "__main__":
    import os
    here = os.path.join(os.path.dirname(os.path.abspath(__file__)), "examples")
    os.makedirs(here, exist_ok=True)
    simulate_recording(os.path.join(here, "zero_angles.csv"),
                       os.path.join(here, "zero_angles_truth.json"), seed=1)
    _, tr = simulate_recording(os.path.join(here, "nonzero_angles.csv"),
                               os.path.join(here, "nonzero_angles_truth.json"),
                               delta_g=(0.3 * DEG, -0.4 * DEG, 0.5 * DEG),
                               delta_p=(0.6 * DEG, 0.2 * DEG, -0.35 * DEG), seed=2)
    print("wrote examples to", here, "; frames out of view:", tr["frames_out_of_view"])
