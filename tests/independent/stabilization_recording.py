"""Independent simulator of seed 001 recordings: a gyro-stabilised gimbal on a rocking carrier.

Built from the patent (CN102288133B, eqs. (1)–(4)) and the CSV format alone, with numpy and scipy,
so that it can serve as a reference for the estimator.

Conventions
-----------
- Frames: n inertial (x right, y forward, z up), b carrier, g IMU, p gimbal, c camera. Matrices
  are passive (``C_a^b`` maps coordinates in a to b); ``R_x, R_y, R_z`` are passive elementary
  rotations, e.g. ``R_z(a) = [[cos a, sin a, 0], [-sin a, cos a, 0], [0, 0, 1]]``.
- Carrier: per body axis, the rate is a sum of sinusoids ``A 2πf cos(2πft + φ)`` [rad/s] (A [rad]
  is the angle amplitude about that axis). ``dC_n^b/dt = -[ω_b×] C_n^b`` with ``C_n^b(0) = I`` is
  integrated as a quaternion by ``scipy.integrate.solve_ivp`` (DOP853, tolerances 1e-12).
- IMU (eq. (1)): ``ω_m = C_b^g ω_b + bias + noise``, ``C_b^g = R_y(δgy) R_x(δgx) R_z(δgz)``. Row k
  holds ω_m at t_k (``point``) or its mean over (t_k - h, t_k] (``interval-mean``, Gauss–Legendre
  per interval); white noise of angle random walk N [rad/√s] has standard deviation N/√h per row.
- Gimbal: ``C_b^p = R_x(ε) R_z(η)``; (η, ε) start at the aim and follow eq. (4) driven by ω_m (the
  loop knows no installation angle). Over each interval the loop takes the mean rate (the row for
  ``interval-mean``, a third-order quadrature of the rows for ``point``) and makes a midpoint
  step. Encoders report η, ε rounded to a multiple of ``encoder_lsb_rad``.
- Camera (LOS = its y axis): ``patent`` ``C_b^c = R_y(δpy) R_x(ε + δpx) R_z(η + δpz)`` (eq. (2));
  ``inner-gimbal`` ``C_b^c = R_y(δpy) R_x(δpx) R_z(δpz) R_x(ε) R_z(η)``.
- Image: the target is a fixed direction in n imaged at (x0, z0) [px] at t = 0; a direction u in c
  images at ``(k_x u_x/u_y, k_z u_z/u_y)`` [px], ``k = pixels / (2 tan(fov/2))``, plus white noise.
  A LOS turned left by a puts the target at ``+k_x a``; turned up, at ``-k_z a``.
"""

from __future__ import annotations

import argparse
import math
import os
import sys
import tempfile
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from scipy.integrate import solve_ivp
from scipy.spatial.transform import Rotation

CSV_COLUMNS = ("t_s", "gyro_x", "gyro_y", "gyro_z", "eta_rad", "eps_rad", "los_x_px", "los_z_px")
MOUNTS = ("patent", "inner-gimbal")
SAMPLINGS = ("point", "interval-mean")
ARCMIN = math.pi / (180.0 * 60.0)
"""One arc-minute [rad]."""
DEG_PER_H = math.pi / (180.0 * 3600.0)
"""One degree per hour [rad/s]."""
DEG_PER_SQRT_H = math.pi / (180.0 * 60.0)
"""One degree per root hour [rad/√s]."""
MAX_PITCH = math.radians(89.0)
"""Eq. (4) divides by cos ε: runs whose gimbal pitch goes beyond this are refused [rad]."""
DEFAULT_ROCKING = (
    ((3.0, 0.23, 0.0), (1.0, 0.71, 1.0)),
    ((4.0, 0.17, 0.5), (1.5, 0.53, 2.0), (0.5, 1.3, 0.3)),
    ((2.0, 0.11, 1.2), (0.8, 0.61, 0.0)),
)
"""Rocking about body x, y, z: terms (amplitude [deg], frequency [Hz], phase [rad])."""

Rocking = Sequence[Sequence[tuple[float, float, float]]]


