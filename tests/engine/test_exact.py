"""engine.exact: the products agree with numpy's to rounding, sum in the documented order, and a whole game gives
the same state hash whichever BLAS kernels numpy's OpenBLAS picks for the CPU; the elementary functions are within
an ulp (sin, cos and tan for every magnitude up to the largest double; hypot from subnormals to overflow), give the
same bits compiled and interpreted, and keep the demo's hash whatever SIMD code numpy picks."""

from __future__ import annotations

import math
import os
import platform
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from engine import exact
from engine.exact import dot, inverse, length, matmul, matvec, vecmat

ROOT = Path(__file__).resolve().parents[2]


def test_products_match_numpy_to_rounding_with_broadcasting():
    rng = np.random.default_rng(1)
    a, b = rng.standard_normal((5, 3, 4)), rng.standard_normal((5, 4, 2))
    v, w = rng.standard_normal((5, 4)), rng.standard_normal((5, 3))
    np.testing.assert_allclose(matmul(a, b), a @ b, rtol=1e-13, atol=1e-14)
    np.testing.assert_allclose(matmul(a[0], b), a[0] @ b, rtol=1e-13, atol=1e-14)  # broadcast the leading axis
    np.testing.assert_allclose(matvec(a, v), (a @ v[:, :, None])[:, :, 0], rtol=1e-13, atol=1e-14)
    np.testing.assert_allclose(vecmat(w, a), (w[:, None, :] @ a)[:, 0, :], rtol=1e-13, atol=1e-14)
    np.testing.assert_allclose(dot(v, v), np.sum(v * v, axis=1), rtol=1e-13)
    np.testing.assert_allclose(length(w), np.linalg.norm(w, axis=1), rtol=1e-13)
    assert isinstance(float(dot([1.0, 2.0, 3.0], [4.0, 5.0, 6.0])), float)
    with pytest.raises(ValueError, match="do not chain"):
        matmul(a, a)


def test_sums_run_left_to_right_without_fused_multiply_adds():
    """(1e16 + 1) − 1e16 is 0 when summed in order, 1 or 2 in other orders; a fused a·b + c keeps a product's
    low bits that the separately rounded product loses."""
    assert float(dot([1e16, 1.0, -1e16], [1.0, 1.0, 1.0])) == 0.0
    assert float(matvec([[1e16, 1.0, -1e16]], [1.0, 1.0, 1.0])[0]) == 0.0
    assert float(vecmat([1.0, 1.0, 1.0], [[1e16], [1.0], [-1e16]])[0]) == 0.0
    assert float(matmul([[1e16, 1.0, -1e16]], [[1.0], [1.0], [1.0]])[0, 0]) == 0.0
    x = 1.0 + 2.0 ** -30
    rounded = x * x  # 1 + 2^-29 (the 2^-60 is rounded away)
    assert float(dot([x, 1.0], [x, -rounded])) == 0.0  # fused: 2^-60


def test_inverse_of_a_camera_matrix_and_a_singular_one():
    from engine.render.components import look_at, perspective

    m = perspective(1.0, 16 / 9, 0.1, 500.0) @ look_at([3.0, 4.0, 5.0], [0.0, 1.0, 0.0])
    np.testing.assert_allclose(inverse(m), np.linalg.inv(m), rtol=1e-10, atol=1e-12)
    np.testing.assert_allclose(matmul(inverse(m), m), np.eye(4), atol=1e-12)
    with pytest.raises(np.linalg.LinAlgError):
        inverse(np.ones((4, 4)))
    with pytest.raises(ValueError, match="square"):
        inverse(np.ones((3, 4)))


def _blas_core_types() -> tuple[str, str]:
    """Two OpenBLAS kernel sets this CPU can run, one with fused multiply-adds and wide SIMD if it has them."""
    flags = Path("/proc/cpuinfo").read_text() if Path("/proc/cpuinfo").exists() else ""
    if " fma" in flags and " avx2" in flags:
        return "Sandybridge", "Haswell"
    if " avx" in flags:
        return "Prescott", "Sandybridge"
    pytest.skip("the CPU has a single OpenBLAS kernel set (no AVX): nothing to compare")


