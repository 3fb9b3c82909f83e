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

:func:`solve` runs the whole iteration, from the first residual to the report, in one compiled call
(:func:`systems.toon_smoke.kernels.mgpcg_kernel`, on the levels packed end to end: :class:`_PackedLevels`).
:func:`solve_numpy` is the same iteration as separate numpy and compiled calls, some thirty an iteration, and the
reference it is tested against bit for bit.
"""

from __future__ import annotations

import copy
from dataclasses import dataclass, field, fields

import numpy as np
from numpy.typing import NDArray

from components.toon_smoke import MAX_COARSEST_CELLS, coarsest_shape

F32 = NDArray[np.float32]

__all__ = ["PoissonHierarchy", "SolveReport", "build_hierarchy", "solve", "solve_numpy"]

_SMOOTH_SWEEPS = 2  # red-black Gauss-Seidel sweeps before and after each coarse correction


@dataclass
class Level:
    """One multigrid level: face coefficients, the diagonal and the red/black masks of its active cells.

    The smoother works on a *padded flat* layout: a cell field is stored with a ring of ghost cells as one contiguous
    vector of ``(nx+2)(ny+2)(nz+2)`` values, so that a neighbour is a fixed offset (±sx, ±sy, ±1) and every stencil
    term is one contiguous slice (one cheap numpy call, where a 3-D strided view costs several times more on small
    grids).  The ``*_span`` arrays cover the flat range ``[sx, P − sx)`` (every cell that has all six neighbours in
    the vector); ghost cells in that range have zero coefficients and stay 0.
    """

    shape: tuple[int, int, int]
    ax: F32  # (nx-1, ny, nz) interior x-face coefficients
    ay: F32  # (nx, ny-1, nz)
    az: F32  # (nx, ny, nz-1)
    faces: tuple[F32, F32, F32]  # full face arrays incl. boundary planes (for coarsening and the velocity update)
    neighbour_coefficients: tuple[F32, ...]  # per cell: A of its −x, +x, −y, +y, −z, +z face (0 on the border)
    diag: F32
    inv_diag: F32
    red: NDArray[np.bool_]
    black: NDArray[np.bool_]
    active: NDArray[np.bool_]
    flat: _FlatLevel
    dense_inverse: NDArray[np.float64] | None = None  # coarsest level only: pinv of M on the active cells
    dense_cells: NDArray[np.intp] | None = None  # coarsest level only: padded flat index of each active cell


@dataclass
class _FlatLevel:
    """The padded flat layout of one level (see :class:`Level`) and its scratch vectors."""

    padded_shape: tuple[int, int, int]
    offsets: tuple[int, ...]  # flat offset of the −x, +x, −y, +y, −z, +z neighbour
    span: slice  # [sx, P − sx)
    coefficients: tuple[F32, ...] | None  # A per neighbour over the span; None: every product A·φ_nb equals φ_nb
    diag: F32  # over the span (0 on ghosts and inactive cells)
    red_inv_diag: F32  # 1/diag on active red cells, 0 elsewhere (the half sweeps as arithmetic blends)
    black_inv_diag: F32
    keep_red: F32  # 1 where a red half sweep leaves the value alone (black, inactive and ghost cells), else 0
    keep_black: F32
    active: NDArray[np.bool_]  # over the span
    inactive: NDArray[np.bool_]  # over the span
    x: F32  # (P,) the level's iterate, ghosts 0
    b: F32  # (P,) the level's right-hand side, ghosts 0
    r: F32  # (P,) the level's residual (or M φ), ghosts 0
    s: F32  # span-sized scratch (neighbour sums)
    t: F32  # span-sized scratch
    x_span: F32 = field(init=False)
    b_span: F32 = field(init=False)
    r_span: F32 = field(init=False)
    x_neighbours: tuple[F32, ...] = field(init=False)  # x shifted by each offset, over the span
    coefficient_matrix: F32 = field(init=False)  # the coefficients (6, span) for the compiled smoother; (6, 0) when
    # coefficients is None
    parent_index: NDArray[np.intp] | None = field(init=False)  # see below
    x_interior: F32 = field(init=False)  # the (nx, ny, nz) views of x, b and r (see :meth:`interior`), made once
    b_interior: F32 = field(init=False)
    r_interior: F32 = field(init=False)
    smoother: tuple = field(init=False)  # the compiled smoothers' level arguments (:func:`_pre_smooth`)

    def __post_init__(self) -> None:
        lo, hi = self.span.start, self.span.stop
        self.x_span, self.b_span, self.r_span = self.x[self.span], self.b[self.span], self.r[self.span]
        self.x_neighbours = tuple(self.x[lo + o:hi + o] for o in self.offsets)
        self.coefficient_matrix = (np.zeros((6, 0), np.float32) if self.coefficients is None
                                   else np.ascontiguousarray(np.stack(self.coefficients), np.float32))
        self.x_interior, self.b_interior, self.r_interior = (self.interior(v) for v in (self.x, self.b, self.r))
        self.smoother = (self.x, self.b_span, self.red_inv_diag, self.black_inv_diag, self.keep_red, self.keep_black,
                         self.offsets[1], self.offsets[3], self.coefficient_matrix, self.coefficients is not None,
                         self.span.start, self.s, _SMOOTH_SWEEPS)
        nx, ny, nz = (n - 2 for n in self.padded_shape)
        self.parent_index = None
        if nx % 2 == 0 and ny % 2 == 0 and nz % 2 == 0:
            self.parent_index = _parent_index(self.padded_shape)[self.span]

    def __deepcopy__(self, memo: dict) -> _FlatLevel:
        """Snapshots deep-copy the hierarchy: copy the vectors and rebuild the views into the copies (a plain deep
        copy would give views of copies that no longer alias the copied vectors)."""
        return _FlatLevel(**{f.name: copy.deepcopy(getattr(self, f.name), memo) for f in fields(self) if f.init})

    def interior(self, vector: F32) -> F32:
        """The (nx, ny, nz) view of the real cells of a padded flat vector."""
        return vector.reshape(self.padded_shape)[1:-1, 1:-1, 1:-1]


def _parent_index(padded_shape: tuple[int, int, int]) -> NDArray[np.intp]:
    """For every entry of a padded flat vector of an even-sided level: the index of the cell's parent (the coarse
    cell holding its 2×2×2 block) in the next level's padded flat vector, and 0 for ghosts (the coarse vector's
    first entry, a ghost that is never written: always 0)."""
    nx, ny, nz = (n - 2 for n in padded_shape)
    coarse = (nx // 2 + 2, ny // 2 + 2, nz // 2 + 2)
    parents = np.arange(coarse[0] * coarse[1] * coarse[2]).reshape(coarse)[1:-1, 1:-1, 1:-1]
    index = np.zeros(padded_shape, np.intp)
    index[1:-1, 1:-1, 1:-1] = parents.repeat(2, axis=0).repeat(2, axis=1).repeat(2, axis=2)
    return index.reshape(-1)


@dataclass
class _PackedLevels:
    """Every level's padded flat layout (:class:`_FlatLevel`) end to end in a few arrays, for the compiled solve
    (:func:`systems.toon_smoke.kernels.mgpcg_kernel`): one call takes these instead of a dozen arrays per level.
    Copies of the levels' arrays, with scratch vectors of their own (the numpy solve keeps its own)."""

    table: NDArray[np.int64]  # per level: offset in vectors, padded shape (3), offset in the span arrays, offset in
    # coefficients, whether the level is weighted (its coefficients are not None)
    vectors: F32  # (3, Σ P): each level's x, b and r (scratch)
    scratch: F32  # (Σ span): each level's s
    stencil: F32  # (5, Σ span): diag, red_inv_diag, black_inv_diag, keep_red, keep_black
    inactive: NDArray[np.bool_]  # (Σ span)
    parents: NDArray[np.intp]  # (Σ span): parent_index, into the next level's vector (0 on the coarsest level)
    coefficients: F32  # the (6, span) coefficient matrices of the weighted levels, flattened one after another
    dense_inverse: NDArray[np.float64]  # the coarsest level's
    dense_cells: NDArray[np.intp]


