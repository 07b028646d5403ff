"""Fast fused kernel of the ground calibration: placement -> pixels -> both solves -> D.

Same mathematics as the literal reference (:mod:`montecarlo.seed000.ground`, seed 000 eqs. 4-18)
in another algebra, tested equal to it to 1e-12:

* pixels from the tangent-plane form ``k u_x / u_y`` (no equivalent angles;
  docs/reference/conventions.md);
* directions from pixels as ``[f_x / k_x, 1, f_z / k_z]`` normalised (eqs. 1-3 combined);
* eq. (14) without inverse trigonometry: ``sin(theta) = C23``, ``cos(theta) = sqrt(1 - C23^2)``,
  ``(sin, cos)(gamma) = (-C13, C33) / hypot(C13, C33)``, ``sin(psi) = (C12 C33 - C13 C32) /
  cos(theta)``, and ``C_b^c`` of eq. (5) built from those sines and cosines, so Euler angles are
  never formed;
* the elements of ``D = C_b^c (C_b^a)^T`` that the metrics need.

The arithmetic and the invalid-geometry flags run in one numba loop; the inverse trigonometric
functions of the metrics run as numpy's SIMD ufuncs (numba's are scalar here). Aggregation into
the streaming statistics is :mod:`montecarlo.engine.accumulate`, a second numba loop.
"""

from __future__ import annotations

import numba as nb
import numpy as np

from montecarlo.geometry.invalid import Invalid
from montecarlo.jit import cached

_BEHIND = int(Invalid.BEHIND_SENSOR)
_OUTSIDE = int(Invalid.OUTSIDE_FOV)
_PITCH = int(Invalid.PITCH_OUT_OF_RANGE)
_ROLL = int(Invalid.ROLL_OUT_OF_RANGE)
_YAW = int(Invalid.YAW_OUT_OF_RANGE)

N_FIELDS = 9
"""Rows of the kernel's output per solver variant. Grouped by the function that turns them
into metrics (VALUE_ROWS): rows 0-5, arctan2 numerators: |axial vector| (= 2 sin phi), -D21,
-D13 of raw, then of normalised; rows 6-11, the denominators: tr D - 1, D22, D33; rows 12-13,
arccos arguments (1 + tr D)/4, clipped (raw, normalised); rows 14-15, arcsin arguments D23,
clipped; rows 16-17, filled by :func:`metrics_in_place` with eq. (18)."""

VALUE_ROWS = (
    (0, "rotation_angle"), (0, "delta_psi"), (0, "delta_gamma"),
    (1, "rotation_angle"), (1, "delta_psi"), (1, "delta_gamma"),
    (0, "table1_angle"), (1, "table1_angle"), (0, "delta_theta"), (1, "delta_theta"),
    (0, "eq18_angle"), (1, "eq18_angle"),
)
"""(variant index: 0 raw, 1 normalised; metric) of each metric row of
:func:`metrics_in_place`; the rows themselves are METRIC_ROWS of the fields."""
METRIC_ROWS = np.array([0, 1, 2, 3, 4, 5, 12, 13, 14, 15, 16, 17])
"""Rows of the fields that hold the metrics after :func:`metrics_in_place`."""

SUB_CHUNK = 8192
"""Trials whose statistics are reduced together and merged into a block's (by Chan's formula,
in trial order): the published figures depend on it, so it stays fixed."""
SOLVE_CHUNK = 65536
"""Trials solved and reduced to metrics at a time inside a block, a multiple of SUB_CHUNK
(speed only: the figures do not depend on it)."""


@nb.njit(inline="always")
def _clip(x, lo, hi):  # pragma: no cover - compiled
    """x limited to [lo, hi] by selects (numba's min/max stop LLVM vectorising)."""
    x = lo if x < lo else x
    return hi if x > hi else x