def test_the_demo_hash_is_the_same_with_other_blas_kernels():
    """The demo (water with floating bodies, smoke against colliders, picking, the autopilot's projections)
    gave another hash under OPENBLAS_CORETYPE=Haswell than under Sandybridge while bodies were rotated with ``@``."""
    cmd = [sys.executable, "-m", "engine", "run", "configs/scenes/demo.toml", "--no-render", "--steps", "60",
           "--seed", "3", "--hash"]
    hashes = []
    for core in _blas_core_types():
        env = {**os.environ, "OPENBLAS_CORETYPE": core}
        out = subprocess.run(cmd, capture_output=True, text=True, check=True, cwd=ROOT, env=env)
        hashes.append(out.stdout.strip().splitlines()[-1])
    assert hashes[0] == hashes[1]


# ------------------------------------------------------------------------------------- elementary functions
def _ulps(a, b) -> np.ndarray:
    """Units in the last place between float64 arrays (ordered as integers across the sign)."""
    ia, ib = (np.asarray(x, dtype=np.float64).view(np.int64) for x in (a, b))
    ia, ib = (np.where(i < 0, np.int64(-2**63) - i, i) for i in (ia, ib))
    return np.abs(ia - ib)


def _inputs() -> dict[str, np.ndarray]:
    rng = np.random.default_rng(7)
    n = 20000
    signs = rng.choice([-1.0, 1.0], n)
    return {"exp": np.concatenate([rng.uniform(-745.0, 709.7, n), rng.uniform(-1.0, 1.0, n),
                                   rng.uniform(-1e-8, 1e-8, 100)]),
            "atan": np.concatenate([rng.uniform(-5.0, 5.0, n), signs * np.exp(rng.uniform(-60.0, 60.0, n))]),
            "asin": rng.uniform(-1.0, 1.0, n),
            "cbrt": np.concatenate([rng.uniform(-1e3, 1e3, 300), signs[:300] * np.exp(rng.uniform(-700, 700, 300)),
                                    [5e-324, 1e-310, 27.0, -8.0, 1e300]]),
            "atan2": np.stack([rng.standard_normal(n) * np.exp(rng.uniform(-5, 5, n)),
                               rng.standard_normal(n) * np.exp(rng.uniform(-5, 5, n))]),
            "trig": np.concatenate(list(_trig_inputs(2000).values())),
            "hypot": np.concatenate([np.stack(pair) for pair in _hypot_inputs(2000).values()], axis=1)}


def _trig_inputs(n: int) -> dict[str, np.ndarray]:
    """Arguments of sin, cos and tan by magnitude, n of each (and a few named ones): fdlibm reduces |x| ≤ π/4 not at
    all, |x| up to 2^20·π/2 ≈ 1647099 by π/2 in 33-bit parts (its comment says 2^19·π/2 ≈ 823550) and larger ones
    with 2/π's bits (Payne–Hanek); multiples of π/2 and π/4 are where the reduction cancels most."""
    rng = np.random.default_rng(11)
    signs = rng.choice([-1.0, 1.0], n)

    def log_uniform(lo: float, hi: float) -> np.ndarray:
        return signs * np.exp(rng.uniform(math.log(lo), math.log(hi), n))

    big = np.finfo(np.float64).max
    return {"|x| < 1e-8": np.concatenate([rng.uniform(-1e-8, 1e-8, n), [5e-324, -1e-310, 2.0 ** -27, -2.0 ** -28]]),
            "|x| < 1": rng.uniform(-1.0, 1.0, n),
            "|x| < 10": rng.uniform(-10.0, 10.0, n),
            "|x| < 1e3": rng.uniform(-1e3, 1e3, n),
            "|x| < 1e6": rng.uniform(-1e6, 1e6, n),
            "near 2^19·π/2": 2.0 ** 19 * (math.pi / 2) + rng.uniform(-1e3, 1e3, n),
            "near 2^20·π/2": signs * (2.0 ** 20 * (math.pi / 2) + rng.uniform(-1e3, 1e3, n)),
            "1e6 to 1e15": log_uniform(1e6, 1e15),
            "1e15 to 1e22": np.concatenate([log_uniform(1e15, 1e22), [1e22, -1e22]]),
            "near 1e300": signs * 1e300 * rng.uniform(0.5, 2.0, n),
            "near DBL_MAX": np.concatenate([signs * rng.uniform(1.7e308, big, n), [1.7e308, big, -big]]),
            "n·π/2": signs * rng.integers(1, 10 ** 6, n) * (math.pi / 2),
            "n·π/4": signs * rng.integers(1, 10 ** 6, n) * (math.pi / 4)}