@dataclass(frozen=True)
class Recording:
    """One run: the CSV columns and the truth.

    ``t_s`` [s], ``gyro`` (N, 3) [rad/s] in IMU axes, ``eta_rad``, ``eps_rad`` encoder readings
    [rad], ``los_px`` (N, 2) measured image [px]; truth: ``los_true_px`` noise-free image [px] and
    ``los_error_rad`` (N, 2), the LOS (camera y axis) turned left and up from its direction at
    t = 0, in the camera frame at t = 0 [rad].
    """

    t_s: np.ndarray
    gyro: np.ndarray
    eta_rad: np.ndarray
    eps_rad: np.ndarray
    los_px: np.ndarray
    los_true_px: np.ndarray
    los_error_rad: np.ndarray

    def columns(self) -> np.ndarray:
        """The (N, 8) table in the order of ``CSV_COLUMNS``."""
        return np.column_stack([self.t_s, self.gyro, self.eta_rad, self.eps_rad, self.los_px])


def rot(axis: str, angle) -> np.ndarray:
    """Passive elementary rotation R_axis(angle), angle [rad]; shape ``angle.shape + (3, 3)``."""
    a = np.asarray(angle, float)
    i, j = {"x": (1, 2), "y": (2, 0), "z": (0, 1)}[axis]
    m = np.zeros((*a.shape, 3, 3))
    m[..., 3 - i - j, 3 - i - j] = 1.0
    m[..., i, i] = m[..., j, j] = np.cos(a)
    m[..., i, j] = np.sin(a)
    m[..., j, i] = -np.sin(a)
    return m


def body_rate(t, rocking: Rocking) -> np.ndarray:
    """Carrier body rate ω_b(t) [rad/s] in b, shape ``t.shape + (3,)``, t [s]."""
    t = np.asarray(t, float)
    w = np.zeros((*t.shape, 3))
    for axis, terms in enumerate(rocking):
        for amp_deg, freq, phase in terms:
            omega = 2.0 * np.pi * freq
            w[..., axis] += np.radians(amp_deg) * omega * np.cos(omega * t + phase)
    return w


def carrier_attitude(t: np.ndarray, rate: Callable[[float], np.ndarray]) -> np.ndarray:
    """C_n^b (N, 3, 3) at times t [s], t[0] = 0: ``dC_n^b/dt = -[ω_b×] C_n^b``, ``C_n^b(0) = I``.

    The state is the quaternion q (x, y, z, w) of the active rotation b → n, ``C_n^b = R(q)^T``,
    with ``q̇ = ½ q ⊗ (ω_b, 0)``.
    """
    def rhs(time, q):
        w = rate(time)
        return np.concatenate([0.5 * (q[3] * w + np.cross(q[:3], w)), [-0.5 * q[:3] @ w]])

    sol = solve_ivp(rhs, (t[0], t[-1]), [0.0, 0.0, 0.0, 1.0], method="DOP853", t_eval=t,
                    rtol=1e-12, atol=1e-12)
    return Rotation.from_quat(sol.y.T).as_matrix().transpose(0, 2, 1)


def interval_mean(rate: Callable[[np.ndarray], np.ndarray], t: np.ndarray, h: float) -> np.ndarray:
    """Mean of ``rate`` over each interval (t_k - h, t_k] [rad/s], by 8-point Gauss–Legendre."""
    x, w = np.polynomial.legendre.leggauss(8)
    return 0.5 * np.einsum("j,njk->nk", w, rate(t[:, None] - 0.5 * h * (1.0 - x)))


def eq4_rates(eta: float, eps: float, w: np.ndarray) -> tuple[float, float]:
    """Eq. (4), seed 001: gimbal rates (η̇, ε̇) [rad/s] holding the LOS; carrier rate w [rad/s]."""
    se, ce, sp, cp = math.sin(eta), math.cos(eta), math.sin(eps), math.cos(eps)
    eps_dot = -ce * w[0] - se * w[1]
    eta_dot = (-sp * se * w[0] + sp * ce * w[1] - cp * w[2]) / cp
    return eta_dot, eps_dot


def gimbal_loop(w_interval: np.ndarray, h: float, eta0: float, eps0: float):
    """Gimbal angles (η, ε) [rad] at the sample times from eq. (4), one midpoint step per interval.

    Row k of ``w_interval`` [rad/s] is the rate over (t_{k-1}, t_k]; row 0 is not used.
    """
    n = len(w_interval)
    eta, eps = np.empty(n), np.empty(n)
    eta[0], eps[0] = eta0, eps0
    for k in range(1, n):
        w = w_interval[k].tolist()
        d_eta, d_eps = eq4_rates(eta[k - 1], eps[k - 1], w)
        d_eta, d_eps = eq4_rates(eta[k - 1] + 0.5 * h * d_eta, eps[k - 1] + 0.5 * h * d_eps, w)
        eta[k], eps[k] = eta[k - 1] + h * d_eta, eps[k - 1] + h * d_eps
    return eta, eps