def _pack_levels(levels: list[Level]) -> _PackedLevels:
    """The levels' fields concatenated level after level (see :class:`_PackedLevels`)."""
    flats = [level.flat for level in levels]
    sizes = [flat.x.size for flat in flats]
    spans = [flat.s.size for flat in flats]
    table = np.zeros((len(flats), 7), np.int64)
    table[:, 0] = np.cumsum([0] + sizes[:-1])
    table[:, 1:4] = [flat.padded_shape for flat in flats]
    table[:, 4] = np.cumsum([0] + spans[:-1])
    weighted = [flat.coefficients is not None for flat in flats]
    table[:, 5] = np.cumsum([0] + [6 * n * w for n, w in zip(spans[:-1], weighted[:-1])])
    table[:, 6] = weighted
    parents = [np.zeros(n, np.intp) if flat.parent_index is None else flat.parent_index
               for flat, n in zip(flats, spans)]
    coefficients = [flat.coefficient_matrix.ravel() for flat in flats if flat.coefficients is not None]
    return _PackedLevels(
        table, np.zeros((3, sum(sizes)), np.float32), np.zeros(sum(spans), np.float32),
        np.stack([np.concatenate([getattr(flat, name) for flat in flats])
                  for name in ("diag", "red_inv_diag", "black_inv_diag", "keep_red", "keep_black")]),
        np.concatenate([flat.inactive for flat in flats]), np.concatenate(parents),
        np.concatenate([np.zeros(0, np.float32)] + coefficients), levels[-1].dense_inverse, levels[-1].dense_cells)