# Written for LLVM's loop vectoriser, which is what makes this kernel fast:
# - the loops call only forceinline functions (inlined by LLVM, so the loop body is flat; numba's
#   own inlining breaks parfor analysis here);
# - parallel=True only for prange's no-alias guarantee on arguments (it runs on one thread, see
#   solve_chunk);
# - one 1-D argument per row: rows of one 2-D array would need run-time overlap checks, too many
#   for the vectoriser;
# - one reciprocal per divisor: division and square root set the pace.
@nb.njit(forceinline=True, error_model="numpy")
def _solution(m12, m32, m13, m23, m33, pre, c00, c01, c02, c10, c11, c12, c20, c21, c22
              ):  # pragma: no cover - compiled
    """(flag, the 8 fields of N_FIELDS) of one solution: eq. (14) as sines and cosines, eq. (5)
    from them, then D = C_b^c (C_b^a)^T."""
    st = m23
    ct = np.sqrt(1.0 - m23 * m23)
    sp = (m12 * m33 - m13 * m32) / ct
    cp = np.sqrt(1.0 - sp * sp)
    inv_hg = 1.0 / np.sqrt(m13 * m13 + m33 * m33)
    sg = -m13 * inv_hg
    cg = m33 * inv_hg
    e14 = (_PITCH if not (abs(m23) < 1.0) else 0) | (_ROLL if not (m33 > 0.0) else 0)
    e14 = _YAW if (e14 == 0) & (not (abs(sp) <= 1.0)) else e14
    flag = pre if pre != 0 else e14
    # eq. (5): C_b^c from the computed sines and cosines
    e00 = cg * cp - sg * st * sp
    e01 = cg * sp + sg * st * cp
    e02 = -sg * ct
    e10 = -ct * sp
    e11 = ct * cp
    e12 = st
    e20 = sg * cp + cg * st * sp
    e21 = sg * sp - cg * st * cp
    e22 = cg * ct
    # D = C_b^c (C_b^a)^T
    d00 = e00 * c00 + e01 * c01 + e02 * c02
    d01 = e00 * c10 + e01 * c11 + e02 * c12
    d02 = e00 * c20 + e01 * c21 + e02 * c22
    d10 = e10 * c00 + e11 * c01 + e12 * c02
    d11 = e10 * c10 + e11 * c11 + e12 * c12
    d12 = e10 * c20 + e11 * c21 + e12 * c22
    d20 = e20 * c00 + e21 * c01 + e22 * c02
    d21 = e20 * c10 + e21 * c11 + e22 * c12
    d22 = e20 * c20 + e21 * c21 + e22 * c22
    w0 = d21 - d12
    w1 = d02 - d20
    w2 = d10 - d01
    trace = d00 + d11 + d22
    ok = flag == 0
    nan = np.nan
    # the arguments of the metrics of montecarlo.geometry.metrics, clipped as there
    return (flag,
            np.sqrt(w0 * w0 + w1 * w1 + w2 * w2) if ok else nan,
            trace - 1.0 if ok else nan,
            _clip((1.0 + trace) / 4.0, -1.0, 1.0) if ok else nan,
            -d10 if ok else nan,
            d11 if ok else nan,
            _clip(d12, -1.0, 1.0) if ok else nan,
            -d02 if ok else nan,
            d22 if ok else nan)


