"""Compiled kernels (numba) for the per-step loops that numpy cannot batch well.

Most simulation code here is numpy: one call works on a whole array.  That stops paying when the arrays are
small (a 26 × 26 pool, a dozen outline points) or the work is irregular (neighbours from a cell list, a
polygon clipped against a grid): each numpy call costs about a microsecond however little it does, and a step
that needs hundreds of them is bound by call overhead, not arithmetic.  numba, the standard JIT compiler for
numeric Python, compiles such a function once, to machine code working on the same numpy arrays, so a loop over
cells or particles runs at C speed and with no temporaries.

:func:`kernel` is the one way the engine compiles a function, with the same settings everywhere:

- ``cache=True``: the machine code is written beside the module (``__pycache__``) and reused by later processes,
  so only the first run on a machine pays the compile (a fraction of a second for a small kernel, up to about
  eight seconds for the largest, the height-field ray march and the water's outline step; about two and a half
  minutes of one core for all the effects' kernels).
- ``fastmath=False``: IEEE arithmetic in the order written.  LLVM then may not reassociate sums or fuse
  multiply-adds, so a kernel gives the same bits in every run and process, like numpy's ``+ - * /``.  Keep
  transcendental functions in float64, as everywhere (``docs/`` and the conventions explain why).
- ``error_model="numpy"``: division by zero gives inf/nan as in numpy instead of raising.
- ``nogil=True``: a kernel releases the GIL while it runs.

The cache is read and written under a lock file (:class:`LockedCache`), so several processes may compile at once:
``python -m engine warm`` (``make test`` and ``make demo`` run it) compiles every kernel the scenes use on all
cores, before the first run needs them.

``NUMBA_DISABLE_JIT=1`` (numba's own switch) runs every kernel as plain Python, for a debugger or a traceback
with line numbers; results are the same, only slow.
"""

from __future__ import annotations

import contextlib
import os
from typing import Any, Callable, Iterator, TypeVar

import numba
import numpy as np
from numba.core.caching import FunctionCache

try:
    import fcntl
except ImportError:  # Windows: no advisory locks; `python -m engine warm` then compiles in one process
    fcntl = None

F = TypeVar("F", bound=Callable[..., Any])

OPTIONS: dict[str, Any] = {"cache": True, "fastmath": False, "error_model": "numpy", "nogil": True}

LOCK_NAME = ".ecsfx-kernels.lock"
CAN_LOCK = fcntl is not None


def kernel(fn: F | None = None, **options: Any) -> Any:
    """Compile ``fn`` with the engine's settings (:data:`OPTIONS`); extra ``options`` go to ``numba.njit``.

    Use as ``@kernel`` or ``@kernel(inline="always")``.  The function must be numba-compatible: numpy arrays,
    scalars and tuples in, loops and ``np`` functions inside.  It compiles on its first call for each set of
    argument types.
    """
    settings = {**OPTIONS, **options}
    if fn is None:
        return lambda f: _compile(f, settings)
    return _compile(fn, settings)


def _compile(fn: Callable[..., Any], settings: dict[str, Any]) -> Any:
    dispatcher = numba.njit(**settings)(fn)
    if settings.get("cache") and type(getattr(dispatcher, "_cache", None)) is FunctionCache:
        dispatcher._cache = LockedCache(dispatcher.py_func)
    return dispatcher


class LockedCache(FunctionCache):
    """numba's per-function disk cache, read and written under a lock file in its folder.

    numba saves a new overload by reading the function's index, adding the entry and writing the index and a data
    file numbered after the entries it saw.  Two processes compiling different signatures of one function at the
    same time (a helper such as :func:`pairwise_sum`, compiled for each caller's argument types) would both take
    number 1: the index of one would then point at the other's machine code.  Saving under an exclusive lock and
    loading under a shared one makes the read-modify-write whole, so kernels may compile in several processes at
    once (``python -m engine warm``, two test runs, a demo beside a test).  Without ``fcntl`` (Windows) nothing is
    locked, as in numba itself.
    """

    def load_overload(self, sig: Any, target_context: Any) -> Any:
        if not os.path.isdir(self.cache_path):  # nothing saved yet: nothing to lock
            return super().load_overload(sig, target_context)
        with _locked(self.cache_path, shared=True):
            return super().load_overload(sig, target_context)

    def save_overload(self, sig: Any, data: Any) -> None:
        self._impl.locator.ensure_cache_path()
        with _locked(self.cache_path, shared=False):
            super().save_overload(sig, data)


