"""Whether numba's on-disk cache already holds a kernel, so that a compile can be announced."""

from __future__ import annotations

from typing import Any


def cached(dispatcher: Any) -> bool:
    """True if ``dispatcher`` (an ``@njit(cache=True)`` function) has a valid cache entry.

    A missing or stale index (the source changed since) means the first call compiles. numba
    has no public API for this; if its internals change, the answer is True (no announcement).
    """
    try:
        return bool(dispatcher._cache._cache_file._load_index())
    except Exception:
        return True