def _hypot_inputs(n: int) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """Argument pairs of hypot by magnitude, n of each: e_hypot.c scales both by 2^-600 when the larger is above
    2^500, by 2^600 when the smaller is below 2^-500 and by 2^1022 when it is subnormal, returns the sum when they
    are more than 2^60 apart, and splits the sum under the root in one way when the larger is above twice the
    smaller and in another otherwise."""
    rng = np.random.default_rng(13)

    def signed(v: np.ndarray) -> np.ndarray:
        return rng.choice([-1.0, 1.0], n) * v

    def log_uniform(lo: float, hi: float) -> np.ndarray:
        return signed(np.exp(rng.uniform(math.log(lo), math.log(hi), n)))

    near = rng.uniform(-1.0, 1.0, n)
    big = np.finfo(np.float64).max
    return {"|x|, |y| < 1": (rng.uniform(-1.0, 1.0, n), rng.uniform(-1.0, 1.0, n)),
            "|x| ≈ |y|": (near, signed(near * rng.uniform(0.999, 1.001, n))),
            "|x| ≈ 2|y|": (signed(2.0 * near * rng.uniform(0.99, 1.01, n)), near),
            "1e-300 to 1e300": (log_uniform(1e-300, 1e300), log_uniform(1e-300, 1e300)),
            "2^60 apart": (log_uniform(1.0, 10.0), log_uniform(1.0, 10.0) * 2.0 ** -60),
            "near 1e300": (signed(1e300 * rng.uniform(0.1, 10.0, n)), signed(1e300 * rng.uniform(0.1, 10.0, n))),
            "tiny normal": (log_uniform(2.3e-308, 1e-150), log_uniform(2.3e-308, 1e-150)),
            "near overflow": (signed(rng.uniform(0.0, big, n)), signed(rng.uniform(0.0, big, n))),
            "subnormal": (signed(rng.uniform(0.0, 2.2e-308, n)), signed(rng.uniform(0.0, 2.2e-308, n))),
            "subnormal and tiny": (signed(rng.uniform(0.0, 2.2e-308, n)), log_uniform(2.3e-308, 1e-291))}


def test_hypot_is_within_an_ulp_of_the_true_value():
    """Against CPython's ``math.hypot`` (since 3.10 computed with extra precision, correctly rounded in all but rare
    cases): at most 1 apart at every magnitude, overflowing where it does. Against the exact root (60 digits of
    √(x² + y²) of the binary values): below an ulp for normal arguments (0.97 at most seen); fdlibm 5.3 splits a
    subnormal argument's square with the unscaled high words and errs by up to 1.19 ulps there (Java's port too)."""
    from decimal import Decimal, getcontext

    getcontext().prec = 60
    overflow = Decimal(2) ** 1024 - Decimal(2) ** 970  # the true values that round to +∞
    for label, (x, y) in _hypot_inputs(20000).items():
        got = exact.hypot(x, y)
        want = np.array([math.hypot(a, b) for a, b in zip(x, y)])
        assert _ulps(got, want).max() <= 1, label
        bound = 1.2 if label.startswith("subnormal") else 1.0
        for a, b, r in zip(x[:400].tolist(), y[:400].tolist(), got[:400].tolist()):
            true = (Decimal(a) ** 2 + Decimal(b) ** 2).sqrt()
            if math.isinf(r):
                assert true >= overflow, (label, a, b)
            else:
                assert abs((Decimal(r) - true) / Decimal(math.ulp(r))) < bound, (label, a, b)