@dataclass
class PoissonHierarchy:
    """The multigrid levels for one solid mask (rebuilt when obstacles change)."""

    levels: list[Level] = field(default_factory=list)
    singular: bool = False  # no open boundary: M has the constants in its null space
    fluid_weight: F32 | None = None  # 1 in fluid cells, 0 in solid cells (fine level)
    packed: _PackedLevels | None = None  # the levels for the compiled solve (:func:`solve`)


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
    flat = _flat_level((nx, ny, nz), tuple(neighbours), diag, (inv_diag * red).astype(f32),
                       (inv_diag * black).astype(f32), (~red).astype(f32), (~black).astype(f32), active)
    return Level((nx, ny, nz), np.ascontiguousarray(ax[1:-1]), np.ascontiguousarray(ay[:, 1:-1]),
                 np.ascontiguousarray(az[:, :, 1:-1]), (ax, ay, az), tuple(neighbours), diag, inv_diag.astype(f32),
                 red, black, active, flat)


def _flat_level(shape: tuple[int, int, int], neighbours: tuple[F32, ...], diag: F32, red_inv_diag: F32,
                black_inv_diag: F32, keep_red: F32, keep_black: F32, active: NDArray[np.bool_]) -> _FlatLevel:
    """Cell fields of one level in the padded flat layout (ghosts: zero coefficients, keep 1, inactive).

    The neighbour coefficients are dropped (``coefficients=None``) when every product A_f·φ_nb equals φ_nb
    exactly: A_f = 1, or A_f = 0 towards a ghost or an inactive cell, both of which hold φ = 0 (or this cell is
    inactive, where the sum is never used).  That is every fine level (faces are 0 or 1, inactive cells are solid)
    and every coarse level without obstacles; the stencil is then five additions instead of six products and five
    additions, with the same bits.
    """
    nx, ny, nz = shape
    padded_shape = (nx + 2, ny + 2, nz + 2)
    size = padded_shape[0] * padded_shape[1] * padded_shape[2]
    sy, sx = nz + 2, (ny + 2) * (nz + 2)
    span = slice(sx, size - sx)

    def to_span(values, fill=0.0, dtype=np.float32):
        out = np.full(padded_shape, fill, dtype)
        out[1:-1, 1:-1, 1:-1] = values
        return out.reshape(-1)[span].copy()

    active_span = to_span(active, False, bool)
    offsets = (-sx, sx, -sy, sy, -1, 1)
    padded_active = np.zeros(size, bool)
    padded_active.reshape(padded_shape)[1:-1, 1:-1, 1:-1] = active
    exact = True
    coefficients = tuple(to_span(c) for c in neighbours)
    for c, offset in zip(coefficients, offsets):  # loop over the six neighbours
        neighbour_active = padded_active[sx + offset:size - sx + offset]
        exact &= bool(np.all((c == 1.0) | ((c == 0.0) & ~(active_span & neighbour_active))))
    return _FlatLevel(padded_shape, offsets, span, None if exact else coefficients, to_span(diag),
                      to_span(red_inv_diag), to_span(black_inv_diag), to_span(keep_red, 1.0),
                      to_span(keep_black, 1.0), active_span, ~active_span, np.zeros(size, np.float32),
                      np.zeros(size, np.float32), np.zeros(size, np.float32), np.zeros(size - 2 * sx, np.float32),
                      np.zeros(size - 2 * sx, np.float32))


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