def point_to_interval(w: np.ndarray) -> np.ndarray:
    """Mean rate over (t_{k-1}, t_k] [rad/s] from point samples w (N, 3): weights (-1, 8, 5)/12 on
    rows k-2, k-1, k (third order); the trapezoid for row 1; row 0 is copied."""
    out = w.copy()
    out[1:] = 0.5 * (w[:-1] + w[1:])
    out[2:] = (-w[:-2] + 8.0 * w[1:-1] + 5.0 * w[2:]) / 12.0
    return out


def camera_dcm(eta, eps, delta_p: np.ndarray, mount: str) -> np.ndarray:
    """C_b^c for gimbal angles η, ε [rad] and camera installation angles δp (x, y, z) [rad]."""
    if mount == "patent":
        return rot("y", delta_p[1]) @ rot("x", eps + delta_p[0]) @ rot("z", eta + delta_p[2])
    return (rot("y", delta_p[1]) @ rot("x", delta_p[0]) @ rot("z", delta_p[2])
            @ rot("x", eps) @ rot("z", eta))


def pinhole(u: np.ndarray, k: np.ndarray) -> np.ndarray:
    """Image (x, z) [px] of directions u (..., 3) in the camera frame; k (k_x, k_z) [px/rad]."""
    return k * u[..., [0, 2]] / u[..., 1:2]


def simulate_recording(*, delta_g_arcmin, delta_p_arcmin, mount: str, gyro_sampling: str,
                       target_offset_px=(0.0, 0.0), duration_s: float = 60.0,
                       rate_hz: float = 100.0, fov_deg=(4.0, 3.0), pixels=(1280, 960),
                       aim_deg=(10.0, 15.0), gyro_bias_deg_h=(2.0, -1.5, 3.0),
                       gyro_arw: float = 0.02, image_noise_px: float = 0.3,
                       encoder_lsb_rad: float | None = 2.0 * np.pi / 2**20,
                       rocking_deg: Rocking = DEFAULT_ROCKING,
                       rng: np.random.Generator | None = None) -> Recording:
    """Simulate one run of the gimbal while the carrier rocks.

    Parameters
    ----------
    delta_g_arcmin, delta_p_arcmin : IMU (δgx, δgy, δgz) and camera (δpx, δpy, δpz) installation
        angles [arcmin]. target_offset_px : image (x0, z0) of the target at t = 0 [px].
    aim_deg : initial gimbal azimuth η and pitch ε [deg]. gyro_bias_deg_h : constant bias per IMU
        axis [deg/h]. gyro_arw : angle random walk [deg/√h]. encoder_lsb_rad : encoder step
        [rad] (None: exact). rocking_deg : see ``DEFAULT_ROCKING``.
    """
    if mount not in MOUNTS or gyro_sampling not in SAMPLINGS:
        raise ValueError(f"mount {mount!r} or gyro_sampling {gyro_sampling!r} unknown")
    rng = np.random.default_rng() if rng is None else rng
    h = 1.0 / rate_hz
    t = np.arange(round(duration_s * rate_hz)) * h
    n = len(t)
    delta_g = np.asarray(delta_g_arcmin, float) * ARCMIN
    delta_p = np.asarray(delta_p_arcmin, float) * ARCMIN

    def rate(tau):
        return body_rate(tau, rocking_deg)

    c_bg = rot("y", delta_g[1]) @ rot("x", delta_g[0]) @ rot("z", delta_g[2])
    w_b = rate(t) if gyro_sampling == "point" else interval_mean(rate, t, h)
    gyro = (w_b @ c_bg.T + np.asarray(gyro_bias_deg_h, float) * DEG_PER_H
            + rng.standard_normal((n, 3)) * gyro_arw * DEG_PER_SQRT_H / math.sqrt(h))
    w_loop = gyro if gyro_sampling == "interval-mean" else point_to_interval(gyro)
    eta, eps = gimbal_loop(w_loop, h, *np.radians(aim_deg))
    if np.max(np.abs(eps)) > MAX_PITCH:
        raise ValueError(f"gimbal pitch reaches {np.degrees(np.max(np.abs(eps))):.2f} deg "
                         f"(beyond {np.degrees(MAX_PITCH):.0f} deg)")

    c_nc = camera_dcm(eta, eps, delta_p, mount) @ carrier_attitude(t, rate)
    k = np.asarray(pixels, float) / (2.0 * np.tan(np.radians(np.asarray(fov_deg, float)) / 2.0))
    u0 = np.array([target_offset_px[0] / k[0], 1.0, target_offset_px[1] / k[1]])
    u = c_nc @ (c_nc[0].T @ (u0 / np.linalg.norm(u0)))
    los_true = pinhole(u, k)
    los = c_nc[0] @ c_nc[:, 1, :, None]
    los_error = np.column_stack([np.arctan2(-los[:, 0, 0], los[:, 1, 0]),
                                 np.arctan2(los[:, 2, 0], los[:, 1, 0])])
    image = los_true + rng.standard_normal((n, 2)) * image_noise_px
    if encoder_lsb_rad:
        eta, eps = (np.round(a / encoder_lsb_rad) * encoder_lsb_rad for a in (eta, eps))
    return Recording(t_s=t, gyro=gyro, eta_rad=eta, eps_rad=eps, los_px=image,
                     los_true_px=los_true, los_error_rad=los_error)