def test_hypot_special_values_as_c99():
    def same(a: float, b: float) -> bool:
        return a == b and math.copysign(1.0, a) == math.copysign(1.0, b)

    inf, nan = math.inf, math.nan
    for v in (0.0, -0.0, 1.0, -2.5, 5e-324, 1e308, inf, -inf, nan):
        for w in (inf, -inf):
            assert same(exact.hypot(v, w), inf) and same(exact.hypot(w, v), inf), v  # NaN beside ±∞ too
    for v in (0.0, -0.0, 1.0, -2.5, 5e-324, -1e308):
        assert math.isnan(exact.hypot(v, nan)) and math.isnan(exact.hypot(nan, v)), v
        for z in (0.0, -0.0):
            assert same(exact.hypot(v, z), abs(v)) and same(exact.hypot(z, v), abs(v)), v  # +0 for ±0, ±0
    assert math.isnan(exact.hypot(nan, nan))
    assert exact.hypot(3.0, 4.0) == 5.0 and exact.hypot(5e-324, 5e-324) == math.hypot(5e-324, 5e-324)
    assert exact.hypot(1.5e308, 1.5e308) == inf and exact.hypot(-1.5e308, 1e300) == 1.5e308  # only true overflow
    assert exact.hypot(1e308, -1e308) == math.hypot(1e308, 1e308) == 1.4142135623730951e308
    big = np.finfo(np.float64).max
    assert exact.hypot(big, 1e291) == big and exact.hypot(1.2e308, 1.2e308) == math.hypot(1.2e308, 1.2e308)
    assert exact.hypot(big, 2.0 ** 997) == big and exact.hypot(big, 2.0 ** 998) == inf  # 2^1024 − 2^970 between
    rng = np.random.default_rng(2)
    x = rng.standard_normal(1000) * np.exp(rng.uniform(-700.0, 700.0, 1000))
    y = rng.standard_normal(1000) * np.exp(rng.uniform(-700.0, 700.0, 1000))
    h = exact.hypot(x, y)
    for a, b in ((y, x), (-x, y), (x, -y), (-y, -x)):  # symmetric in its arguments and their signs, to the bit
        assert exact.hypot(a, b).view(np.int64).tolist() == h.view(np.int64).tolist()


def test_hypot_takes_numbers_and_arrays_alike():
    from numba import njit

    x = np.array([[0.25, -3.0, 0.0], [7.5, 1e-3, 1e300]])
    y = np.array([[4.0, 2.0, -0.0], [-1e-310, 1e-3, 1e301]])
    arr = exact.hypot(x, y)
    assert arr.shape == x.shape and arr.dtype == np.float64
    assert arr.ravel().tolist() == [exact.hypot(float(a), float(b)) for a, b in zip(x.ravel(), y.ravel())]
    assert isinstance(exact.hypot(3.0, 4.0), float) and exact.hypot(3, 4) == 5.0
    assert exact.hypot(x, 2.0).tolist() == [[exact.hypot(float(v), 2.0) for v in row] for row in x]  # broadcast
    assert exact.hypot(2.0, x[0]).tolist() == [exact.hypot(2.0, float(v)) for v in x[0]]
    assert exact.hypot(x, y[0]).shape == (2, 3) and exact.hypot([1.0, 2.0], [2.0, 1.0]).tolist() == [5.0 ** 0.5] * 2
    assert exact.hypot(np.zeros((0, 2)), 1.0).shape == (0, 2)

    @njit
    def lengths(v):  # called from another compiled function
        out = np.empty(v.shape[0])
        for i in range(v.shape[0]):
            out[i] = exact.hypot_scalar(v[i, 0], v[i, 1])
        return out

    assert lengths(np.stack([x.ravel(), y.ravel()], axis=1)).tolist() == arr.ravel().tolist()


