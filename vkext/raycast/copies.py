"""Host copies of a cast's rays and hits, split among threads (numpy copies release the GIL):
:func:`parallel_copy` converts while it copies and can scan one job for NaN as it lands."""

from __future__ import annotations

import os
import threading
from concurrent.futures import ThreadPoolExecutor
from typing import Any

import numpy as np

# host copies of a cast are split among threads (numpy copies release the GIL): one core
# cannot fill a wide memory bus, and first touches of fresh output pages fault in parallel
COPY_THREADS = min(8, os.cpu_count() or 1)
COPY_SPLIT = 1 << 18  # bytes: the least a part gets; jobs smaller in all stay on this thread
_copy_pool: ThreadPoolExecutor | None = None


def parallel_copy(jobs: list[tuple[np.ndarray, np.ndarray]], *, cached: bool = True,
                  check: int | None = None) -> bool:
    """``dst[...] = src`` for every (dst, src) pair of arrays of one shape (any layout and
    real dtype: a source is converted while it is copied). Jobs of at least two
    :data:`COPY_SPLIT` in all are cut along their first axis into parts of at least that
    (up to ``2 * COPY_THREADS`` a job), which this thread and up to ``COPY_THREADS - 1``
    threads of a pool take one at a time until none is left: a thread that wakes late
    (a busy or virtual host) then copies less instead of holding everyone up, and this
    thread waits only for parts already taken. Without ``cached`` the destinations are
    written in order only (they may be write-combined memory).

    ``check`` names the job (its index) whose destination is scanned for NaN part by part
    as it lands, while in cache; returns whether it has any (False without ``check``)."""
    global _copy_pool
    copy = _copy if cached else _copy_in_order
    total = sum(dst.nbytes for dst, _ in jobs)
    if COPY_THREADS < 2 or total < 2 * COPY_SPLIT:
        parts = [(dst, src, i == check) for i, (dst, src) in enumerate(jobs)]
        return _copy_parts(copy, parts)
    parts = []
    for i, (dst, src) in enumerate(jobs):  # small streams too: they copy beside the large
        n = len(dst)
        pieces = max(1, min(2 * COPY_THREADS, dst.nbytes // COPY_SPLIT, n))
        parts += [(dst[a:b], src[a:b], i == check) for a, b in
                  ((n * k // pieces, n * (k + 1) // pieces) for k in range(pieces))]
    parts.sort(key=lambda p: -p[0].nbytes)  # the largest first: the last parts are short
    if _copy_pool is None:
        _copy_pool = ThreadPoolExecutor(COPY_THREADS - 1,
                                        thread_name_prefix="vkext-raycast-copy")
    shared = _SharedParts(copy, parts)
    for _ in range(min(COPY_THREADS - 1, len(parts) - 1)):
        _copy_pool.submit(shared.run)
    shared.run()
    return shared.wait()


class _SharedParts:
    """Parts that threads take one at a time (``next`` on a list's iterator holds the GIL,
    so each part goes to one thread); :meth:`wait` returns once every part is copied."""

    def __init__(self, copy: Any, parts: list[tuple[np.ndarray, np.ndarray, bool]]):
        self.copy, self.parts, self.left = copy, iter(parts), len(parts)
        self.lock, self.done = threading.Lock(), threading.Event()
        self.nan, self.error = False, None

    def run(self) -> None:
        for part in self.parts:
            nan, error = False, None
            try:
                nan = _copy_parts(self.copy, [part])
            except BaseException as e:  # handed to the waiting thread
                error = e
            with self.lock:
                self.nan |= nan
                self.error = self.error or error
                self.left -= 1
                if self.left == 0:
                    self.done.set()

    def wait(self) -> bool:
        self.done.wait()
        if self.error is not None:
            raise self.error
        return self.nan


def _copy_parts(copy: Any, parts: list[tuple[np.ndarray, np.ndarray, bool]]) -> bool:
    nan = False
    for dst, src, checked in parts:
        copy(dst, src)
        # min() propagates NaN: one pass over the part while it is in cache
        nan = nan or bool(checked and len(dst) and np.isnan(dst.min()))
    return nan


def _copy(dst: np.ndarray, src: np.ndarray) -> None:
    if src.ndim == 2 and 0 < src.strides[0] < src.strides[1]:
        # column-major rows (a transpose's): column by column reads each one in order,
        # about twice as fast as numpy's element order for (N, 3)
        for j in range(src.shape[1]):
            np.copyto(dst[:, j], src[:, j], casting="unsafe")
        return
    _copy_in_order(dst, src)


def _copy_in_order(dst: np.ndarray, src: np.ndarray) -> None:
    # unsafe: float64 and integer rays round to float32 as astype would
    np.copyto(dst, src, casting="unsafe")
