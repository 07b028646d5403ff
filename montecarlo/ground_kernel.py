"""Fast fused kernel of the ground calibration: placement -> pixels -> both solves -> D.

Same mathematics as the literal reference (:mod:`montecarlo.ground`, seed 000 eqs. 4-18) in
another algebra, tested equal to it to 1e-12:

* pixels from the tangent-plane form ``k u_x / u_y`` (no equivalent angles, NOTES.md);
* directions from pixels as ``[f_x / k_x, 1, f_z / k_z]`` normalised (eqs. 1-3 combined);
* eq. (14) without inverse trigonometry: ``sin(theta) = C23``, ``cos(theta) = sqrt(1 - C23^2)``,
  ``(sin, cos)(gamma) = (-C13, C33) / hypot(C13, C33)``, ``sin(psi) = (C12 C33 - C13 C32) /
  cos(theta)``, and ``C_b^c`` of eq. (5) built from those sines and cosines, so Euler angles are
  never formed;
* the elements of ``D = C_b^c (C_b^a)^T`` that the metrics need.

The arithmetic and the invalid-geometry flags run in one numba loop; the inverse trigonometric
functions of the metrics run as numpy's SIMD ufuncs (numba's are scalar here). Aggregation into
the streaming statistics of :mod:`montecarlo.aggregate` is a second numba loop.
"""

from __future__ import annotations

import numba as nb
import numpy as np

from montecarlo import aggregate as agg
from montecarlo import ground_study
from montecarlo.invalid import Invalid

_BEHIND = int(Invalid.BEHIND_SENSOR)
_OUTSIDE = int(Invalid.OUTSIDE_FOV)
_PITCH = int(Invalid.PITCH_OUT_OF_RANGE)
_ROLL = int(Invalid.ROLL_OUT_OF_RANGE)
_YAW = int(Invalid.YAW_OUT_OF_RANGE)

D_FIELDS = ("axial", "trace_minus_1", "eq18_cos", "table1_cos", "minus_d21", "d22",
            "d23_clipped", "minus_d13", "d33")
"""Per trial and variant the kernel returns these quantities of D (axial = |axial vector| =
2 sin(phi)); the metrics are then one inverse trigonometric function of them each."""
N_FIELDS = len(D_FIELDS)

_SHIFT = agg._SHIFT
_BASE = agg._BASE
_ZERO = agg.ZERO_BIN
_N_MAG = agg.N_MAG

SUB_CHUNK = 8192
"""Trials processed at a time inside a block (keeps the working set in cache)."""


@nb.njit(inline="always")
def _clip(x, lo, hi):  # pragma: no cover - compiled
    """x limited to [lo, hi] by selects (numba's min/max stop LLVM vectorising)."""
    x = lo if x < lo else x
    return hi if x > hi else x


