"""Small vector and matrix products that give the same bits on every CPU.

numpy's ``@`` / ``matmul``, ``dot``, ``linalg.norm`` of a whole vector and ``linalg.inv`` / ``solve`` hand their
work to BLAS and LAPACK (OpenBLAS in numpy's wheels). OpenBLAS picks its kernels by the CPU it runs on: on one
with FMA the products are fused into the sums, the sums are split over SIMD lanes differently, and the last bit
of a result changes. A simulation that rotates its bodies with ``R @ v`` then gives another state hash on
another machine (``OPENBLAS_CORETYPE=Sandybridge`` against ``Haswell`` on the same machine shows it), and a
recorded replay or a lockstep game no longer agrees.

Everything here is written with numpy's element-wise ``*`` and ``+`` (and plain Python floats), which round
each operation exactly as IEEE 754 says, with no fused multiply-add, and sums in the order written: index 0
first, then 1, 2, ... So the result is the same on every CPU, in every process. Element-wise ufuncs, reductions
along an axis (``np.add.reduce``) and ``np.einsum`` do not call BLAS and need none of this; use these functions
wherever a product of vectors or matrices decides simulation state (positions, contacts, which cells a ray
hits, what a pointer picks). Rendering, where a float's last bit never matters, may keep ``@``.

The arrays are small (3- and 4-vectors, 3 × 3 and 4 × 4 matrices, stacks of them); each function costs a few
numpy calls per summed index.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import ArrayLike, NDArray

__all__ = ["dot", "inverse", "length", "matmul", "matvec", "vecmat"]

F64 = NDArray[np.float64]


def dot(a: ArrayLike, b: ArrayLike) -> F64:
    """Σ_k a[..., k]·b[..., k] over the last axis (broadcasting the others), summed k = 0, 1, 2, ... A float
    for two vectors."""
    a, b = np.asarray(a, dtype=np.float64), np.asarray(b, dtype=np.float64)
    out = a[..., 0] * b[..., 0]
    for k in range(1, a.shape[-1]):
        out = out + a[..., k] * b[..., k]
    return out


def length(v: ArrayLike) -> F64:
    """√(v·v) over the last axis: what ``np.linalg.norm(v, axis=-1)`` computes for real vectors."""
    return np.sqrt(dot(v, v))


def matvec(m: ArrayLike, v: ArrayLike) -> F64:
    """m·v for matrices (..., r, k) and vectors (..., k) → (..., r)."""
    m, v = np.asarray(m, dtype=np.float64), np.asarray(v, dtype=np.float64)
    return dot(m, v[..., None, :])


def vecmat(v: ArrayLike, m: ArrayLike) -> F64:
    """vᵀ·m (= mᵀ·v) for vectors (..., k) and matrices (..., k, c) → (..., c)."""
    v, m = np.asarray(v, dtype=np.float64), np.asarray(m, dtype=np.float64)
    out = v[..., 0, None] * m[..., 0, :]
    for k in range(1, m.shape[-2]):
        out = out + v[..., k, None] * m[..., k, :]
    return out


def matmul(a: ArrayLike, b: ArrayLike) -> F64:
    """a·b for matrices (..., r, k) and (..., k, c) → (..., r, c), the leading axes broadcast as in ``@``."""
    a, b = np.asarray(a, dtype=np.float64), np.asarray(b, dtype=np.float64)
    if a.shape[-1] != b.shape[-2]:
        raise ValueError(f"matmul: shapes {a.shape} and {b.shape} do not chain")
    out = a[..., :, 0, None] * b[..., None, 0, :]
    for k in range(1, a.shape[-1]):
        out = out + a[..., :, k, None] * b[..., None, k, :]
    return out


def inverse(m: ArrayLike) -> F64:
    """The inverse of one small square matrix (a camera's 4 × 4 projection·view), by Gauss–Jordan elimination
    with partial pivoting in Python floats. Raises ``np.linalg.LinAlgError`` for a singular matrix, as
    ``np.linalg.inv`` does."""
    a = np.asarray(m, dtype=np.float64)
    n = a.shape[0]
    if a.shape != (n, n):
        raise ValueError(f"inverse: a square matrix is needed, got shape {a.shape}")
    rows = [list(map(float, row)) + [1.0 if i == j else 0.0 for j in range(n)] for i, row in enumerate(a)]
    for col in range(n):
        pivot = max(range(col, n), key=lambda r: abs(rows[r][col]))  # first of equal magnitudes
        if rows[pivot][col] == 0.0 or not math.isfinite(rows[pivot][col]):
            raise np.linalg.LinAlgError("Singular matrix")
        rows[col], rows[pivot] = rows[pivot], rows[col]
        p = rows[col][col]
        rows[col] = [x / p for x in rows[col]]
        for r in range(n):
            f = rows[r][col]
            if r != col and f != 0.0:
                rows[r] = [x - f * y for x, y in zip(rows[r], rows[col])]
    return np.array([row[n:] for row in rows])
