"""The display grid of seeds/002: density blobs from particles (§3.3, figure 2), Perlin noise (§3.4), the marching
cubes isosurface and its toon-ramp coordinate (§3.5).  Pure numpy (and scikit-image's marching cubes).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from engine.noise import PerlinNoise
from systems.toon_smoke.grid import F32, Geometry

__all__ = [
    "blob_axes",
    "extract_isosurface",
    "noise_factor",
    "splat_blobs",
    "splat_blobs_numpy",
    "toon_coordinate",
]

_SPLAT_CHUNK = 1_500_000  # particle × stencil entries per vectorized batch (bounds temporary memory)


def blob_axes(density_at_particle: NDArray[np.float64], speed: NDArray[np.float64], threshold: float,
              radius: float, radius_per_density: float, radius_max: float, stretch: float, stretch_max: float
              ) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Semi-axes of each blob ellipsoid (figure 2): (along the velocity, across it), in metres.

    The sphere radius grows with the local density, R = min(R_max, R₀ + dR/dρ·(ρ − D_p)); the blob is stretched
    along u by s = min(s_max, 1 + k·|u|) and thinned across by √s so that its volume stays that of the sphere:
    a = R·s, b = R/√s (a/b = s^{3/2}).
    """
    r = np.minimum(radius_max, radius + radius_per_density * np.maximum(density_at_particle - threshold, 0.0))
    s = np.minimum(stretch_max, 1.0 + stretch * speed)
    return r * s, r / np.sqrt(s)


def splat_blobs(target: F32, centres: NDArray[np.float64], directions: NDArray[np.float64],
                along: NDArray[np.float64], across: NDArray[np.float64], amplitude: float) -> int:
    """Add one ellipsoidal density blob per particle to ``target`` (in place): figure 2, seeds/002, as one compiled
    loop (:func:`systems.toon_smoke.kernels.splat_blobs_kernel`); :func:`splat_blobs_numpy` is the same sum in
    numpy (the kernel's reference in the tests).  Returns the number of blobs added."""
    if len(centres) == 0 or amplitude == 0.0:
        return 0
    from systems.toon_smoke.kernels import splat_blobs_kernel

    f64 = np.float64
    return int(splat_blobs_kernel(target, np.ascontiguousarray(centres, f64), np.ascontiguousarray(directions, f64),
                                  np.ascontiguousarray(along, f64), np.ascontiguousarray(across, f64),
                                  float(amplitude)))


