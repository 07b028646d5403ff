"""Helpers around numba's compiled kernels: whether the on-disk cache already holds one (so
that a compile can be announced), and one compiled specialization per kernel."""

from __future__ import annotations

import functools
from collections.abc import Callable
from typing import Any

import numpy as np


def cached(dispatcher: Any) -> bool:
    """True if ``dispatcher`` (an ``@njit(cache=True)`` function) has a valid cache entry.

    A missing or stale index (the source changed since) means the first call compiles. numba
    has no public API for this; if its internals change, the answer is True (no announcement).
    """
    try:
        return bool(dispatcher._cache._cache_file._load_index())
    except Exception:
        return True


def one_layout(kernel: Callable[..., Any]) -> Callable[..., Any]:
    """``kernel`` (an ``@njit`` function called from Python) with every array argument made
    C-contiguous and writable first (a copy only where it is not).

    numba compiles one specialization per array layout and per read-only flag: views from
    ``np.broadcast_to`` or frozen data are read-only, slices are not contiguous, and each
    combination was a compile of its own (seconds each on the first run of a fresh install).
    """
    @functools.wraps(kernel)
    def call(*args: Any) -> Any:
        return kernel(*(np.require(a, requirements=("C", "W")) if isinstance(a, np.ndarray)
                        else a for a in args))

    return call
