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

The elementary functions here (:func:`exp`, :func:`cbrt`, :func:`atan`, :func:`atan2`, :func:`asin`) exist for
the same reason. numpy computes ``np.exp``, ``np.log``, ``np.power``, ``np.cbrt``, ``np.arctan2``, ``np.arccos``
and others with SIMD code chosen by the CPU: on a CPU with AVX-512 (numpy's ``AVX512_SKX`` dispatch) float64
``exp``, ``cbrt`` and ``arctan2`` give other last bits than on an AVX2 or older one, and the demo's state hash
after its autoplay differed (``NPY_DISABLE_CPU_FEATURES`` shows it on one machine). Python's ``math`` and numba's
calls go to the C library, which differs between systems. These are written with ``+ - * /`` (no fused
multiply-adds: the kernels compile without fast-math), ``frexp``/``ldexp`` and comparisons only, so they give the
same bits everywhere: fdlibm's algorithms (Sun's freely distributable libm, the reference of Java's
``StrictMath``), within one unit in the last place of the true value. Each is a compiled scalar function that
other kernels call, and takes a number or an array. ``np.sin``, ``np.cos``, ``np.sqrt``, ``np.tanh`` and
``np.hypot`` gave the same bits with and without AVX-512 and are used directly.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import ArrayLike, NDArray

from engine.jit import kernel

__all__ = ["asin", "atan", "atan2", "cbrt", "dot", "exp", "inverse", "length", "matmul", "matvec", "vecmat"]

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


# ------------------------------------------------------------------------------------- elementary functions
# Constants of fdlibm (e_exp.c, s_atan.c, e_atan2.c); each is the double nearest the value named.
_LN2_HI = 6.93147180369123816490e-01  # ln 2's leading 32 bits: k · _LN2_HI is exact for |k| < 2^20
_LN2_LO = 1.90821492927058770002e-10  # ln 2 − _LN2_HI
_INV_LN2 = 1.44269504088896338700e+00
_EXP_OVER = 7.09782712893383973096e+02  # above: exp overflows
_EXP_UNDER = -7.45133219101941108420e+02  # below: exp is 0
_P1, _P2, _P3 = 1.66666666666666019037e-01, -2.77777777770155933842e-03, 6.61375632143793436117e-05
_P4, _P5 = -1.65339022054652515390e-06, 4.13813679705723846039e-08
_ATAN_HI = (4.63647609000806093515e-01, 7.85398163397448278999e-01, 9.82793723247329054082e-01,
            1.57079632679489655800e+00)  # atan(0.5), atan(1), atan(1.5), atan(inf): leading parts
_ATAN_LO = (2.26987774529616870924e-17, 3.06161699786838301793e-17, 1.39033110312309984516e-17,
            6.12323399573676603587e-17)
_AT0, _AT1, _AT2, _AT3 = (3.33333333333329318027e-01, -1.99999999998764832476e-01, 1.42857142725034663711e-01,
                          -1.11111104054623557880e-01)
_AT4, _AT5, _AT6, _AT7 = (9.09088713343650656196e-02, -7.69187620504482999495e-02, 6.66107313738753120669e-02,
                          -5.83357013379057348645e-02)
_AT8, _AT9, _AT10 = 4.97687799461593236017e-02, -3.65315727442169155270e-02, 1.62858201153657823623e-02
_PI = 3.1415926535897931160e+00
_PI_LO = 1.2246467991473531772e-16  # π − _PI
_PI_2 = 1.5707963267948965580e+00
_PI_4 = 7.8539816339744827900e-01


@kernel
def exp_scalar(x: float) -> float:
    """e^x (fdlibm's e_exp): x = k·ln 2 + r with |r| ≤ ln 2 / 2, e^r from a rational form of a degree-5
    polynomial in r², then 2^k exactly."""
    if x != x:
        return x
    if x > _EXP_OVER:
        return math.inf
    if x < _EXP_UNDER:
        return 0.0
    if abs(x) < 3.725290298461914e-09:  # 2^-28: e^x rounds to 1 + x
        return 1.0 + x
    k = math.floor(x * _INV_LN2 + 0.5)
    hi = x - k * _LN2_HI
    lo = k * _LN2_LO
    r = hi - lo
    t = r * r
    c = r - t * (_P1 + t * (_P2 + t * (_P3 + t * (_P4 + t * _P5))))
    y = 1.0 - ((lo - (r * c) / (2.0 - c)) - hi)
    return math.ldexp(y, k)


