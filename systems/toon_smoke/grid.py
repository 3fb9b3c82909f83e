"""Grid geometry and interpolation shared by the fluid, the particles and the display grid (pure numpy).

Index conventions (all arrays [x, y, z]):
* a cell-centred field of n cells has its sample i at i + ½ cell units from the box's low corner;
* the MAC velocity u lives on x-faces (nx+1, ny, nz) at (i, j+½, k+½), v on y-faces, w on z-faces;
* "cell units" measure positions from the box's low corner in simulation cells; local metres are
  ``cell units · h − extent/2``.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

F32 = NDArray[np.float32]


@dataclass
class Trilinear:
    """Corners and weights of trilinear interpolation at many points of one grid shape (reused per field)."""

    corners: NDArray[np.intp]  # (8, N) flat indices of the corners (x, y, z bits: 000, 001, 010, … 111)
    fx: F32  # (N,) fractions along x, y, z
    fy: F32
    fz: F32
    shape: tuple[int, ...]  # the shape of the points (of each result)

    def gather(self, values: F32) -> F32:
        """Interpolate ``values`` (the grid shape given to :func:`trilinear_weights`) at the points (float32 values
        and weights blend in place in the gathered corners)."""
        c = values.ravel().take(self.corners)
        if c.dtype == np.float32 and self.fx.dtype == np.float32:
            return _blend_in_place(c, self.fx, self.fy, self.fz).reshape(self.shape)
        return _blend(c, self.fx, self.fy, self.fz).reshape(self.shape)

    def gather_many(self, fields: list[F32]) -> list[F32]:
        """:meth:`gather` for several fields of the same grid (the corners and weights computed once; one gather
        per field is cheaper than one gather from the fields stacked)."""
        return [self.gather(f) for f in fields]


def _blend(c: NDArray, fx: NDArray, fy: NDArray, fz: NDArray) -> NDArray:
    """Lerp the corner values (…, 8, N) along z, then y, then x: the same operations, in the same order, as
    c00 = v000 + (v001 − v000)·fz, …, c0 = c00 + (c01 − c00)·fy, …, c0 + (c1 − c0)·fx."""
    lo, hi = c[..., 0::2, :], c[..., 1::2, :]
    c = lo + (hi - lo) * fz
    lo, hi = c[..., 0::2, :], c[..., 1::2, :]
    c = lo + (hi - lo) * fy
    lo, hi = c[..., 0, :], c[..., 1, :]
    return lo + (hi - lo) * fx


def _blend_in_place(c: F32, fx: F32, fy: F32, fz: F32) -> F32:
    """:func:`_blend` of a float32 (8, N) buffer with float32 weights, in place on the buffer (it is scratch):
    hi −= lo, hi ·= f, hi += lo is lo + (hi − lo)·f with the same roundings (addition commutes bit for bit).
    Returns a new (N,) array."""
    for f in (fz, fy):  # the z, then the y lerps
        lo, hi = c[0::2], c[1::2]
        hi -= lo
        hi *= f
        hi += lo
        c = hi
    lo, hi = c[0], c[1]
    hi -= lo
    hi *= fx
    return np.add(hi, lo)


_BOUNDS: dict[tuple[int, int, int], tuple] = {}


def _bounds(shape: tuple[int, int, int]) -> tuple:
    """Per grid shape: (3, 1) upper coordinate bounds (float32, float64), (3, 1) largest base index, corner offsets."""
    if shape not in _BOUNDS:
        nx, ny, nz = shape
        upper = np.array([[nx - 1.0], [ny - 1.0], [nz - 1.0]])
        sx, sy = ny * nz, nz
        corners = np.array([0, 1, sy, sy + 1, sx, sx + 1, sx + sy, sx + sy + 1], np.intp)[:, None]
        _BOUNDS[shape] = (upper.astype(np.float32), upper, np.array([[nx - 2], [ny - 2], [nz - 2]], np.intp),
                          np.array([sx, sy, 1], np.intp)[:, None], corners)
    return _BOUNDS[shape]


def trilinear_points(shape: tuple[int, int, int], points: NDArray) -> Trilinear:
    """Weights to sample a grid of ``shape`` at index-space coordinates ``points`` (3, …), clamped to the grid.

    Clamping the coordinates (not the result) makes a back-trace that leaves the box read the boundary value, as
    in Stam's clamped semi-Lagrangian advection.  float32 points give float32 weights, others float64.
    """
    points = np.asarray(points)
    upper32, upper64, last, strides, corners = _bounds(tuple(shape))
    float32 = points.dtype == np.float32
    c = np.maximum(points.reshape(3, -1), 0.0)  # = np.clip (NaN included), without its wrapper's cost
    np.minimum(c, upper32 if float32 else upper64, out=c)
    i = c.astype(np.intp)
    np.minimum(i, last, out=i)
    fractions = np.float32 if float32 else np.float64
    f = np.subtract(c, i.astype(fractions), out=c if c.dtype == fractions else None)  # in c's buffer
    i *= strides
    base = i[0] + i[1]
    base += i[2]
    return Trilinear(base + corners, f[0], f[1], f[2], points.shape[1:])


def trilinear_weights(shape: tuple[int, int, int], x: F32, y: F32, z: F32) -> Trilinear:
    """:func:`trilinear_points` with the coordinates given one axis at a time."""
    return trilinear_points(shape, np.stack(np.broadcast_arrays(x, y, z)))


def sample(values: F32, x: F32, y: F32, z: F32) -> F32:
    """Trilinear interpolation of ``values`` at index-space coordinates (clamped)."""
    return trilinear_weights(values.shape, x, y, z).gather(values)


_STAGGER = {name: np.array(offset)[:, None] for name, offset in
            (("u", (0.0, 0.5, 0.5)), ("v", (0.5, 0.0, 0.5)), ("w", (0.5, 0.5, 0.0)))}


def sample_mac(u: F32, v: F32, w: F32, px: F32, py: F32, pz: F32) -> tuple[F32, F32, F32]:
    """Velocity at points given in cell units: each component from its own staggered grid."""
    return sample_mac_points(u, v, w, np.stack(np.broadcast_arrays(px, py, pz)))


def sample_mac_points(u: F32, v: F32, w: F32, points: NDArray) -> tuple[F32, F32, F32]:
    """:func:`sample_mac` at points (3, …) in cell units."""
    return MacSampler(u, v, w).sample(points)


class MacSampler:
    """Samples a MAC velocity (u, v, w on their staggered grids) at many points, the three components in one pass.

    The three face grids are laid end to end in one flat vector (copied once per sampler, so a sampler serves every
    query of a step), and each component's corners index into it with the grid's offset: one clamp, one floor, one
    gather and one blend for all three components instead of one each.  Every element sees the same operations, in
    the same order and precision, as :func:`trilinear_points` per component, so the values have the same bits.
    """

    def __init__(self, u: F32, v: F32, w: F32) -> None:
        self.values = np.concatenate((u.reshape(-1), v.reshape(-1), w.reshape(-1)))
        self.tables = _mac_tables(u.shape, v.shape, w.shape)

    def sample(self, points: NDArray) -> tuple[NDArray, NDArray, NDArray]:
        """(u, v, w) at points (3, …) in cell units (float32 points give float32 results, others float64)."""
        points = np.asarray(points)
        stagger, upper32, upper64, last, strides, corners = self.tables
        float32 = points.dtype == np.float32
        # (component, axis, point) coordinates in each component's index space, clamped to its grid
        c = np.subtract(points.reshape(1, 3, -1), stagger.astype(points.dtype, copy=False))
        np.maximum(c, 0.0, out=c)  # = np.clip (NaN included), without its wrapper's cost
        np.minimum(c, upper32 if float32 else upper64, out=c)
        i = c.astype(np.intp)
        np.minimum(i, last, out=i)
        f = c - i.astype(np.float32 if float32 else np.float64)
        i *= strides
        base = i[:, 0] + i[:, 1]
        base += i[:, 2]
        out = _blend(self.values.take(base[:, None, :] + corners), f[:, 0], f[:, 1, None, :], f[:, 2, None, :])
        return tuple(out[k].reshape(points.shape[1:]) for k in range(3))


_MAC_TABLES: dict[tuple, tuple] = {}


def _mac_tables(*shapes: tuple[int, int, int]) -> tuple:
    """Per (u, v, w) shapes: staggers (3, 3, 1), upper bounds (float32, float64), largest base index and strides
    (3, 3, 1), and the corner offsets of each component (3, 8, 1) including its grid's start in the joint vector."""
    key = tuple(tuple(s) for s in shapes)
    if key not in _MAC_TABLES:
        bounds = [_bounds(s) for s in key]
        start = np.cumsum([0] + [int(np.prod(s)) for s in key[:-1]])
        stagger = np.stack([_STAGGER[name] for name in "uvw"])
        _MAC_TABLES[key] = (stagger, np.stack([b[0] for b in bounds]), np.stack([b[1] for b in bounds]),
                            np.stack([b[2] for b in bounds]), np.stack([b[3] for b in bounds]),
                            np.stack([b[4] + s for b, s in zip(bounds, start)]))
    return _MAC_TABLES[key]