def splat_blobs_numpy(target: F32, centres: NDArray[np.float64], directions: NDArray[np.float64],
                      along: NDArray[np.float64], across: NDArray[np.float64], amplitude: float) -> int:
    """Add one ellipsoidal density blob per particle to ``target`` (in place), without a Python loop per particle.

    ``centres`` are in the target's index space (cell i's centre at i), ``directions`` unit stretch axes, ``along``
    and ``across`` the semi-axes in cells.  Each blob adds amplitude·(1 − q²)³ where
    q² = (d·û)²/a² + (|d|² − (d·û)²)/b² < 1 (a smooth, compactly supported bump).  Particles are grouped by the
    stencil radius they need (⌈a⌉ cells, at most a handful of groups), each group is evaluated as one
    (particles × stencil) array (see :func:`_splat_group`) and scattered with an unbuffered ``np.add.at``
    (sequential in index order, so the sum repeats bit for bit) into a zeroed box that holds every stencil (the
    grid padded by the largest reach, cut to the blobs' extent), so no bounds test is needed; the box's part inside
    the grid is added back at the end.  Blobs centred more than one cell outside the grid are skipped (particles
    never are: they are reborn when they leave).  Returns the number of blobs added.

    The float32 operations are the compiled kernel's, in its order (products summed left to right, no BLAS; the
    offset from the rounded cell taken in the grid's own index space, before the padding), so the two give the
    same bits: this is the kernel's reference in the tests.
    """
    if len(centres) == 0 or amplitude == 0.0:
        return 0
    near = np.all((centres >= -1.0) & (centres <= np.array(target.shape)), axis=1)
    if not near.all():
        centres, directions, along, across = centres[near], directions[near], along[near], across[near]
        if len(centres) == 0:
            return 0
    reach = np.maximum(np.ceil(along).astype(np.int64), 1)
    pad = int(reach.max()) + 2
    centres = centres.astype(np.float32)  # the kernel's float32 centres, in the grid's index space
    # Only the box the stencils can reach is allocated and added back: the rounded centre cell of each blob (as in
    # _splat_group) ± its reach, in the index space of the grid padded by ``pad`` cells on every side.  Cells
    # outside it would only have received + 0.
    base = np.rint(centres).astype(np.intp) + pad
    lo = (base - reach[:, None]).min(axis=0)
    hi = (base + reach[:, None]).max(axis=0) + 1
    shape = tuple(int(n) for n in hi - lo)
    box = np.zeros(shape, np.float32)
    flat = box.reshape(-1)
    for r in np.unique(reach):  # loop over stencil sizes, each vectorized over its particles
        members = np.flatnonzero(reach == r)
        stencil = _stencil(int(r), shape)
        batch = max(1, _SPLAT_CHUNK // len(stencil[0]))
        for start in range(0, len(members), batch):
            sel = members[start:start + batch]
            _splat_group(flat, shape, lo - pad, centres[sel], directions[sel], along[sel], across[sel], stencil,
                         amplitude)
    start = np.maximum(lo, pad)  # the part of the box inside the target (target cell i is padded cell i + pad)
    stop = np.minimum(hi, np.array(target.shape) + pad)
    if np.all(stop > start):
        target[tuple(slice(a - pad, b - pad) for a, b in zip(start, stop))] += box[
            tuple(slice(a - o, b - o) for a, b, o in zip(start, stop, lo))]
    return len(centres)


_STENCILS: dict[tuple, tuple[NDArray[np.intp], NDArray[np.float32], NDArray[np.float32]]] = {}


def _stencil(reach: int, shape: tuple[int, ...]) -> tuple[NDArray[np.intp], NDArray[np.float32], NDArray[np.float32]]:
    """The cells whose centre can lie within ``reach`` of a point rounded to a cell centre: their flat index offsets
    in a grid of ``shape`` (S,), their (x, y, z) offsets as float32 (3, S) and their squared lengths |o|² (S,)."""
    key = (reach, shape)
    if key not in _STENCILS:
        if len(_STENCILS) >= 64:  # the splat box changes shape with the smoke: keep the cache small
            _STENCILS.clear()
        r = np.arange(-reach, reach + 1)
        offsets = np.stack(np.meshgrid(r, r, r, indexing="ij"), axis=-1).reshape(-1, 3)
        offsets = offsets[(offsets * offsets).sum(axis=1) <= (reach + 0.87) ** 2]
        flat = (offsets[:, 0] * shape[1] + offsets[:, 1]) * shape[2] + offsets[:, 2]
        offsets_t = np.ascontiguousarray(offsets.T, dtype=np.float32)
        _STENCILS[key] = (flat.astype(np.intp), offsets_t, (offsets_t * offsets_t).sum(axis=0))
    return _STENCILS[key]


def _splat_group(flat: F32, shape: tuple[int, ...], origin: NDArray[np.intp], centres, directions, along, across,
                 stencil, amplitude) -> None:
    """One stencil size: q for every (particle, offset) pair, since with d = f + o (f the rounded cell's offset
    from the centre, o the stencil offset): d·û = f·û + o·û and |d|² = |f|² + 2 f·o + |o|².  Only the pairs
    inside the ellipsoid (q > 0) are finished.  ``centres`` are float32 in the grid's index space; ``flat`` is a
    box of ``shape`` whose cell 0 is the cell ``origin`` of that space.  Every product is summed left to right
    (x, y, z) in float32, as :func:`systems.toon_smoke.kernels.splat_blobs_kernel` does per pair."""
    offset_flat, offsets_t, offsets_sq = stencil
    ox, oy, oz = offsets_t[0], offsets_t[1], offsets_t[2]
    c = centres
    rounded = np.rint(c)
    base = rounded.astype(np.intp)
    f = rounded - c  # exact (Sterbenz): |f| ≤ ½
    a = directions.astype(np.float32)
    fa = f[:, 0] * a[:, 0] + f[:, 1] * a[:, 1] + f[:, 2] * a[:, 2]
    ff = f[:, 0] * f[:, 0] + f[:, 1] * f[:, 1] + f[:, 2] * f[:, 2]
    g = f + f  # 2·(f·o) as (2f)·o: doubling is exact, so the products have the same bits
    t = fa[:, None] + (a[:, 0, None] * ox + a[:, 1, None] * oy + a[:, 2, None] * oz)
    dist2 = ff[:, None] + (g[:, 0, None] * ox + g[:, 1, None] * oy + g[:, 2, None] * oz)
    dist2 += offsets_sq
    inv_a2 = (1.0 / along ** 2).astype(np.float32)[:, None]
    inv_b2 = (1.0 / across ** 2).astype(np.float32)[:, None]
    t *= t
    t *= inv_a2 - inv_b2
    dist2 *= inv_b2
    t += dist2  # 1 − q (q of the docstring of :func:`splat_blobs`)
    keep = np.flatnonzero(t < 1.0)  # q = 1 − that > 0 exactly where that < 1 (Sterbenz: 1 − x is exact there)
    q = 1.0 - t.reshape(-1)[keep]
    base -= origin
    base_flat = (base[:, 0] * shape[1] + base[:, 1]) * shape[2] + base[:, 2]
    index = (base_flat[:, None] + offset_flat).reshape(-1)[keep]
    np.add.at(flat, index, np.float32(amplitude) * q * q * q)


def noise_factor(geo: Geometry, seed: int, scale: float, strength: float, octaves: int) -> F32:
    """max(0, 1 + strength·fbm(x / scale)) at every display cell: a function of (local) position alone (§3.4).

    Uses the engine's shared improved Perlin noise (:class:`engine.noise.PerlinNoise`), in float64.
    """
    if strength == 0.0:
        return np.ones(geo.display_shape, np.float32)
    x, y, z = geo.local_display_centres()  # per-axis: the noise broadcasts them as late as it can (same values)
    n = PerlinNoise(seed).fbm3(x / scale, y / scale, z / scale, octaves=octaves)
    return np.maximum(0.0, 1.0 + strength * n).astype(np.float32)


def extract_isosurface(density: F32, iso: float, cell: float, origin: NDArray[np.float64]
                       ) -> tuple[F32, F32, NDArray[np.uint32]]:
    """Marching cubes (Lorensen & Cline 1987, Lewiner et al. 2003 topology) of ``density`` at D_iso (§3.5).

    scikit-image's ``measure.marching_cubes`` does the work on the bounding box of the cells above D_iso.  That box
    is padded with one layer of zeros so every surface is closed (watertight) even where the smoke touches the
    walls.  ``origin`` is the local position of cell
    (0, 0, 0)'s centre.  Returns vertices (local metres), unit outward normals (−∇ρ/|∇ρ|, interpolated from the
    central-difference gradient of the field) and counter-clockwise-outward triangles.
    """
    from skimage import measure

    empty = (np.zeros((0, 3), np.float32), np.zeros((0, 3), np.float32), np.zeros((0, 3), np.uint32))
    above = density > iso
    if not above.any():
        return empty
    # Crop to the cells above D_iso plus one cell of margin (below D_iso, so the crop cuts no surface), then pad
    # with zeros: the work of marching cubes follows the smoke, not the box.
    start = []
    crop = []
    for axis in range(3):
        rows = np.flatnonzero(above.any(axis=tuple(a for a in range(3) if a != axis)))
        lo, hi = max(int(rows[0]) - 1, 0), min(int(rows[-1]) + 2, density.shape[axis])
        start.append(lo)
        crop.append(slice(lo, hi))
    core = density[tuple(crop)]
    padded = np.zeros(tuple(n + 2 for n in core.shape), density.dtype)  # = np.pad(core, 1), without its wrapper
    padded[1:-1, 1:-1, 1:-1] = core
    verts, faces, normals, _ = measure.marching_cubes(padded, level=iso, spacing=(cell, cell, cell),
                                                      gradient_direction="descent", method="lewiner",
                                                      mask=surface_cells(padded, iso))
    verts = verts + (np.asarray(origin, np.float64) + (np.asarray(start) - 1) * cell)
    # skimage orders each triangle clockwise seen from the low-value side; flip to counter-clockwise outward.
    faces = faces[:, ::-1]
    return verts.astype(np.float32), normals.astype(np.float32), np.ascontiguousarray(faces, dtype=np.uint32)


def surface_cells(volume: F32, iso: float) -> NDArray[np.bool_]:
    """The cells marching cubes must visit: those whose eight corners are neither all above nor all below D_iso
    (a corner equal to D_iso counts as both), as scikit-image's ``mask`` (the volume's shape).

    The other cells make no triangles, and skipping them leaves the mesh exactly as it was (the same vertices,
    normals and triangles in the same order; tested).  On the demo's puff 60 steps in, about 2 000 of 39 000
    cells, and marching cubes 1.9 → 0.7 ms; over a puff's life, about a quarter less.  Each cell is marked at
    its low corner and at its high corner: scikit-image reads a cell's mask entry at one of the two, and marking
    both keeps the mesh whole whichever it is."""
    above, below = volume >= iso, volume <= iso
    lo, hi = slice(None, -1), slice(1, None)
    corners = [(a, b, c) for a in (lo, hi) for b in (lo, hi) for c in (lo, hi)]
    some_above = np.zeros(tuple(n - 1 for n in volume.shape), bool)
    some_below = np.zeros_like(some_above)
    for corner in corners:  # loop over the eight corners, each a whole-array operation
        some_above |= above[corner]
        some_below |= below[corner]
    crossing = some_above & some_below
    mask = np.zeros(volume.shape, bool)
    mask[:-1, :-1, :-1] = crossing
    mask[1:, 1:, 1:] |= crossing
    return mask


def toon_coordinate(view: NDArray, gradient: NDArray) -> NDArray:
    """Ramp coordinate c = (−v·g + 1)/2 of seeds/002 §3.5 (v: unit line of sight from the eye, g: unit density
    gradient).  Zero vectors give c = ½; the result is clamped to [0, 1] against rounding."""
    v = np.asarray(view, np.float64)
    g = np.asarray(gradient, np.float64)
    vn = np.linalg.norm(v, axis=-1, keepdims=True)
    gn = np.linalg.norm(g, axis=-1, keepdims=True)
    v = np.divide(v, vn, out=np.zeros_like(v), where=vn > 0)
    g = np.divide(g, gn, out=np.zeros_like(g), where=gn > 0)
    return np.clip((1.0 - (v * g).sum(axis=-1)) * 0.5, 0.0, 1.0)