# Written for LLVM's loop vectoriser, which is what makes this kernel fast:
# - one flat loop body without calls (numba's inliner breaks parfor analysis here, hence the
#   raw and normalised blocks written out);
# - parallel=True only for prange's no-alias guarantee on arguments (it runs on one thread,
#   see solve_chunk);
# - one 1-D argument per row: rows of one 2-D array would need run-time overlap checks, too
#   many for the vectoriser.
@nb.njit(cache=True, nogil=True, error_model="numpy", parallel=True)
def _solve(L, H, kx, kz, half_nx, half_nz,
           C00, C01, C02, C10, C11, C12, C20, C21, C22,
           dx, dy, dh1, dh, eax, eaz, ebx, ebz, flag_raw, flag_norm,
           r0, r1, r2, r3, r4, r5, r6, r7, r8, n0, n1, n2, n3, n4, n5, n6, n7, n8
           ):  # pragma: no cover - compiled
    rb = np.sqrt(L * L + H * H)
    nan = np.nan
    for i in nb.prange(dx.shape[0]):
        c00, c01, c02 = C00[i], C01[i], C02[i]
        c10, c11, c12 = C10[i], C11[i], C12[i]
        c20, c21, c22 = C20[i], C21[i], C22[i]
        x = dx[i]
        y = L + dy[i]
        za = dh1[i]
        zb = H + dh1[i] + dh[i]
        # eq. (6): targets in frame a; eq. (4) in tangent-plane form
        uax = c00 * x + c01 * y + c02 * za
        uay = c10 * x + c11 * y + c12 * za
        uaz = c20 * x + c21 * y + c22 * za
        ubx = c00 * x + c01 * y + c02 * zb
        uby = c10 * x + c11 * y + c12 * zb
        ubz = c20 * x + c21 * y + c22 * zb
        pax = kx * uax / uay
        paz = kz * uaz / uay
        pbx = kx * ubx / uby
        pbz = kz * ubz / uby
        # forward reasons per target, combined as ground.simulate does
        fa = _BEHIND if not (uay > 0.0) else \
            (0 if (abs(pax) <= half_nx) & (abs(paz) <= half_nz) else _OUTSIDE)
        fb = _BEHIND if not (uby > 0.0) else \
            (0 if (abs(pbx) <= half_nx) & (abs(pbz) <= half_nz) else _OUTSIDE)
        fwd = fa | fb
        pax += eax[i]
        paz += eaz[i]
        pbx += ebx[i]
        pbz += ebz[i]
        seen2 = (abs(pax) <= half_nx) & (abs(paz) <= half_nz) & (abs(pbx) <= half_nx) \
            & (abs(pbz) <= half_nz)
        pre = fwd if fwd != 0 else (0 if seen2 else _OUTSIDE)
        # eqs. (1)-(3), (7)-(9): unit directions of A and B in frame a
        ax = pax / kx
        az = paz / kz
        na = np.sqrt(ax * ax + 1.0 + az * az)
        ax = ax / na
        ay = 1.0 / na
        az = az / na
        bx = pbx / kx
        bz = pbz / kz
        nb_ = np.sqrt(bx * bx + 1.0 + bz * bz)
        bx = bx / nb_
        by = 1.0 / nb_
        bz = bz / nb_
        # eq. (11): raw solution
        m12_r, m32_r = ax, az
        m13_r = (bx * rb - ax * L) / H
        m23_r = (by * rb - ay * L) / H
        m33_r = (bz * rb - az * L) / H
        # eqs. (12)-(13): normalised solution
        alpha = np.sqrt(m13_r * m13_r + m23_r * m23_r + m33_r * m33_r)
        cross = ax * m33_r - m13_r * az
        beta = np.sqrt(cross * cross + ay * ay + m23_r * m23_r)
        m13_n, m23_n, m33_n = m13_r / alpha, m23_r / alpha, m33_r / alpha
        m12_n, m32_n = alpha * ax / beta, alpha * az / beta
        # raw: eq. (14) as sines and cosines, eq. (5), D
        st_r = m23_r
        ct_r = np.sqrt(1.0 - m23_r * m23_r)
        sp_r = (m12_r * m33_r - m13_r * m32_r) / ct_r
        cp_r = np.sqrt(1.0 - sp_r * sp_r)
        hg_r = np.sqrt(m13_r * m13_r + m33_r * m33_r)
        sg_r = -m13_r / hg_r
        cg_r = m33_r / hg_r
        e14_r = (_PITCH if not (abs(m23_r) < 1.0) else 0) \
            | (_ROLL if not (m33_r > 0.0) else 0)
        e14_r = _YAW if (e14_r == 0) & (not (abs(sp_r) <= 1.0)) else e14_r
        flag_r = pre if pre != 0 else e14_r
        # eq. (5): C_b^c from the computed sines and cosines
        e00 = cg_r * cp_r - sg_r * st_r * sp_r
        e01 = cg_r * sp_r + sg_r * st_r * cp_r
        e02 = -sg_r * ct_r
        e10 = -ct_r * sp_r
        e11 = ct_r * cp_r
        e12 = st_r
        e20 = sg_r * cp_r + cg_r * st_r * sp_r
        e21 = sg_r * sp_r - cg_r * st_r * cp_r
        e22 = cg_r * ct_r
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
        ok = flag_r == 0
        flag_raw[i] = flag_r
        # the arguments of the metrics of montecarlo.metrics, clipped as there
        r0[i] = np.sqrt(w0 * w0 + w1 * w1 + w2 * w2) if ok else nan
        r1[i] = trace - 1.0 if ok else nan
        c18 = np.sqrt(_clip(1.0 + trace, 0.0, 4.0)) / 2.0
        r2[i] = c18 if ok else nan
        r3[i] = _clip((1.0 + trace) / 4.0, -1.0, 1.0) if ok else nan
        r4[i] = -d10 if ok else nan
        r5[i] = d11 if ok else nan
        r6[i] = _clip(d12, -1.0, 1.0) if ok else nan
        r7[i] = -d02 if ok else nan
        r8[i] = d22 if ok else nan
        # normalised: the same with the normalised columns
        st_n = m23_n
        ct_n = np.sqrt(1.0 - m23_n * m23_n)
        sp_n = (m12_n * m33_n - m13_n * m32_n) / ct_n
        cp_n = np.sqrt(1.0 - sp_n * sp_n)
        hg_n = np.sqrt(m13_n * m13_n + m33_n * m33_n)
        sg_n = -m13_n / hg_n
        cg_n = m33_n / hg_n
        e14_n = (_PITCH if not (abs(m23_n) < 1.0) else 0) \
            | (_ROLL if not (m33_n > 0.0) else 0)
        e14_n = _YAW if (e14_n == 0) & (not (abs(sp_n) <= 1.0)) else e14_n
        flag_n = pre if pre != 0 else e14_n
        # eq. (5): C_b^c from the computed sines and cosines
        e00 = cg_n * cp_n - sg_n * st_n * sp_n
        e01 = cg_n * sp_n + sg_n * st_n * cp_n
        e02 = -sg_n * ct_n
        e10 = -ct_n * sp_n
        e11 = ct_n * cp_n
        e12 = st_n
        e20 = sg_n * cp_n + cg_n * st_n * sp_n
        e21 = sg_n * sp_n - cg_n * st_n * cp_n
        e22 = cg_n * ct_n
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
        ok = flag_n == 0
        flag_norm[i] = flag_n
        # the arguments of the metrics of montecarlo.metrics, clipped as there
        n0[i] = np.sqrt(w0 * w0 + w1 * w1 + w2 * w2) if ok else nan
        n1[i] = trace - 1.0 if ok else nan
        c18 = np.sqrt(_clip(1.0 + trace, 0.0, 4.0)) / 2.0
        n2[i] = c18 if ok else nan
        n3[i] = _clip((1.0 + trace) / 4.0, -1.0, 1.0) if ok else nan
        n4[i] = -d10 if ok else nan
        n5[i] = d11 if ok else nan
        n6[i] = _clip(d12, -1.0, 1.0) if ok else nan
        n7[i] = -d02 if ok else nan
        n8[i] = d22 if ok else nan