def _pseudo_inverse(matrix: NDArray[np.float64]) -> NDArray[np.float64]:
    """pinv(M) of the coarsest level's operator with the same bits on every CPU.

    ``np.linalg.pinv`` runs LAPACK's SVD through OpenBLAS, whose kernels are chosen by the CPU: its last bits
    differed between ``OPENBLAS_CORETYPE`` settings on one machine. M is symmetric, each row's sum is its
    open-boundary faces' coefficients (faces towards inactive cells are 0), and the connected groups of active
    cells (faces > 0) that touch no open face have the constants on them as null space, the others none. With U
    the orthonormal basis of those constants, pinv(M) = (M + U Uᵀ)⁻¹ − U Uᵀ; the inverse is Gauss–Jordan
    elimination with partial pivoting in numpy's element-wise arithmetic (no BLAS, no fused multiply-adds).
    """
    n = matrix.shape[0]
    group = list(range(n))  # union-find over the faces between active cells

    def root(i: int) -> int:
        while group[i] != i:
            group[i] = group[group[i]]
            i = group[i]
        return i

    for i, j in zip(*np.nonzero(np.triu(matrix, 1))):
        group[root(int(i))] = root(int(j))
    roots = np.array([root(i) for i in range(n)])
    open_rows = matrix.sum(axis=1) > 1e-9 * np.abs(np.diagonal(matrix))
    null = np.zeros((n, n))
    for r in np.unique(roots):
        members = roots == r
        if not open_rows[members].any():
            null[np.ix_(members, members)] = 1.0 / members.sum()
    work = np.concatenate([matrix + null, np.eye(n)], axis=1)
    for k in range(n):
        pivot = k + int(np.argmax(np.abs(work[k:, k])))
        if pivot != k:
            work[[k, pivot]] = work[[pivot, k]]
        work[k] = work[k] / work[k, k]
        factors = work[:, k].copy()
        factors[k] = 0.0
        work -= factors[:, None] * work[k][None, :]
    return work[:, n:] - null


def build_hierarchy(solid: NDArray[np.bool_], open_faces: tuple[bool, ...]) -> PoissonHierarchy:
    """Levels from the fine solid mask down to :func:`components.toon_smoke.coarsest_shape` (≤ 64 cells unless a
    side turns odd or drops below 4 first; the config refuses grids whose coarsest level exceeds
    ``MAX_COARSEST_CELLS``, whose dense inverse would take seconds to build)."""
    level = _make_level(*face_coefficients(solid, tuple(open_faces)))
    levels = [level]
    coarsest = coarsest_shape(solid.shape)
    while level.shape != coarsest:
        level = _coarsen(level)
        levels.append(level)
    if np.prod(level.shape) > MAX_COARSEST_CELLS:
        raise ValueError(f"grid {levels[0].shape} halves only down to {level.shape}: keep the sides within a factor "
                         "of 8 of each other")
    level.dense_inverse = _pseudo_inverse(_dense_operator(level)) if level.active.any() else np.zeros((0, 0))
    padded_index = np.arange(level.flat.x.size).reshape(level.flat.padded_shape)[1:-1, 1:-1, 1:-1]
    level.dense_cells = padded_index[level.active]  # C order, as the rows of the dense operator
    return PoissonHierarchy(levels, singular=not any(open_faces), fluid_weight=(~solid).astype(np.float32),
                            packed=_pack_levels(levels))


def _neighbour_sum(flat: _FlatLevel) -> F32:
    """Σ_f A_f φ_nb(f) over the span of the level's iterate ``flat.x`` (ghosts hold 0), in the order −x, +x, −y, +y,
    −z, +z; written into (and returned as) ``flat.s``."""
    s, views = flat.s, flat.x_neighbours
    if flat.coefficients is None:
        np.add(views[0], views[1], out=s)
        for view in views[2:]:  # loop over the stencil's terms, each one call over the whole grid
            s += view
        return s
    np.multiply(flat.coefficients[0], views[0], out=s)
    for coefficient, view in zip(flat.coefficients[1:], views[1:]):  # loop over the stencil's terms
        np.multiply(coefficient, view, out=flat.t)
        s += flat.t
    return s