def write_csv(path: str | Path, recording: Recording) -> None:
    """Write the run in the seed 001 CSV format, atomically (temporary file, then rename)."""
    path = Path(path)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    try:
        with os.fdopen(fd, "w") as out:
            out.write(",".join(CSV_COLUMNS) + "\n")
            np.savetxt(out, recording.columns(), fmt="%.17g", delimiter=",")
        os.chmod(tmp, 0o644)
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


class _Parser(argparse.ArgumentParser):
    """Bad flags: one line and exit code 2, without the usage text."""

    def error(self, message):
        self.exit(2, f"{self.prog}: {message}\n")


def main(argv: Sequence[str] | None = None) -> int:
    """Command line: write one simulated run as CSV; the truth goes to standard output."""
    p = _Parser(prog="python -m tests.independent.stabilization_recording",
                                description="Simulate a seed 001 recording (CSV).")
    p.add_argument("out", type=Path)
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--mount", choices=MOUNTS, default="patent")
    p.add_argument("--gyro-sampling", choices=SAMPLINGS, default="interval-mean")
    p.add_argument("--delta-g-arcmin", type=float, nargs=3, default=(5.0, -4.0, 3.0))
    p.add_argument("--delta-p-arcmin", type=float, nargs=3, default=(-6.0, 2.0, 8.0))
    p.add_argument("--target-offset-px", type=float, nargs=2, default=(0.0, 0.0))
    p.add_argument("--aim-deg", type=float, nargs=2, default=(10.0, 15.0))
    p.add_argument("--duration-s", type=float, default=60.0)
    p.add_argument("--rate-hz", type=float, default=100.0)
    p.add_argument("--gyro-bias-deg-h", type=float, nargs=3, default=(2.0, -1.5, 3.0))
    p.add_argument("--gyro-arw", type=float, default=0.02, help="angle random walk [deg/√h]")
    p.add_argument("--image-noise-px", type=float, default=0.3)
    a = p.parse_args(argv)
    try:
        rec = simulate_recording(
            delta_g_arcmin=a.delta_g_arcmin, delta_p_arcmin=a.delta_p_arcmin, mount=a.mount,
            gyro_sampling=a.gyro_sampling, target_offset_px=a.target_offset_px,
            duration_s=a.duration_s, rate_hz=a.rate_hz, aim_deg=a.aim_deg,
            gyro_bias_deg_h=a.gyro_bias_deg_h, gyro_arw=a.gyro_arw,
            image_noise_px=a.image_noise_px, rng=np.random.default_rng(a.seed))
        write_csv(a.out, rec)
    except ValueError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    except OSError as exc:
        print(f"{a.out}: cannot write ({exc.strerror})", file=sys.stderr)
        return 2
    dg, dp = np.asarray(a.delta_g_arcmin), np.asarray(a.delta_p_arcmin)
    print(f"{a.out}: {len(rec.t_s)} rows; truth [arcmin] dpx={dp[0]:g} dgx={dg[0]:g} "
          f"dgy={dg[1]:g} dz={dp[2] - dg[2]:g} dpy={dp[1]:g}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