def upsample_linear(values: F32, factor: int) -> F32:
    """Trilinear upsampling of a cell-centred grid by an integer factor (separable, one axis at a time).

    Fine cell i sits at (i + ½)/factor − ½ coarse cells; the coarse field is clamped at the borders.  Used to copy
    the simulation grid onto the display grid each step (seeds/002 §3.2).
    """
    if factor == 1:
        return values.copy()
    out = values
    for axis in range(3):
        n = out.shape[axis]
        i0, t = _axis_weights(n, factor)
        shape = [1, 1, 1]
        shape[axis] = -1
        a = np.take(out, i0, axis=axis)
        if n == 1:  # a single sample (i1 = i0 = 0): a + (a − a)·t, as the general formula gives
            out = a + (a - a) * t.reshape(shape)
            continue
        # b − a with b the sample after a (i1 = i0 + 1 always): the coarse differences, taken like a (the same
        # subtractions, done once per coarse pair instead of once per fine cell); then a + (b − a)·t in place
        lo, hi = [slice(None)] * 3, [slice(None)] * 3
        lo[axis], hi[axis] = slice(0, -1), slice(1, None)
        d = np.take(out[tuple(hi)] - out[tuple(lo)], i0, axis=axis)
        d *= t.reshape(shape)
        d += a
        out = d
    return out