@kernel
def cbrt_scalar(x: float) -> float:
    """The real cube root: x = m·2^(3j) with m in [1/2, 4); m^(1/3) by Halley's iteration from a linear guess
    (cubic convergence: three steps reach about 50 bits), cut to 26 bits (Veltkamp's split) so that its square
    is exact, then fdlibm's last Newton step for the cube root (s_cbrt.c)."""
    if x == 0.0 or x != x or math.isinf(x):
        return x
    m, e = math.frexp(abs(x))
    r = e % 3
    m = math.ldexp(m, r)
    t = 0.6 + 0.26 * m
    for _ in range(3):
        t3 = t * t * t
        t = t * (t3 + 2.0 * m) / (2.0 * t3 + m)
    c = t * 134217729.0  # 2^27 + 1
    t = c - (c - t)
    s = t * t
    q = m / s
    q = (q - t) / (t + t + q)
    t = t + t * q
    y = math.ldexp(t, (e - r) // 3)
    return -y if x < 0.0 else y


@kernel
def atan_scalar(x: float) -> float:
    """atan x (fdlibm's s_atan): |x| reduced to one of five intervals around 0, 0.5, 1, 1.5 and ∞, then an
    odd polynomial of degree 23 split in two halves."""
    if x != x:
        return x
    a = abs(x)
    if a >= 7.378697629483821e+19:  # 2^66: π/2
        z = _ATAN_HI[3] + _ATAN_LO[3]
        return -z if x < 0.0 else z
    if a < 0.4375:
        if a < 7.450580596923828e-09:  # 2^-27: atan x rounds to x
            return x
        i = -1
        v = x
    elif a < 0.6875:
        i = 0
        v = (2.0 * a - 1.0) / (2.0 + a)
    elif a < 1.1875:
        i = 1
        v = (a - 1.0) / (a + 1.0)
    elif a < 2.4375:
        i = 2
        v = (a - 1.5) / (1.0 + 1.5 * a)
    else:
        i = 3
        v = -1.0 / a
    z = v * v
    w = z * z
    s1 = z * (_AT0 + w * (_AT2 + w * (_AT4 + w * (_AT6 + w * (_AT8 + w * _AT10)))))
    s2 = w * (_AT1 + w * (_AT3 + w * (_AT5 + w * (_AT7 + w * _AT9))))
    if i < 0:
        return v - v * (s1 + s2)
    z = _ATAN_HI[i] - ((v * (s1 + s2) - _ATAN_LO[i]) - v)
    return -z if x < 0.0 else z


@kernel
def atan2_scalar(y: float, x: float) -> float:
    """The angle of (x, y) in [−π, π] (fdlibm's e_atan2), signed zeros and infinities as C's ``atan2``."""
    if x != x or y != y:
        return x + y
    if x == 1.0:
        return atan_scalar(y)
    m = (2 if math.copysign(1.0, x) < 0.0 else 0) + (1 if math.copysign(1.0, y) < 0.0 else 0)
    if y == 0.0:
        if m < 2:
            return y
        return _PI if m == 2 else -_PI
    if x == 0.0:
        return -_PI_2 if m & 1 else _PI_2
    if math.isinf(x):
        if math.isinf(y):
            z = 3.0 * _PI_4 if m >= 2 else _PI_4
        else:
            z = _PI if m >= 2 else 0.0
        return -z if m & 1 else z
    if math.isinf(y):
        return -_PI_2 if m & 1 else _PI_2
    k = math.frexp(y)[1] - math.frexp(x)[1]
    if k > 60:  # |y/x| > 2^60: π/2
        z = _PI_2 + 0.5 * _PI_LO
        m &= 1
    elif x < 0.0 and k < -60:  # |y/x| < 2^-60 on the negative side: ±π
        z = 0.0
    else:
        z = atan_scalar(abs(y / x))
    if m == 0:
        return z
    if m == 1:
        return -z
    if m == 2:
        return _PI - (z - _PI_LO)
    return (z - _PI_LO) - _PI


@kernel
def asin_scalar(x: float) -> float:
    """asin x = atan2(x, √((1 − x)(1 + x))); NaN outside [−1, 1]. Within two units in the last place."""
    if not abs(x) <= 1.0:
        return math.nan
    return atan2_scalar(x, math.sqrt((1.0 - x) * (1.0 + x)))


@kernel
def _exp_array(x, out):
    for i in range(x.size):
        out[i] = exp_scalar(x[i])


@kernel
def _cbrt_array(x, out):
    for i in range(x.size):
        out[i] = cbrt_scalar(x[i])


@kernel
def _atan_array(x, out):
    for i in range(x.size):
        out[i] = atan_scalar(x[i])


@kernel
def _asin_array(x, out):
    for i in range(x.size):
        out[i] = asin_scalar(x[i])


@kernel
def _atan2_array(y, x, out):
    for i in range(y.size):
        out[i] = atan2_scalar(y[i], x[i])


def _unary(scalar, array, x):
    if np.ndim(x) == 0 and not isinstance(x, np.ndarray):
        return float(scalar(float(x)))
    a = np.asarray(x, dtype=np.float64)
    flat = np.ascontiguousarray(a).reshape(-1)
    out = np.empty_like(flat)
    array(flat, out)
    return out.reshape(a.shape)


def exp(x: ArrayLike) -> F64:
    """e^x with the same bits on every machine (a float for a number, an array of x's shape for an array)."""
    return _unary(exp_scalar, _exp_array, x)


def cbrt(x: ArrayLike) -> F64:
    """The real cube root with the same bits on every machine."""
    return _unary(cbrt_scalar, _cbrt_array, x)


def atan(x: ArrayLike) -> F64:
    """atan x with the same bits on every machine."""
    return _unary(atan_scalar, _atan_array, x)


def asin(x: ArrayLike) -> F64:
    """asin x with the same bits on every machine (NaN outside [−1, 1])."""
    return _unary(asin_scalar, _asin_array, x)


def atan2(y: ArrayLike, x: ArrayLike) -> F64:
    """The angle of (x, y), as ``np.arctan2(y, x)``, with the same bits on every machine; y and x broadcast."""
    if np.ndim(y) == 0 and np.ndim(x) == 0 and not isinstance(y, np.ndarray) and not isinstance(x, np.ndarray):
        return float(atan2_scalar(float(y), float(x)))
    b = np.broadcast_arrays(np.asarray(y, dtype=np.float64), np.asarray(x, dtype=np.float64))
    ys, xs = (np.ascontiguousarray(a).reshape(-1) for a in b)
    out = np.empty_like(ys)
    _atan2_array(ys, xs, out)
    return out.reshape(b[0].shape)