def apply_operator(level: Level, phi: F32) -> F32:
    """M φ = diag·φ − Σ_f A_f φ_nb (zero on inactive cells), for a compact (nx, ny, nz) field."""
    flat = level.flat
    flat.x_interior[...] = phi
    out = flat.r_span
    np.multiply(flat.diag, flat.x_span, out=out)
    out -= _neighbour_sum(flat)
    if flat.coefficients is None:  # the plain sum is not zero on inactive cells; A·φ_nb would have been
        np.copyto(out, np.float32(0.0), where=flat.inactive)
    return flat.r_interior.copy()


def _pre_smooth(flat: _FlatLevel) -> None:
    """Pre-smoothing from φ = 0, in place on ``flat.x``: the first red half sweep (no neighbours to sum), black,
    then _SMOOTH_SWEEPS − 1 more (red, black) pairs; one compiled call
    (:func:`systems.toon_smoke.kernels.pre_smooth_kernel`), the same bits as :func:`_pre_smooth_numpy`."""
    from systems.toon_smoke.kernels import pre_smooth_kernel

    pre_smooth_kernel(*flat.smoother)


def _post_smooth(flat: _FlatLevel, coarse: _FlatLevel) -> None:
    """Piecewise-constant prolongation (each coarse value added to its 8 children, the adjoint of the restriction;
    0 on inactive cells), then _SMOOTH_SWEEPS (black, red) pairs; one compiled call
    (:func:`systems.toon_smoke.kernels.post_smooth_kernel`), the same bits as :func:`_post_smooth_numpy`."""
    from systems.toon_smoke.kernels import post_smooth_kernel

    post_smooth_kernel(*flat.smoother, coarse.x, flat.parent_index, flat.inactive)


def _pre_smooth_numpy(flat: _FlatLevel) -> None:
    """:func:`_pre_smooth` in numpy (its reference)."""
    np.multiply(flat.red_inv_diag, flat.b_span, out=flat.x_span)
    _half_sweep_numpy(flat, flat.keep_black, flat.black_inv_diag)
    for _ in range(_SMOOTH_SWEEPS - 1):
        _half_sweep_numpy(flat, flat.keep_red, flat.red_inv_diag)
        _half_sweep_numpy(flat, flat.keep_black, flat.black_inv_diag)


def _post_smooth_numpy(flat: _FlatLevel, coarse: _FlatLevel) -> None:
    """:func:`_post_smooth` in numpy (its reference): one gather of each cell's parent (0 for ghosts), one
    contiguous addition over the span."""
    x = flat.x_span
    x += coarse.x.take(flat.parent_index)
    np.copyto(x, np.float32(0.0), where=flat.inactive)
    for _ in range(_SMOOTH_SWEEPS):
        _half_sweep_numpy(flat, flat.keep_black, flat.black_inv_diag)
        _half_sweep_numpy(flat, flat.keep_red, flat.red_inv_diag)


def _residual(flat: _FlatLevel) -> F32:
    """b − M x on active cells, 0 elsewhere, into ``flat.r_span`` (compiled,
    :func:`systems.toon_smoke.kernels.residual_kernel`; the same bits as :func:`_residual_numpy`)."""
    from systems.toon_smoke.kernels import residual_kernel

    residual_kernel(flat.x, flat.b_span, flat.diag, flat.inactive, flat.offsets[1], flat.offsets[3],
                    flat.coefficient_matrix, flat.coefficients is not None, flat.span.start, flat.r_span)
    return flat.r_span


def _residual_numpy(flat: _FlatLevel) -> F32:
    """b − M x on active cells, 0 elsewhere, into ``flat.r_span`` (numpy; the reference of :func:`_residual`)."""
    residual = flat.r_span
    np.multiply(flat.diag, flat.x_span, out=residual)
    residual -= _neighbour_sum(flat)
    np.subtract(flat.b_span, residual, out=residual)
    np.copyto(residual, np.float32(0.0), where=flat.inactive)
    return residual