_AXIS_CACHE: dict[tuple[int, int], tuple[NDArray[np.intp], F32]] = {}


def _axis_weights(n: int, factor: int) -> tuple[NDArray[np.intp], F32]:
    """Per fine cell along one axis: the coarse sample below it (clamped to [0, n − 2], so the one above is always
    i0 + 1) and the lerp weight t."""
    key = (n, factor)
    if key not in _AXIS_CACHE:
        pos = (np.arange(n * factor) + 0.5) / factor - 0.5
        pos = np.clip(pos, 0.0, n - 1.0)
        i0 = np.minimum(np.floor(pos).astype(np.intp), max(n - 2, 0))
        _AXIS_CACHE[key] = (i0, (pos - i0).astype(np.float32))
    return _AXIS_CACHE[key]


@dataclass
class Geometry:
    """Coordinates and masks of one volume config, built once (derived from the config, not state)."""

    shape: tuple[int, int, int]
    display_shape: tuple[int, int, int]
    factor: int
    h: float  # simulation cell size, metres
    extent: NDArray[np.float64]
    centres: tuple[F32, F32, F32]  # cell-centre coordinates in cell units, broadcastable (n,1,1) / (1,n,1) / (1,1,n)
    faces_1d: tuple[F32, F32, F32]  # face coordinates per axis (n+1) in cell units
    centres_1d: tuple[F32, F32, F32]  # centre coordinates per axis (n) in cell units
    backtrace_bases: dict[str, F32] = field(default_factory=dict)  # (3, …) sample coordinates of u, v, w, c grids
    _sphere_masks: dict = field(default_factory=dict, repr=False)  # see sphere_mask

    @classmethod
    def build(cls, shape: tuple[int, int, int], factor: int, extent) -> Geometry:
        extent = np.asarray(extent, float)
        h = float(extent[0] / shape[0])
        centres_1d = tuple((np.arange(n) + 0.5).astype(np.float32) for n in shape)
        faces_1d = tuple(np.arange(n + 1).astype(np.float32) for n in shape)
        centres = tuple(c.reshape([-1 if a == i else 1 for a in range(3)]) for i, c in enumerate(centres_1d))
        g = cls(tuple(shape), tuple(n * factor for n in shape), int(factor), h, extent, centres, faces_1d,
                centres_1d)
        g.backtrace_bases = {name: np.stack(g._full_grid(name)) for name in ("u", "v", "w", "c")}
        return g

    def _full_grid(self, name: str) -> tuple[F32, F32, F32]:
        """Dense coordinates (cell units) of every sample of the u / v / w faces or of the cell centres."""
        axes = list(self.centres_1d)
        if name != "c":
            a = "uvw".index(name)
            axes[a] = self.faces_1d[a]
        grids = np.meshgrid(*axes, indexing="ij")
        return tuple(np.ascontiguousarray(g, dtype=np.float32) for g in grids)

    def sphere_mask(self, grid: str, centre, radius: float) -> NDArray[np.bool_]:
        """Samples of the cell centres (``"c"``) or of the u / v / w faces strictly inside a sphere (local metres).

        Sources test the same spheres every step: the last few masks are kept (read-only) per grid, centre and
        radius.
        """
        key = (grid, tuple(float(c) for c in centre), float(radius))
        mask = self._sphere_masks.get(key)
        if mask is None:
            x, y, z = self.local_centres() if grid == "c" else self.local_faces("uvw".index(grid))
            mask = (x - centre[0]) ** 2 + (y - centre[1]) ** 2 + (z - centre[2]) ** 2 < radius ** 2
            mask.flags.writeable = False
            if len(self._sphere_masks) >= 32:  # scripts may move sources every step: keep the cache small
                self._sphere_masks.clear()
            self._sphere_masks[key] = mask
        return mask

    # -- conversions between local metres and cell units
    def to_cells(self, local: NDArray[np.float64]) -> NDArray[np.float64]:
        return (local + 0.5 * self.extent) / self.h

    def to_local(self, cells: NDArray[np.float64]) -> NDArray[np.float64]:
        return cells * self.h - 0.5 * self.extent

    def local_centres(self) -> tuple[NDArray[np.float64], ...]:
        """Cell-centre coordinates in local metres, broadcastable per axis."""
        return tuple(c.astype(np.float64) * self.h - 0.5 * e for c, e in zip(self.centres, self.extent))

    def local_display_centres(self) -> tuple[NDArray[np.float64], ...]:
        """Display-cell-centre coordinates in local metres, broadcastable per axis."""
        hd = self.h / self.factor
        out = []
        for axis, (n, e) in enumerate(zip(self.display_shape, self.extent)):
            c = (np.arange(n) + 0.5) * hd - 0.5 * e
            out.append(c.reshape([-1 if a == axis else 1 for a in range(3)]))
        return tuple(out)

    def local_faces(self, axis: int) -> tuple[NDArray[np.float64], ...]:
        """Coordinates (local metres, broadcastable) of the faces normal to ``axis``."""
        out = []
        for a in range(3):
            c = self.faces_1d[a] if a == axis else self.centres_1d[a]
            c = c.astype(np.float64) * self.h - 0.5 * self.extent[a]
            out.append(c.reshape([-1 if b == a else 1 for b in range(3)]))
        return tuple(out)
