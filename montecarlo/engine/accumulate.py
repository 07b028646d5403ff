"""Fused reduction of per-trial metric rows into the streaming statistics of :mod:`.aggregate`.

A numba loop for systems with a fast kernel (see :meth:`.aggregate.PointStats.add_block_summary`):
count, mean, sum of squared deviations, min, max and the histogram of each metric row in one
pass over the values, with the bins of :func:`.aggregate.bin_index`. Imported only where
kernels run, so that numba stays out of processes that only aggregate.
"""

from __future__ import annotations

import numba as nb
import numpy as np

from montecarlo.engine.aggregate import BIN_BASE, BIN_SHIFT, N_MAG, ZERO_BIN
from montecarlo.jit import cached

_EXPONENT = 0x7FF0000000000000
_MAGNITUDE = 0x7FFFFFFFFFFFFFFF
_INT_MAX = np.iinfo(np.int64).max
_INT_MIN = np.iinfo(np.int64).min


@nb.njit(cache=True, nogil=True, error_model="numpy", fastmath={"reassoc", "nsz"})
def accumulate(values, rows, hist, stats, bins, piece):  # pragma: no cover - compiled
    """Add per-trial metric values to streaming statistics (NaN = invalid, skipped).

    values : (k, n) float64, of which ``rows`` (m,) are the metrics, in this order;
    hist : (m, N_BINS) int64, in place; stats : (m, 5) float64 in
    place: count, mean, m2, min, max; piece : int, the values are reduced ``piece`` columns
    at a time, each piece's moments merged into ``stats`` by Chan's formula, row after row and
    piece after piece within a row (so the result depends on ``piece``, never on how many
    columns one call is given); bins : (piece,) int32 scratch for the bin indices (as
    :func:`.aggregate.bin_index`).

    Written for the loop vectoriser: validity is tested on the exponent bits and min/max are
    taken on order-preserving integer keys of the bits with integer min/max (a float min/max
    that skips NaNs is not a reduction LLVM can vectorise). The sums are reassociated
    (vectorised): deterministic on one CPU type, and may differ in the last bits between CPU
    types, as numpy's own SIMD dispatch does.
    """
    n = values.shape[1]
    bits = values.view(np.int64)
    # Row after row, and piece after piece within a row: each row's statistics are merged in
    # piece order as before (the rows are independent), while the histogram row the
    # increments scatter into (~1 MB) stays in the L2 cache for all the pieces of the call.
    for r in range(rows.shape[0]):
        for start in range(0, n, piece):
            _accumulate_piece(values[rows[r]], bits[rows[r]], hist[r], stats[r], bins, start,
                              min(start + piece, n))


@nb.njit(cache=True, nogil=True, error_model="numpy", fastmath={"reassoc", "nsz"})
def _accumulate_piece(values, bits, hrow, stats, bins, start, stop
                      ):  # pragma: no cover - compiled
    """:func:`accumulate` of the columns ``start:stop`` of one metric row (``values``,
    ``bits`` (n,), its histogram ``hrow`` and statistics ``stats`` (5,))."""
    row = values[start:stop]
    brow = bits[start:stop]
    shift = 0.0  # a value near the data, for a one-pass sum of squared deviations
    for i in range(stop - start):
        if row[i] == row[i]:
            shift = row[i]
            break
    cnt = 0
    s1 = 0.0
    s2 = 0.0
    kmin = _INT_MAX
    kmax = _INT_MIN
    for i in range(stop - start):
        b = brow[i]
        valid = (b & _EXPONENT) != _EXPONENT  # finite
        d = row[i] - shift if valid else 0.0
        cnt += 1 if valid else 0
        s1 += d
        s2 += d * d
        key = b if b >= 0 else b ^ _MAGNITUDE  # integer order = float order
        kmin = min(kmin, key if valid else _INT_MAX)
        kmax = max(kmax, key if valid else _INT_MIN)
        k = ((b & _MAGNITUDE) >> BIN_SHIFT) - BIN_BASE
        kk = min(k, N_MAG)
        idx = ZERO_BIN if k < 0 else (ZERO_BIN - 1 - kk if b < 0 else ZERO_BIN + 1 + kk)
        bins[i] = idx if valid else -1
    for i in range(stop - start):
        if bins[i] >= 0:
            hrow[bins[i]] += 1
    if cnt == 0:
        return
    lo = np.array([kmin if kmin >= 0 else kmin ^ _MAGNITUDE]).view(np.float64)[0]
    hi = np.array([kmax if kmax >= 0 else kmax ^ _MAGNITUDE]).view(np.float64)[0]
    mean = shift + s1 / cnt
    m2 = max(s2 - s1 * s1 / cnt, 0.0)
    n0 = stats[0]
    if n0 == 0.0:
        stats[1] = mean
        stats[2] = m2
        stats[0] = cnt
    else:
        tot = n0 + cnt
        delta = mean - stats[1]
        stats[1] += delta * cnt / tot
        stats[2] += m2 + delta * delta * n0 * cnt / tot
        stats[0] = tot
    stats[3] = min(stats[3], lo)
    stats[4] = max(stats[4], hi)


def new_stats(m: int) -> np.ndarray:
    """Empty accumulator rows for :func:`accumulate`."""
    s = np.zeros((m, 5))
    s[:, 3] = np.inf
    s[:, 4] = -np.inf
    return s


def is_cached() -> bool:
    """True if numba's cache holds :func:`accumulate` (else its first use compiles)."""
    return cached(accumulate)
