"""Native thread pools of the engine process: BLAS runs on one thread.

numpy's BLAS (OpenBLAS in the wheels) starts one thread per core and uses them for every matrix product and
LAPACK call, however small.  The engine's arrays are many and small (a 64 × 64 pseudo-inverse, 3 × 3 inertia
tensors, (N, 3) @ (3, 3) transforms), where the threads only add hand-offs, and in a rendering process they
compete with the software rasteriser's threads for the same cores.  On this project's 2-core machines under
load, one thread made a 64 × 64 ``pinv`` 1 ms instead of 140 ms and a 300² matrix product 2.6 ms instead of
34 ms.  So the engine limits BLAS to one thread when the first :class:`~engine.app.App` starts, through
threadpoolctl (the standard tool for this, used by scikit-learn and joblib).

``ECSFX_BLAS_THREADS`` overrides it: a positive number sets the thread count, ``auto`` leaves BLAS alone.
"""

from __future__ import annotations

import contextlib

import logging
import os

log = logging.getLogger(__name__)

ENV = "ECSFX_BLAS_THREADS"
_applied: list = []  # the threadpoolctl limiter, kept alive for the process


def blas_thread_setting() -> int | None:
    """Threads wanted for BLAS: ``ECSFX_BLAS_THREADS`` (default 1); None for ``auto``."""
    value = os.environ.get(ENV, "1").strip().lower()
    if value in ("auto", ""):
        return None
    try:
        threads = int(value)
    except ValueError:
        threads = 0
    if threads < 1:
        log.warning("%s=%r is not a positive number or 'auto'; using 1", ENV, value)
        return 1
    return threads


def limit_blas_threads() -> None:
    """Apply :func:`blas_thread_setting` once per process (later calls do nothing)."""
    if _applied:
        return
    threads = blas_thread_setting()
    if threads is None:
        _applied.append(None)
        return
    from threadpoolctl import threadpool_limits

    # threadpoolctl limits the libraries loaded so far. numba's first call of any compiled kernel loads scipy's
    # own OpenBLAS (for np.linalg inside kernels), which would then start with a thread per core: load it first.
    with contextlib.suppress(ImportError):
        import scipy.linalg.cython_blas  # noqa: F401
    _applied.append(threadpool_limits(limits=threads, user_api="blas"))