def test_elementary_functions_are_within_an_ulp_of_the_true_value():
    """exp, atan and atan2 against the C library's (which is within an ulp itself: so at most 1 apart), asin
    within 2; the cube root against the exact root (decimal arithmetic), where glibc's own errs by 2 ulps."""
    from decimal import Decimal, getcontext

    data = _inputs()
    for name in ("exp", "atan", "asin"):
        got = getattr(exact, name)(data[name])
        want = np.array([getattr(math, name)(x) for x in data[name]])
        assert _ulps(got, want).max() <= (2 if name == "asin" else 1), name
    y, x = data["atan2"]
    assert _ulps(exact.atan2(y, x), [math.atan2(a, b) for a, b in zip(y, x)]).max() <= 1
    getcontext().prec = 50
    third = Decimal(1) / Decimal(3)
    for v in data["cbrt"]:
        got = float(exact.cbrt(float(v)))
        true = (Decimal(abs(float(v))) ** third).copy_sign(Decimal(float(v)))
        assert abs((Decimal(got) - true) / Decimal(math.ulp(got))) < 0.67, v  # fdlibm's bound: 0.667


def test_elementary_functions_special_values_as_the_c_library():
    specials = [0.0, -0.0, 1.0, -1.0, 0.5, -2.0, math.inf, -math.inf, math.nan, 5e-324, -5e-324, 1e308, -1e308]

    def same(a: float, b: float) -> bool:
        return (math.isnan(a) and math.isnan(b)) or (a == b and math.copysign(1.0, a) == math.copysign(1.0, b))

    for y in specials:
        for x in specials:
            assert same(exact.atan2(y, x), math.atan2(y, x)), (y, x)
        assert same(exact.atan(y), math.atan(y)), y
        assert same(exact.cbrt(y), math.cbrt(y)) or abs(_ulps(exact.cbrt(y), math.cbrt(y))) <= 2, y
    for x in specials + [709.78, 710.0, -745.0, -746.0, 1e-300]:
        want = math.inf if x > 709.79 else math.exp(x)
        assert _ulps(exact.exp(x), want) <= 1 or same(exact.exp(x), want), x
    assert exact.exp(710.0) == math.inf and exact.exp(-746.0) == 0.0 and math.isnan(exact.exp(math.nan))
    assert math.isnan(exact.asin(1.5)) and exact.asin(1.0) == math.asin(1.0) and same(exact.asin(-0.0), -0.0)


def test_elementary_functions_take_numbers_and_arrays_alike():
    x = np.array([[0.25, -3.0], [7.5, 1e-3]])
    for name in ("exp", "cbrt", "atan"):
        arr = getattr(exact, name)(x)
        assert arr.shape == x.shape and arr.dtype == np.float64
        assert [getattr(exact, name)(float(v)) for v in x.ravel()] == arr.ravel().tolist()
        assert isinstance(getattr(exact, name)(0.5), float)
    assert exact.atan2(x, 2.0).tolist() == [[exact.atan2(float(v), 2.0) for v in row] for row in x]


def test_sin_cos_tan_are_within_an_ulp_at_every_magnitude():
    """Against the C library's (glibc's are within an ulp of the true value, as fdlibm's: so at most 1 apart), from
    tiny arguments through the three reductions to the largest double, and at multiples of π/2 and π/4."""
    for label, x in _trig_inputs(20000).items():
        for name in ("sin", "cos", "tan"):
            want = np.array([getattr(math, name)(v) for v in x])
            assert _ulps(getattr(exact, name)(x), want).max() <= 1, (name, label)
    assert exact.sin(1e22) == -0.8522008497671888 and exact.cos(1e22) == 0.523214785395139  # fdlibm's, glibc's


