"""Compiled kernels (``engine.jit.kernel``) of the toon smoke's per-step loops.

:func:`splat_blobs_kernel`: the density blobs of §3.3 (figure 2, seeds/002), one ellipsoidal bump per particle.
In numpy (:func:`systems.toon_smoke.display.splat_blobs_numpy`) this is two (particles × stencil) matrix products,
masks, a gather and an unbuffered ``np.add.at`` per stencil size: on the demo's 32³ display grid with a few
hundred particles the calls, not the arithmetic, took the time (about 1.4 ms a volume a step).  Here it is one
loop over the particles and their stencil cells, with no temporaries.

The float32 operations are those of the numpy code, in its order, except the stencil products: the numpy code
gets f·o and û·o from a BLAS matrix product, whose rounding depends on the library and the CPU (fused
multiply-adds or not); the kernel sums the three products left to right, the same on every machine.  The
blobs are added to a zeroed buffer in the numpy code's order (stencil sizes ascending, particles, stencil cells)
and the buffer to the grid, so the sums round the same way.
"""

from __future__ import annotations

import math

import numpy as np

from engine.jit import kernel


@kernel
def splat_blobs_kernel(target, centres, directions, along, across, amplitude):  # pragma: no cover
    """Add amplitude·(1 − q²)³ per particle to ``target`` (float32, in place), with
    q² = (d·û)²/a² + (|d|² − (d·û)²)/b² < 1 (figure 2, seeds/002; see ``display.splat_blobs``).

    ``centres`` (N, 3) are in the grid's index space (cell i's centre at i), ``directions`` (N, 3) unit stretch
    axes û, ``along``/``across`` (N,) the semi-axes a, b in cells.  Blobs centred more than one cell outside the grid are skipped; stencil cells outside it are
    dropped.  Returns the number of blobs added.
    """
    nx, ny, nz = target.shape
    n = centres.shape[0]
    box = np.zeros(target.shape, np.float32)
    reach = np.empty(n, np.int64)
    near = np.zeros(n, np.bool_)
    max_reach = 1
    count = 0
    for p in range(n):
        ok = True
        for k in range(3):
            c = centres[p, k]
            if not (c >= -1.0 and c <= target.shape[k]):
                ok = False
        near[p] = ok
        r = max(int(math.ceil(along[p])), 1)
        reach[p] = r
        if ok:
            count += 1
            max_reach = max(max_reach, r)
    amp = np.float32(amplitude)
    one = np.float32(1.0)
    for r in range(1, max_reach + 1):  # stencil sizes ascending, as numpy's np.unique(reach)
        limit = (r + 0.87) ** 2
        for p in range(n):
            if not near[p] or reach[p] != r:
                continue
            c0, c1, c2 = np.float32(centres[p, 0]), np.float32(centres[p, 1]), np.float32(centres[p, 2])
            b0, b1, b2 = np.float32(np.rint(c0)), np.float32(np.rint(c1)), np.float32(np.rint(c2))
            f0, f1, f2 = b0 - c0, b1 - c1, b2 - c2
            a0, a1, a2 = np.float32(directions[p, 0]), np.float32(directions[p, 1]), np.float32(directions[p, 2])
            fa = f0 * a0 + f1 * a1 + f2 * a2
            ff = f0 * f0 + f1 * f1 + f2 * f2
            g0, g1, g2 = f0 + f0, f1 + f1, f2 + f2
            inv_a2 = np.float32(1.0 / along[p] ** 2)
            inv_b2 = np.float32(1.0 / across[p] ** 2)
            shape_term = inv_a2 - inv_b2
            i0, j0, k0 = int(b0), int(b1), int(b2)
            for ox in range(-r, r + 1):
                for oy in range(-r, r + 1):
                    for oz in range(-r, r + 1):
                        if ox * ox + oy * oy + oz * oz > limit:
                            continue
                        x, y, z = np.float32(ox), np.float32(oy), np.float32(oz)
                        t = fa + (a0 * x + a1 * y + a2 * z)
                        d2 = ff + (g0 * x + g1 * y + g2 * z)
                        d2 += x * x + y * y + z * z
                        t *= t
                        t *= shape_term
                        d2 *= inv_b2
                        t += d2  # 1 - q
                        if not t < one:
                            continue
                        i, j, kk = i0 + ox, j0 + oy, k0 + oz
                        if i < 0 or i >= nx or j < 0 or j >= ny or kk < 0 or kk >= nz:
                            continue
                        q = one - t
                        box[i, j, kk] += amp * q * q * q
    for i in range(nx):
        for j in range(ny):
            for kk in range(nz):
                target[i, j, kk] += box[i, j, kk]
    return count
