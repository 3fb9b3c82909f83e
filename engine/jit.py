"""Compiled kernels (numba) for the per-step loops that numpy cannot batch well.

Most simulation code here is numpy: one call works on a whole array.  That stops paying when the arrays are
small (a 26 × 26 pool, a dozen outline points) or the work is irregular (neighbours from a cell list, a
polygon clipped against a grid): each numpy call costs about a microsecond however little it does, and a step
that needs hundreds of them is bound by call overhead, not arithmetic.  numba, the standard JIT compiler for
numeric Python, compiles such a function once, to machine code working on the same numpy arrays, so a loop over
cells or particles runs at C speed and with no temporaries.

:func:`kernel` is the one way the engine compiles a function, with the same settings everywhere:

- ``cache=True``: the machine code is written beside the module (``__pycache__``) and reused by later processes,
  so only the first run on a machine pays the compile (a fraction of a second for a small kernel, tens of seconds
  for the water's whole outline step or the smoke's MGPCG solve; about two minutes for all the effects'
  kernels).
- ``fastmath=False``: IEEE arithmetic in the order written.  LLVM then may not reassociate sums or fuse
  multiply-adds, so a kernel gives the same bits in every run and process, like numpy's ``+ - * /``.  Keep
  transcendental functions in float64, as everywhere (``docs/`` and the conventions explain why).
- ``error_model="numpy"``: division by zero gives inf/nan as in numpy instead of raising.
- ``nogil=True``: a kernel releases the GIL while it runs.

``NUMBA_DISABLE_JIT=1`` (numba's own switch) runs every kernel as plain Python, for a debugger or a traceback
with line numbers; results are the same, only slow.
"""

from __future__ import annotations

from typing import Any, Callable, TypeVar

import numba

F = TypeVar("F", bound=Callable[..., Any])

OPTIONS: dict[str, Any] = {"cache": True, "fastmath": False, "error_model": "numpy", "nogil": True}


def kernel(fn: F | None = None, **options: Any) -> Any:
    """Compile ``fn`` with the engine's settings (:data:`OPTIONS`); extra ``options`` go to ``numba.njit``.

    Use as ``@kernel`` or ``@kernel(inline="always")``.  The function must be numba-compatible: numpy arrays,
    scalars and tuples in, loops and ``np`` functions inside.  It compiles on its first call for each set of
    argument types.
    """
    settings = {**OPTIONS, **options}
    if fn is None:
        return lambda f: numba.njit(**settings)(f)
    return numba.njit(**settings)(fn)