@nb.njit(forceinline=True, error_model="numpy")
def _trial(c00, c01, c02, c10, c11, c12, c20, c21, c22, L, H, kx, kz, half_nx, half_nz, rb,
           inv_kx, inv_kz, inv_h, affine, u0, u1, u2, u3, u4, u5, u6, u7
           ):  # pragma: no cover - compiled
    """Both solutions of one trial: (flag, 8 fields) raw followed by normalised."""
    # the draws in their units (the affine maps of GroundSystem.unit_draws)
    x = affine[0, 0] * u0 + affine[1, 0]
    y = L + (affine[0, 1] * u1 + affine[1, 1])
    za = affine[0, 2] * u2 + affine[1, 2]
    zb = H + za + (affine[0, 3] * u3 + affine[1, 3])
    # eq. (6): targets in frame a; eq. (4) in tangent-plane form
    uax = c00 * x + c01 * y + c02 * za
    uay = c10 * x + c11 * y + c12 * za
    uaz = c20 * x + c21 * y + c22 * za
    ubx = c00 * x + c01 * y + c02 * zb
    uby = c10 * x + c11 * y + c12 * zb
    ubz = c20 * x + c21 * y + c22 * zb
    inv_ua = 1.0 / uay
    inv_ub = 1.0 / uby
    pax = kx * uax * inv_ua
    paz = kz * uaz * inv_ua
    pbx = kx * ubx * inv_ub
    pbz = kz * ubz * inv_ub
    # forward reasons per target, combined as ground.simulate does
    fa = _BEHIND if not (uay > 0.0) else \
        (0 if (abs(pax) <= half_nx) & (abs(paz) <= half_nz) else _OUTSIDE)
    fb = _BEHIND if not (uby > 0.0) else \
        (0 if (abs(pbx) <= half_nx) & (abs(pbz) <= half_nz) else _OUTSIDE)
    fwd = fa | fb
    pax += affine[0, 4] * u4 + affine[1, 4]
    paz += affine[0, 5] * u5 + affine[1, 5]
    pbx += affine[0, 6] * u6 + affine[1, 6]
    pbz += affine[0, 7] * u7 + affine[1, 7]
    seen = (abs(pax) <= half_nx) & (abs(paz) <= half_nz) & (abs(pbx) <= half_nx) \
        & (abs(pbz) <= half_nz)
    pre = fwd if fwd != 0 else (0 if seen else _OUTSIDE)
    # eqs. (1)-(3), (7)-(9): unit directions of A and B in frame a
    ax = pax * inv_kx
    az = paz * inv_kz
    ay = 1.0 / np.sqrt(ax * ax + 1.0 + az * az)
    ax = ax * ay
    az = az * ay
    bx = pbx * inv_kx
    bz = pbz * inv_kz
    by = 1.0 / np.sqrt(bx * bx + 1.0 + bz * bz)
    bx = bx * by
    bz = bz * by
    # eq. (11): raw solution
    m13 = (bx * rb - ax * L) * inv_h
    m23 = (by * rb - ay * L) * inv_h
    m33 = (bz * rb - az * L) * inv_h
    raw = _solution(ax, az, m13, m23, m33, pre, c00, c01, c02, c10, c11, c12, c20, c21, c22)
    # eqs. (12)-(13): normalised solution
    alpha = np.sqrt(m13 * m13 + m23 * m23 + m33 * m33)
    cross = ax * m33 - m13 * az
    beta = np.sqrt(cross * cross + ay * ay + m23 * m23)
    inv_alpha = 1.0 / alpha
    ratio = alpha / beta
    norm = _solution(ratio * ax, ratio * az, m13 * inv_alpha, m23 * inv_alpha,
                     m33 * inv_alpha, pre, c00, c01, c02, c10, c11, c12, c20, c21, c22)
    return raw + norm


@nb.njit(forceinline=True)
def _store(t, i, flag_raw, flag_norm, r0, r1, r2, r3, r4, r5, r6, r7, n0, n1, n2, n3, n4, n5,
           n6, n7):  # pragma: no cover - compiled
    flag_raw[i] = t[0]
    r0[i], r1[i], r2[i], r3[i], r4[i], r5[i], r6[i], r7[i] = t[1:9]
    flag_norm[i] = t[9]
    n0[i], n1[i], n2[i], n3[i], n4[i], n5[i], n6[i], n7[i] = t[10:18]


@nb.njit(cache=True, nogil=True, error_model="numpy", parallel=True)
def _solve_fixed(L, H, kx, kz, half_nx, half_nz, affine, C,
                 u0, u1, u2, u3, u4, u5, u6, u7, flag_raw, flag_norm,
                 r0, r1, r2, r3, r4, r5, r6, r7, n0, n1, n2, n3, n4, n5, n6, n7
                 ):  # pragma: no cover - compiled
    """All trials with one C_b^a (``C``, 9 values): no per-trial matrix to read."""
    rb = np.sqrt(L * L + H * H)
    inv_kx, inv_kz, inv_h = 1.0 / kx, 1.0 / kz, 1.0 / H
    c00, c01, c02, c10, c11, c12, c20, c21, c22 = C[0], C[1], C[2], C[3], C[4], C[5], C[6], \
        C[7], C[8]
    for i in nb.prange(u0.shape[0]):
        t = _trial(c00, c01, c02, c10, c11, c12, c20, c21, c22, L, H, kx, kz, half_nx,
                   half_nz, rb, inv_kx, inv_kz, inv_h, affine, u0[i], u1[i], u2[i], u3[i],
                   u4[i], u5[i], u6[i], u7[i])
        _store(t, i, flag_raw, flag_norm, r0, r1, r2, r3, r4, r5, r6, r7, n0, n1, n2, n3, n4,
               n5, n6, n7)