def solve_chunk(C: np.ndarray, L: float, H: float, kx: float, kz: float, half_nx: float,
                half_nz: float, draws: np.ndarray, flags: np.ndarray, out: np.ndarray) -> None:
    """Forward model, both solver variants and the D fields for n trials.

    Parameters
    ----------
    C : (9, n) float64, true C_b^a row-major per trial (repeat a fixed one).
    L, H : float [m], nominal range and height difference; kx, kz, half_nx, half_nz : camera
        scale and half detector size [px].
    draws : (8, n) float64, rows dx, dy, dh1, dh [m] and eax, eaz, ebx, ebz [px].
    flags : (2, n) uint16 out, Invalid bits for variant 0 (raw) and 1 (normalised); a trial
        rejected by the forward model carries its reasons, as in ``ground.simulate``.
    out : (2 * N_FIELDS, n) float64 out, the D_FIELDS of variant 0 then variant 1, NaN where
        invalid.
    """
    previous = nb.get_num_threads()
    nb.set_num_threads(1)
    try:
        _solve(L, H, kx, kz, half_nx, half_nz, *C, *draws, *flags, *out)
    finally:
        nb.set_num_threads(previous)


METRIC_ORDER = ground_study.METRIC_ORDER
"""Metric rows produced by :func:`metrics_from_fields` (the names of montecarlo.metrics)."""


