"""engine.jit: kernels compile with the engine's settings and give IEEE results in the order written."""

from __future__ import annotations


import numpy as np

from engine.jit import OPTIONS, kernel


@kernel
def _running_sum(values):
    total = 0.0
    for i in range(values.shape[0]):
        total += values[i]
    return total


@kernel(inline="always")
def _axpy(a, x, y):
    out = np.empty_like(x)
    for i in range(x.shape[0]):
        out[i] = a * x[i] + y[i]
    return out


def test_sum_keeps_the_written_order():
    # With fastmath LLVM vectorises the reduction into several partial sums, which changes the last bits on
    # data like this; the engine's settings forbid that, so the kernel matches a sequential Python sum exactly.
    values = np.random.default_rng(3).standard_normal(10_001) * 10.0 ** np.arange(-5, 5).repeat(1001)[:10_001]
    expected = 0.0
    for v in values.tolist():
        expected += v
    assert _running_sum(values) == expected


def test_no_fused_multiply_add():
    rng = np.random.default_rng(4)
    x, y = rng.standard_normal(257), rng.standard_normal(257)
    assert np.array_equal(_axpy(1.0 / 3.0, x, y), (1.0 / 3.0) * x + y)


def test_settings():
    assert OPTIONS["fastmath"] is False and OPTIONS["cache"] is True
    assert _running_sum.targetoptions["nogil"] is True
    # division by zero follows numpy (inf), it does not raise
    assert _divide(np.array([1.0]), 0.0)[0] == np.inf


@kernel
def _divide(x, d):
    return x / d
