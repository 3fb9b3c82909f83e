"""Pressure Poisson solve on a MAC grid with solid cells: multigrid-preconditioned conjugate gradients.

The projection step of stable fluids (Stam 1999; seeds/002 §3.1) needs ∇·u = 0.  On a MAC grid with face
"openness" coefficients A_f ∈ [0, 1] (1 between two fluid cells or towards an open boundary, 0 towards a wall or a
solid) the discrete equation for a scaled pressure φ = Δt·p / (ρ·h) is

    M φ = b,   (M φ)_c = Σ_f A_f (φ_c − φ_nb(f)),   b_c = −Σ_f (outward face velocity)

and the face update u_f −= A_f (φ_nb − φ_c) then leaves every fluid cell with zero net flux.  M is the 7-point
Laplacian with Neumann conditions at walls and solids and φ = 0 in the ghost cell of an open face: symmetric
positive (semi-)definite, so conjugate gradients converge; a geometric multigrid V-cycle (red–black Gauss–Seidel
smoothing, face coefficients averaged on coarse levels, a dense inverse on the coarsest) preconditions it, as in
McAdams, Sifakis & Teran, "A parallel multigrid Poisson solver for fluids simulation on large grids" (SCA 2010).

All arrays are indexed [x, y, z]; cell fields are float32, dot products accumulate in float64 (pairwise sums, no
BLAS, so a run repeats bit for bit).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

F32 = NDArray[np.float32]

__all__ = ["PoissonHierarchy", "SolveReport", "build_hierarchy", "solve"]

_COARSEST_CELLS = 64  # stop coarsening at or below this many cells (dense inverse there)
_SMOOTH_SWEEPS = 2  # red-black Gauss-Seidel sweeps before and after each coarse correction


@dataclass
class Level:
    """One multigrid level: face coefficients, the diagonal and the red/black masks of its active cells."""

    shape: tuple[int, int, int]
    ax: F32  # (nx-1, ny, nz) interior x-face coefficients
    ay: F32  # (nx, ny-1, nz)
    az: F32  # (nx, ny, nz-1)
    faces: tuple[F32, F32, F32]  # full face arrays incl. boundary planes (for coarsening and the velocity update)
    neighbour_coefficients: tuple[F32, ...]  # per cell: A of its −x, +x, −y, +y, −z, +z face (0 on the border)
    padded: F32  # (nx+2, ny+2, nz+2) scratch: φ with a ring of zero ghosts
    diag: F32
    inv_diag: F32
    red: NDArray[np.bool_]
    black: NDArray[np.bool_]
    red_inv_diag: F32  # inv_diag on red cells, 0 elsewhere (the Gauss–Seidel half sweeps as arithmetic blends)
    black_inv_diag: F32
    keep_red: F32  # 1 where a red half sweep leaves the value alone (black and inactive cells), else 0
    keep_black: F32
    active: NDArray[np.bool_]
    dense_inverse: NDArray[np.float64] | None = None  # coarsest level only: pinv of M on the active cells


@dataclass
class PoissonHierarchy:
    """The multigrid levels for one solid mask (rebuilt when obstacles change)."""

    levels: list[Level] = field(default_factory=list)
    singular: bool = False  # no open boundary: M has the constants in its null space
    fluid_weight: F32 | None = None  # 1 in fluid cells, 0 in solid cells (fine level)


@dataclass
class SolveReport:
    iterations: int
    residual: float  # max |M φ − b| at exit, same units as b (face velocity × 1)
    rhs: float  # max |b|


def face_coefficients(solid: NDArray[np.bool_], open_faces: tuple[bool, bool, bool, bool, bool, bool]
                      ) -> tuple[F32, F32, F32]:
    """A_f per face: 1 between two fluid cells and on an open boundary next to fluid, else 0.

    ``open_faces`` flags the domain sides (−x, +x, −y, +y, −z, +z); a closed side is a wall (u·n = 0).
    """
    fluid = ~solid
    nx, ny, nz = solid.shape
    ax = np.zeros((nx + 1, ny, nz), np.float32)
    ay = np.zeros((nx, ny + 1, nz), np.float32)
    az = np.zeros((nx, ny, nz + 1), np.float32)
    ax[1:-1] = fluid[1:] & fluid[:-1]
    ay[:, 1:-1] = fluid[:, 1:] & fluid[:, :-1]
    az[:, :, 1:-1] = fluid[:, :, 1:] & fluid[:, :, :-1]
    ax[0], ax[-1] = fluid[0] * open_faces[0], fluid[-1] * open_faces[1]
    ay[:, 0], ay[:, -1] = fluid[:, 0] * open_faces[2], fluid[:, -1] * open_faces[3]
    az[:, :, 0], az[:, :, -1] = fluid[:, :, 0] * open_faces[4], fluid[:, :, -1] * open_faces[5]
    return ax, ay, az


def _make_level(ax: F32, ay: F32, az: F32) -> Level:
    nx, ny, nz = ay.shape[0], ax.shape[1], ax.shape[2]
    diag = (ax[:-1] + ax[1:] + ay[:, :-1] + ay[:, 1:] + az[:, :, :-1] + az[:, :, 1:]).astype(np.float32)
    active = diag > 0.0
    inv_diag = np.zeros_like(diag)
    np.divide(1.0, diag, out=inv_diag, where=active)
    i, j, k = np.indices((nx, ny, nz), sparse=True)
    parity = ((i + j + k) & 1).astype(bool)
    red, black = active & ~parity, active & parity
    neighbours = []
    for axis, faces in enumerate((ax, ay, az)):
        inner = [slice(None)] * 3
        for lo in (True, False):
            c = np.array(faces, dtype=np.float32)
            inner[axis] = slice(0, -1) if lo else slice(1, None)
            c = c[tuple(inner)].copy()
            border = [slice(None)] * 3
            border[axis] = 0 if lo else -1
            c[tuple(border)] = 0.0  # the ghost beyond an open face holds φ = 0: only the diagonal sees that face
            neighbours.append(c)
    f32 = np.float32
    return Level((nx, ny, nz), np.ascontiguousarray(ax[1:-1]), np.ascontiguousarray(ay[:, 1:-1]),
                 np.ascontiguousarray(az[:, :, 1:-1]), (ax, ay, az), tuple(neighbours),
                 np.zeros((nx + 2, ny + 2, nz + 2), f32), diag, inv_diag.astype(f32), red, black,
                 (inv_diag * red).astype(f32), (inv_diag * black).astype(f32), (~red).astype(f32),
                 (~black).astype(f32), active)


def _coarsen(level: Level) -> Level:
    """Average each 2×2 patch of fine faces onto the coarse face it lies in (every other fine face plane)."""
    ax, ay, az = level.faces
    nx, ny, nz = level.shape
    cx, cy, cz = nx // 2, ny // 2, nz // 2
    cax = ax[::2].reshape(cx + 1, cy, 2, cz, 2).mean(axis=(2, 4), dtype=np.float32)
    cay = ay[:, ::2].reshape(cx, 2, cy + 1, cz, 2).mean(axis=(1, 4), dtype=np.float32)
    caz = az[:, :, ::2].reshape(cx, 2, cy, 2, cz + 1).mean(axis=(1, 3), dtype=np.float32)
    return _make_level(cax, cay, caz)


def _dense_operator(level: Level) -> NDArray[np.float64]:
    """M restricted to the active cells of a (small) level, as a dense matrix."""
    index = np.full(level.shape, -1, np.int64)
    cells = np.flatnonzero(level.active)
    index.ravel()[cells] = np.arange(cells.size)
    matrix = np.zeros((cells.size, cells.size))
    matrix[np.arange(cells.size), np.arange(cells.size)] = level.diag.ravel()[cells]
    for axis, coef in enumerate((level.ax, level.ay, level.az)):
        lo = [slice(None)] * 3
        hi = [slice(None)] * 3
        lo[axis], hi[axis] = slice(0, -1), slice(1, None)
        a, b, c = index[tuple(lo)].ravel(), index[tuple(hi)].ravel(), coef.ravel()
        keep = (a >= 0) & (b >= 0) & (c > 0)
        matrix[a[keep], b[keep]] -= c[keep]
        matrix[b[keep], a[keep]] -= c[keep]
    return matrix


def build_hierarchy(solid: NDArray[np.bool_], open_faces: tuple[bool, ...]) -> PoissonHierarchy:
    """Levels from the fine solid mask down to ≤ 64 cells (halving while every side is even and ≥ 4)."""
    level = _make_level(*face_coefficients(solid, tuple(open_faces)))
    levels = [level]
    while (np.prod(level.shape) > _COARSEST_CELLS and all(n % 2 == 0 and n >= 4 for n in level.shape)):
        level = _coarsen(level)
        levels.append(level)
    if np.prod(level.shape) > 4096:
        raise ValueError(f"grid {levels[0].shape} cannot be coarsened below {level.shape}: use sides that are "
                         "multiples of 8")
    level.dense_inverse = np.linalg.pinv(_dense_operator(level)) if level.active.any() else np.zeros((0, 0))
    return PoissonHierarchy(levels, singular=not any(open_faces), fluid_weight=(~solid).astype(np.float32))


def _neighbour_sum(level: Level, phi: F32) -> F32:
    """Σ_f A_f φ_nb(f) over the interior faces (ghost cells beyond the domain hold 0)."""
    buf = level.padded
    buf[1:-1, 1:-1, 1:-1] = phi
    cxm, cxp, cym, cyp, czm, czp = level.neighbour_coefficients
    s = cxm * buf[:-2, 1:-1, 1:-1]
    s += cxp * buf[2:, 1:-1, 1:-1]
    s += cym * buf[1:-1, :-2, 1:-1]
    s += cyp * buf[1:-1, 2:, 1:-1]
    s += czm * buf[1:-1, 1:-1, :-2]
    s += czp * buf[1:-1, 1:-1, 2:]
    return s


def apply_operator(level: Level, phi: F32) -> F32:
    """M φ = diag·φ − Σ_f A_f φ_nb (zero on inactive cells)."""
    return level.diag * phi - _neighbour_sum(level, phi)


def _smooth(level: Level, phi: F32, b: F32, order: tuple[str, str]) -> F32:
    """Red–black Gauss–Seidel: update all red cells from their (black) neighbours, then all black cells.

    Each half sweep is φ ← keep·φ + inv_diag_colour·(b + Σ A φ_nb), an arithmetic blend (no boolean scatter).
    """
    for colour in order:
        if colour == "red":
            keep, scale = level.keep_red, level.red_inv_diag
        else:
            keep, scale = level.keep_black, level.black_inv_diag
        phi = keep * phi + scale * (b + _neighbour_sum(level, phi))
    return phi


def _restrict(r: F32) -> F32:
    """Coarse right-hand side: 4 × the mean of the 8 children (the (2h)²/h² scaling of the 7-point Laplacian)."""
    s = r[0::2] + r[1::2]
    s = s[:, 0::2] + s[:, 1::2]
    s = s[:, :, 0::2] + s[:, :, 1::2]
    s *= np.float32(0.5)
    return s


def _prolong(e: F32) -> F32:
    """Piecewise-constant prolongation: each coarse value to its 8 children (adjoint of the restriction)."""
    cx, cy, cz = e.shape
    out = np.broadcast_to(e[:, None, :, None, :, None], (cx, 2, cy, 2, cz, 2))
    return out.reshape(2 * cx, 2 * cy, 2 * cz)


def v_cycle(hierarchy: PoissonHierarchy, b: F32, depth: int = 0) -> F32:
    """One symmetric V-cycle approximating M⁻¹ b (a symmetric positive preconditioner for CG)."""
    level = hierarchy.levels[depth]
    if level.dense_inverse is not None:
        x = np.zeros_like(b)
        cells = level.active
        # multiply-and-sum rather than BLAS matvec: numpy's pairwise sum gives the same bits on every CPU
        x[cells] = (level.dense_inverse * b[cells].astype(np.float64)[None, :]).sum(axis=1).astype(np.float32)
        return x
    x = level.red_inv_diag * b  # the first red half sweep from φ = 0 needs no neighbours
    x = _smooth(level, x, b, ("black",))
    for _ in range(_SMOOTH_SWEEPS - 1):
        x = _smooth(level, x, b, ("red", "black"))
    residual = np.where(level.active, b - apply_operator(level, x), np.float32(0.0))
    x = x + _prolong(v_cycle(hierarchy, _restrict(residual), depth + 1))
    x[~level.active] = 0.0
    for _ in range(_SMOOTH_SWEEPS):
        x = _smooth(level, x, b, ("black", "red"))
    return x


def _dot(a: F32, b: F32) -> float:
    return float(np.multiply(a, b, dtype=np.float64).sum())


def _remove_mean(x: F32, active: NDArray[np.bool_]) -> None:
    """Project out the constant null-space vector of a closed domain (over the active cells)."""
    count = int(active.sum())
    if count:
        x[active] -= np.float32(x[active].sum(dtype=np.float64) / count)


def solve(hierarchy: PoissonHierarchy, b: F32, x0: F32 | None = None, tolerance: float = 1e-4,
          max_iterations: int = 30) -> tuple[F32, SolveReport]:
    """Preconditioned conjugate gradients for M φ = b until max|r| ≤ tolerance · max|b|.

    ``x0`` warm-starts the iteration (last step's pressure).  In a closed domain the right-hand side and every
    preconditioned residual are made zero-mean so the iteration stays in the range of M.
    """
    fine = hierarchy.levels[0]
    b = np.where(fine.active, b, np.float32(0.0)).astype(np.float32)
    if hierarchy.singular:
        _remove_mean(b, fine.active)
    b_max = float(np.abs(b).max()) if b.size else 0.0
    x = np.zeros_like(b) if x0 is None else np.where(fine.active, x0, np.float32(0.0)).astype(np.float32)
    r = b - apply_operator(fine, x)
    r[~fine.active] = 0.0
    threshold = tolerance * b_max
    res = float(np.abs(r).max())
    if res <= threshold or b_max == 0.0:
        return x, SolveReport(0, res, b_max)
    z = v_cycle(hierarchy, r)
    if hierarchy.singular:
        _remove_mean(z, fine.active)
    p = z.copy()
    rz = _dot(r, z)
    iterations = 0
    while iterations < max_iterations:
        iterations += 1
        ap = apply_operator(fine, p)
        p_ap = _dot(p, ap)
        if p_ap <= 0.0:
            break
        alpha = np.float32(rz / p_ap)
        x += alpha * p
        r -= alpha * ap
        res = float(np.abs(r).max())
        if res <= threshold:
            break
        z = v_cycle(hierarchy, r)
        if hierarchy.singular:
            _remove_mean(z, fine.active)
        rz_new = _dot(r, z)
        p *= np.float32(rz_new / rz)
        p += z
        rz = rz_new
    return x, SolveReport(iterations, res, b_max)