@nb.njit(cache=True, nogil=True, error_model="numpy", parallel=True)
def _solve_varying(L, H, kx, kz, half_nx, half_nz, affine,
                   C00, C01, C02, C10, C11, C12, C20, C21, C22,
                   u0, u1, u2, u3, u4, u5, u6, u7, flag_raw, flag_norm,
                   r0, r1, r2, r3, r4, r5, r6, r7, n0, n1, n2, n3, n4, n5, n6, n7
                   ):  # pragma: no cover - compiled
    """Each trial with its own C_b^a (rows C00..C22)."""
    rb = np.sqrt(L * L + H * H)
    inv_kx, inv_kz, inv_h = 1.0 / kx, 1.0 / kz, 1.0 / H
    for i in nb.prange(u0.shape[0]):
        t = _trial(C00[i], C01[i], C02[i], C10[i], C11[i], C12[i], C20[i], C21[i], C22[i], L,
                   H, kx, kz, half_nx, half_nz, rb, inv_kx, inv_kz, inv_h, affine, u0[i], u1[i],
                   u2[i], u3[i], u4[i], u5[i], u6[i], u7[i])
        _store(t, i, flag_raw, flag_norm, r0, r1, r2, r3, r4, r5, r6, r7, n0, n1, n2, n3, n4,
               n5, n6, n7)


_ARG_ROWS = (0, 6, 12, 1, 7, 14, 2, 8, 3, 9, 13, 4, 10, 15, 5, 11)
"""Output row of each field argument of the kernel (r0..r7 = raw |axial|, tr D - 1,
(1 + tr D)/4, -D21, D22, D23, -D13, D33; n0..n7 the same normalised)."""


def solve_chunk(C: np.ndarray, L: float, H: float, kx: float, kz: float, half_nx: float,
                half_nz: float, rows: list[np.ndarray], affine: np.ndarray, flags: np.ndarray,
                out: np.ndarray, out_rows: tuple[np.ndarray, ...] | None = None) -> None:
    """Forward model, both solver variants and the D fields for n trials.

    Parameters
    ----------
    C : (9,) or (9, n) float64, true C_b^a row-major, one for all trials or one per trial.
    L, H : float [m], nominal range and height difference; kx, kz, half_nx, half_nz : camera
        scale and half detector size [px].
    rows, affine : the unit draws of dx, dy, dh1, dh [m] and eax, eaz, ebx, ebz [px] (8 arrays
        of shape (n,)) and their affine maps (2, 8): value = affine[0, k] rows[k] +
        affine[1, k] (see ``GroundSystem.unit_draws``).
    flags : (2, n) uint16 out, Invalid bits for variant 0 (raw) and 1 (normalised); a trial
        rejected by the forward model carries its reasons, as in ``ground.simulate``.
    out : (2 * N_FIELDS, n) float64 out, the fields of both variants in the layout of
        N_FIELDS, NaN where invalid.
    out_rows : ``output_rows(out)``, if the caller keeps it for a reused buffer.
    """
    nb.set_num_threads(1)  # the runner's workers are processes (2 us a call: negligible)
    outs = output_rows(out) if out_rows is None else out_rows
    if C.ndim == 1:
        _solve_fixed(L, H, kx, kz, half_nx, half_nz, affine, C, *rows, *flags, *outs)
    else:
        _solve_varying(L, H, kx, kz, half_nx, half_nz, affine, *C, *rows, *flags, *outs)


def output_rows(out: np.ndarray) -> tuple[np.ndarray, ...]:
    """The rows of ``out`` in the kernel's argument order (for callers that reuse ``out``)."""
    return tuple(out[k] for k in _ARG_ROWS)


def metrics_in_place(fields: np.ndarray) -> None:
    """The metrics of :mod:`montecarlo.geometry.metrics` from the kernel's fields, in place [rad].

    ``fields``: (2 * N_FIELDS, n); afterwards its METRIC_ROWS hold the metrics of VALUE_ROWS.
    The reference's formulas, evaluated by numpy's SIMD ufuncs over stacked rows; arctan2 of
    the full rather than the halved arguments of ``metrics.rotation_angle`` gives the same
    result, since halving is exact. Eq. (18) as printed, ``arccos(sqrt(1 + tr D)/2)``, is
    exactly half the rotation angle (docs/reference/conventions.md) and is taken as that:
    evaluating the arccos form would only add its own round-off (see ``metrics.eq18_angle``).
    """
    np.arctan2(fields[0:6], fields[6:12], out=fields[0:6])
    np.arccos(fields[12:14], out=fields[12:14])
    np.arcsin(fields[14:16], out=fields[14:16])
    np.multiply(fields[0:4:3], 0.5, out=fields[16:18])


def is_cached(varying: bool) -> bool:
    """True if numba's cache holds the kernel for one mounting (or, ``varying``, one per trial);
    else its first use compiles (several seconds)."""
    return cached(_solve_varying if varying else _solve_fixed)
