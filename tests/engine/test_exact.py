"""engine.exact: the products agree with numpy's to rounding, sum in the documented order, and a whole game gives
the same state hash whichever BLAS kernels numpy's OpenBLAS picks for the CPU."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

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