def metrics_from_fields(fields: np.ndarray, out: np.ndarray) -> None:
    """The metrics of :mod:`montecarlo.metrics` from one variant's D fields [rad].

    ``fields``: (N_FIELDS, n); ``out``: (6, n), rows in METRIC_ORDER. Each metric is the
    reference's formula (numpy's SIMD ufuncs); arctan2 of the halved arguments equals arctan2
    of the full ones exactly, since halving is exact.
    """
    axial, tm1, c18, ct1, md21, d22, d23, md13, d33 = fields
    np.arctan2(axial, tm1, out=out[0])  # rotation_angle
    np.arccos(c18, out=out[1])  # eq. (18)
    np.arccos(ct1, out=out[2])  # Table 1 metric
    np.arctan2(md21, d22, out=out[3])  # eq. (17)
    np.arcsin(d23, out=out[4])
    np.arctan2(md13, d33, out=out[5])


_EXPONENT = 0x7FF0000000000000
_MAGNITUDE = 0x7FFFFFFFFFFFFFFF
_INT_MAX = np.iinfo(np.int64).max
_INT_MIN = np.iinfo(np.int64).min


@nb.njit(cache=True, nogil=True, error_model="numpy", fastmath={"reassoc", "nsz"})
def accumulate(values, hist, stats, bins):  # pragma: no cover - compiled
    """Add per-trial metric values to streaming statistics (NaN = invalid, skipped).

    values : (m, n) float64; hist : (m, N_BINS) int64, in place; stats : (m, 5) float64 in
    place: count, mean, m2, min, max (sub-chunks merged by Chan's formula in a fixed order);
    bins : (n,) int64 scratch. Bins as :func:`montecarlo.aggregate.bin_index`.

    Written for the loop vectoriser: validity is tested on the exponent bits and min/max are
    taken on order-preserving integer keys of the bits with integer min/max (a float min/max
    that skips NaNs is not a reduction LLVM can vectorise). The sums are reassociated
    (vectorised): deterministic on one CPU type, and may differ in the last bits between CPU
    types, as numpy's own SIMD dispatch does.
    """
    m, n = values.shape
    bits = values.view(np.int64)
    for r in range(m):
        row = values[r]
        brow = bits[r]
        shift = 0.0  # a value near the data, for a one-pass sum of squared deviations
        for i in range(n):
            if row[i] == row[i]:
                shift = row[i]
                break
        cnt = 0
        s1 = 0.0
        s2 = 0.0
        kmin = _INT_MAX
        kmax = _INT_MIN
        for i in range(n):
            b = brow[i]
            valid = (b & _EXPONENT) != _EXPONENT  # finite
            d = row[i] - shift if valid else 0.0
            cnt += 1 if valid else 0
            s1 += d
            s2 += d * d
            key = b if b >= 0 else b ^ _MAGNITUDE  # integer order = float order
            kmin = min(kmin, key if valid else _INT_MAX)
            kmax = max(kmax, key if valid else _INT_MIN)
            k = ((b & _MAGNITUDE) >> _SHIFT) - _BASE
            kk = min(k, _N_MAG)
            idx = _ZERO if k < 0 else (_ZERO - 1 - kk if b < 0 else _ZERO + 1 + kk)
            bins[i] = idx if valid else -1
        hrow = hist[r]
        for i in range(n):
            if bins[i] >= 0:
                hrow[bins[i]] += 1
        if cnt == 0:
            continue
        lo = np.array([kmin if kmin >= 0 else kmin ^ _MAGNITUDE]).view(np.float64)[0]
        hi = np.array([kmax if kmax >= 0 else kmax ^ _MAGNITUDE]).view(np.float64)[0]
        mean = shift + s1 / cnt
        m2 = max(s2 - s1 * s1 / cnt, 0.0)
        n0 = stats[r, 0]
        if n0 == 0.0:
            stats[r, 1] = mean
            stats[r, 2] = m2
            stats[r, 0] = cnt
        else:
            tot = n0 + cnt
            delta = mean - stats[r, 1]
            stats[r, 1] += delta * cnt / tot
            stats[r, 2] += m2 + delta * delta * n0 * cnt / tot
            stats[r, 0] = tot
        stats[r, 3] = min(stats[r, 3], lo)
        stats[r, 4] = max(stats[r, 4], hi)


def new_stats(m: int) -> np.ndarray:
    """Empty accumulator rows for :func:`accumulate`."""
    s = np.zeros((m, 5))
    s[:, 3] = np.inf
    s[:, 4] = -np.inf
    return s