@contextlib.contextmanager
def _locked(folder: str, shared: bool) -> Iterator[None]:
    if fcntl is None:
        yield
        return
    try:
        fd = os.open(os.path.join(folder, LOCK_NAME), os.O_RDWR | os.O_CREAT, 0o666)
    except OSError:  # a read-only cache folder: numba itself then only loads
        yield
        return
    try:
        fcntl.flock(fd, fcntl.LOCK_SH if shared else fcntl.LOCK_EX)
        yield
    finally:
        os.close(fd)  # closing the descriptor releases the lock


# ----------------------------------------------------------------------------------- numpy's element rules
# Kernels that repeat numpy's element-wise and reduction semantics bit for bit (the effects' kernels share them).


@kernel(inline="always")
def maximum(a: float, b: float) -> float:
    """np.maximum(a, b) of two floats: NaN propagates; of equal values (0.0 and −0.0) the second."""
    return a if (a > b or a != a) else b


@kernel(inline="always")
def minimum(a: float, b: float) -> float:
    """np.minimum(a, b) of two floats: NaN propagates; of equal values (0.0 and −0.0) the second."""
    return a if (a < b or a != a) else b


# --------------------------------------------------------------------------------------------- summation


@kernel
def _block_sum(a, start, n):
    """numpy's pairwise summation of up to 128 values: one by one below 8, else 8 accumulators."""
    if n < 8:
        res = 0.0
        for i in range(n):
            res += a[start + i]
        return res
    r0, r1, r2, r3 = a[start], a[start + 1], a[start + 2], a[start + 3]
    r4, r5, r6, r7 = a[start + 4], a[start + 5], a[start + 6], a[start + 7]
    i = 8
    stop = n - n % 8
    while i < stop:
        j = start + i
        r0 += a[j]
        r1 += a[j + 1]
        r2 += a[j + 2]
        r3 += a[j + 3]
        r4 += a[j + 4]
        r5 += a[j + 5]
        r6 += a[j + 6]
        r7 += a[j + 7]
        i += 8
    res = ((r0 + r1) + (r2 + r3)) + ((r4 + r5) + (r6 + r7))
    while i < n:
        res += a[start + i]
        i += 1
    return res


@kernel
def pairwise_sum(a, start, n):
    """numpy's pairwise summation of ``a[start:start + n]`` (float64, contiguous): blocks of up to 128 summed
    with 8 accumulators, longer runs split in two at a multiple of 8 (left + right). ``np.add.reduce`` of a
    contiguous array is ``0.0 + pairwise_sum``. The recursion runs on an explicit stack (numba's cache does not
    keep recursive functions)."""
    if n <= 128:
        return _block_sum(a, start, n)
    starts = np.empty(64, np.int64)
    sizes = np.empty(64, np.int64)
    stage = np.empty(64, np.int64)
    left = np.empty(64)
    top = 0
    starts[0], sizes[0], stage[0] = start, n, 0
    ret = 0.0
    have = False
    while True:
        if have:  # a finished child: the left half waits for the right one, the right one completes the sum
            if top < 0:
                return ret
            if stage[top] == 1:
                left[top] = ret
                stage[top] = 2
                half = sizes[top] // 2
                half -= half % 8
                top += 1
                starts[top], sizes[top], stage[top] = starts[top - 1] + half, sizes[top - 1] - half, 0
                have = False
            else:
                ret = left[top] + ret
                top -= 1
            continue
        if sizes[top] <= 128:
            ret = _block_sum(a, starts[top], sizes[top])
            top -= 1
            have = True
            continue
        half = sizes[top] // 2
        half -= half % 8
        stage[top] = 1
        top += 1
        starts[top], sizes[top], stage[top] = starts[top - 1], half, 0