def test_sin_cos_tan_special_values_as_the_c_library():
    def same(a: float, b: float) -> bool:
        return a == b and math.copysign(1.0, a) == math.copysign(1.0, b)

    for x in (0.0, -0.0, 5e-324, -5e-324, 1e-300, -1e-300, 2.0 ** -28, -(2.0 ** -28), 7.45e-9, -7.45e-9):
        assert same(exact.sin(x), x) and same(exact.tan(x), x) and exact.cos(x) == 1.0, x
        assert same(exact.sin(x), math.sin(x)) and same(exact.tan(x), math.tan(x)), x
    for x in (math.inf, -math.inf, math.nan):
        assert math.isnan(exact.sin(x)) and math.isnan(exact.cos(x)) and math.isnan(exact.tan(x)), x
    assert np.isnan(exact.sin(np.array([math.inf, -math.inf, math.nan]))).all()


def test_sin_cos_tan_take_numbers_and_arrays_alike():
    x = np.array([0.0, -0.0, 0.5, -2.0, 10.0, 823549.5, 1647100.0, -1e22, 1.7e308])
    for name in ("sin", "cos", "tan"):
        f = getattr(exact, name)
        arr = f(x)
        assert arr.dtype == np.float64 and isinstance(f(0.5), float) and isinstance(f(3), float)
        assert arr.view(np.int64).tolist() == np.array([f(float(v)) for v in x]).view(np.int64).tolist(), name
        for shape in ((0,), (3,), (2, 3)):
            a = np.linspace(-4.0, 4.0, math.prod(shape)).reshape(shape)
            out = f(a)
            assert out.shape == shape and out.dtype == np.float64
            assert out.ravel().tolist() == [f(float(v)) for v in a.ravel()]
        assert f([1.0, 2.0]).tolist() == [f(1.0), f(2.0)]


_BITS = """
import hashlib, numpy as np
from tests.engine.test_exact import _inputs
from engine import exact
data = _inputs()
out = [getattr(exact, n)(data[n]) for n in ("exp", "atan", "asin", "cbrt")] + [exact.atan2(*data["atan2"])]
out += [getattr(exact, n)(data["trig"]) for n in ("sin", "cos", "tan")] + [exact.hypot(*data["hypot"])]
print(hashlib.sha256(b"".join(np.ascontiguousarray(o).tobytes() for o in out)).hexdigest())
"""


def test_elementary_functions_give_the_same_bits_compiled_and_as_plain_python():
    """The compiled kernels against the same code run as Python floats (``NUMBA_DISABLE_JIT``), whose ``+ - * /``
    round each operation alone: LLVM neither fused a multiply-add nor reordered a sum. sin, cos and tan are
    compared at every magnitude, so each of their argument reductions (Payne–Hanek's too) is, and hypot in each of
    its scalings and splits."""
    results = []
    for env in ({}, {"NUMBA_DISABLE_JIT": "1"}):
        out = subprocess.run([sys.executable, "-c", _BITS], capture_output=True, text=True, check=True, cwd=ROOT,
                             env={**os.environ, **env, "PYTHONPATH": str(ROOT)})
        results.append(out.stdout.strip())
    assert results[0] == results[1]


@pytest.mark.skipif(platform.machine().lower() not in ("x86_64", "amd64"), reason="x86 SIMD levels")
def test_the_demo_hash_is_the_same_with_numpys_simd_code_limited_to_its_baseline():
    """numpy picks the SIMD code of ``exp``, ``cbrt``, ``arctan2``, ``power``... by the CPU; on one with AVX-512 the
    demo's autoplay gave another hash than with that code turned off (``NPY_DISABLE_CPU_FEATURES``) until the
    simulation used engine.exact's functions. On a CPU without AVX2 or AVX-512 both runs are the same run."""
    cmd = [sys.executable, "-m", "game_demo", "--headless", "--autoplay", "--no-render", "--seed", "3"]
    runs = [subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True, cwd=ROOT,
                             env={**os.environ, **env})
            for env in ({}, {"NPY_DISABLE_CPU_FEATURES": "X86_V3 X86_V4 AVX512_ICL AVX512_SPR"})]
    hashes = [run.communicate(timeout=300)[0].strip().splitlines()[-1] for run in runs]
    assert all(run.returncode == 0 for run in runs)
    assert hashes[0] == hashes[1]