def _half_sweep_numpy(flat: _FlatLevel, keep: F32, scale: F32) -> None:
    """One colour of red–black Gauss–Seidel, in place on ``flat.x``: φ ← keep·φ + inv_diag_colour·(b + Σ A φ_nb),
    an arithmetic blend (no boolean scatter); the other colour's cells and inactive cells keep their value."""
    s = _neighbour_sum(flat)
    np.add(flat.b_span, s, out=s)
    np.multiply(scale, s, out=s)
    x = flat.x_span
    np.multiply(keep, x, out=x)
    np.add(x, s, out=x)


def _restrict_into(fine: _FlatLevel, coarse: _FlatLevel) -> None:
    """Coarse right-hand side from the fine residual ``fine.r``: 4 × the mean of the 8 children (the (2h)²/h²
    scaling of the 7-point Laplacian), written into the coarse level's ``b``; compiled
    (:func:`systems.toon_smoke.kernels.restrict_kernel`), the same bits as :func:`_restrict_numpy`."""
    from systems.toon_smoke.kernels import restrict_kernel

    restrict_kernel(fine.r_interior, coarse.b_interior)


def _restrict_numpy(fine: _FlatLevel, coarse: _FlatLevel) -> None:
    """:func:`_restrict_into` in numpy (its reference)."""
    r = fine.r_interior
    s = r[0::2] + r[1::2]
    s = s[:, 0::2] + s[:, 1::2]
    out = coarse.b_interior
    np.add(s[:, :, 0::2], s[:, :, 1::2], out=out)
    out *= np.float32(0.5)


def _v_cycle(levels: list[Level], depth: int) -> None:
    """One symmetric V-cycle from ``flat.b`` of level ``depth`` into its ``flat.x`` (levels below are scratch)."""
    level = levels[depth]
    flat = level.flat
    if level.dense_inverse is not None:
        cells = level.dense_cells  # inactive cells of this level's x are never written: they stay 0
        # multiply-and-sum rather than BLAS matvec: numpy's pairwise sum gives the same bits on every CPU
        flat.x[cells] = (level.dense_inverse * flat.b[cells].astype(np.float64)[None, :]).sum(axis=1).astype(
            np.float32)
        return
    _pre_smooth(flat)
    _residual(flat)  # b − M x on active cells, 0 elsewhere
    coarse = levels[depth + 1].flat
    _restrict_into(flat, coarse)
    _v_cycle(levels, depth + 1)
    _post_smooth(flat, coarse)


def v_cycle(hierarchy: PoissonHierarchy, b: F32) -> F32:
    """One symmetric V-cycle approximating M⁻¹ b (a symmetric positive preconditioner for CG): red–black
    Gauss–Seidel pre- and post-smoothing, the residual restricted to the next level down, a dense solve on the
    coarsest level, the correction prolonged back."""
    flat = hierarchy.levels[0].flat
    flat.b_interior[...] = b
    _v_cycle(hierarchy.levels, 0)
    return flat.x_interior.copy()


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
    preconditioned residual are made zero-mean so the iteration stays in the range of M.  The whole iteration is
    one compiled call (:func:`systems.toon_smoke.kernels.mgpcg_kernel` on the packed levels), the same bits as
    :func:`solve_numpy`.
    """
    from systems.toon_smoke.kernels import mgpcg_kernel

    if hierarchy.packed is None:  # a hierarchy not made by build_hierarchy
        hierarchy.packed = _pack_levels(hierarchy.levels)
    packed = hierarchy.packed
    x, iterations, residual, rhs = mgpcg_kernel(
        b, b if x0 is None else x0, x0 is not None, hierarchy.levels[0].active, hierarchy.singular,
        float(tolerance), int(max_iterations), np.getbufsize(), packed.table, packed.vectors, packed.scratch,
        packed.stencil, packed.inactive, packed.parents, packed.coefficients, packed.dense_inverse,
        packed.dense_cells, _SMOOTH_SWEEPS)
    return x, SolveReport(int(iterations), float(residual), float(rhs))


def solve_numpy(hierarchy: PoissonHierarchy, b: F32, x0: F32 | None = None, tolerance: float = 1e-4,
                max_iterations: int = 30) -> tuple[F32, SolveReport]:
    """:func:`solve` as separate calls (its reference): per iteration the operator, two dot products, max|r|, a
    V-cycle (per level its compiled smoothing, residual and restriction; the dense solve), the zero-mean projection
    and the vector updates, each a numpy or compiled call."""
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
