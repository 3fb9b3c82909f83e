"""Crawfis' tornado vector field (section 2.1 of seeds/004) on the field grid, and velocity lookup.

Two frames meet here:

* Crawfis' unit cube (cx, cy, cz), z up, in which ``gen_tornado`` is written;
* the field box in engine convention: field space is metres with the origin at the centre of the box's bottom
  face, +y up, x in [-Sx/2, Sx/2], y in [0, Sy], z in [-Sz/2, Sz/2].

They are related by the proper rotation cx = ux, cy = 1 - uz, cz = uy (u = the box's unit coordinates), so
"clockwise seen from above" means the same in both.  All trigonometry is float64 (determinism rule).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

from engine import exact

__all__ = ["crawfis_tornado", "centre_line", "wind_grid", "wind_at_nodes", "WindField",
           "lookup_nodes", "gather_wind", "sample_wind", "to_unit", "grid_points"]

F64 = NDArray[np.float64]
SMALL = 1e-11  # Crawfis' SMALL


def centre_line(cz: ArrayLike, t: float, rotation: float = 0.0) -> tuple[F64, F64]:
    """Vortex centre (xc, yc) of each z-slice, turned clockwise (seen from above) by ``rotation`` radians about
    the box's vertical axis (0.5, 0.5) (2.2, seeds/004):

        xc = 0.5 + 0.1 sin(0.04 t + 10 z),   yc = 0.5 + 0.1 cos(0.03 t + 3 z)
    """
    cz = np.asarray(cz, dtype=np.float64)
    ox = 0.1 * exact.sin(0.04 * t + 10.0 * cz)
    oy = 0.1 * exact.cos(0.03 * t + 3.0 * cz)
    if rotation:
        c, s = exact.cos_scalar(float(rotation)), exact.sin_scalar(float(rotation))
        ox, oy = c * ox + s * oy, -s * ox + c * oy  # clockwise about +z: +x turns towards -y
    return 0.5 + ox, 0.5 + oy


def _slices(cz: F64, t: float, rotation: float) -> tuple[F64, F64, F64, F64]:
    """The terms of ``gen_tornado`` that depend on the height alone: (xc, yc, r, r2) of each z value."""
    xc, yc = centre_line(cz, t, rotation)
    r = 0.1 + 0.4 * cz * cz + 0.1 * cz * exact.sin(8.0 * cz)
    r2 = 0.2 + 0.1 * cz
    return xc, yc, r, r2


def _swirl(cx: F64, cy: F64, cz: F64, t: float, rotation: float,
           slices: tuple[F64, F64, F64, F64] | None = None) -> tuple[F64, F64, F64, F64]:
    """The terms of ``gen_tornado`` at broadcastable coordinates: (s, z0, x - xc, y - yc), so that
    v = (s (y - yc) + 0.1 (x - xc), -s (x - xc) + 0.1 (y - yc), s z0).  Per-slice terms (``slices``, or computed
    from ``cz``) stay the size of cz, and the full-size ones are computed in place.  Past the per-slice terms
    every operation is exactly rounded (+ − × ÷ √), so a point gets the same bits whatever array it is in."""
    xc, yc, r, r2 = _slices(cz, t, rotation) if slices is None else slices
    dx, dy = cx - xc, cy - yc
    shape = np.broadcast_shapes(dx.shape, dy.shape, cz.shape)
    d, s, z0 = np.empty(shape), np.empty(shape), np.empty(shape)
    np.add(dx * dx, dy * dy, out=d)
    np.sqrt(d, out=d)
    np.subtract(r, d, out=s)
    np.abs(s, out=s)
    far = s > r2
    np.subtract(0.8, s, out=s)
    np.copyto(s, 1.0, where=~far)  # s = 0.8 - |r - d| if |r - d| > r2 else 1: the discontinuity its author did not like
    np.multiply(d, cz, out=z0)
    np.subtract(0.1, z0, out=z0)
    z0 *= 0.1
    np.maximum(z0, 0.0, out=z0)
    d *= d
    d += z0 * z0
    np.sqrt(d, out=d)  # d = sqrt(d² + z0²)
    s *= (r + r2) - d
    d += SMALL
    s /= d
    s /= 1.0 + cz
    return s, z0, dx, dy


def crawfis_tornado(cx: ArrayLike, cy: ArrayLike, cz: ArrayLike, t: float, rotation: float = 0.0) -> F64:
    """Crawfis' ``gen_tornado`` at points of the unit cube, time ``t``; returns (..., 3) in Crawfis axes.

        r  = 0.1 + 0.4 z² + 0.1 z sin(8 z),  r2 = 0.2 + 0.1 z,  d = |(x, y) - (xc, yc)|
        s  = |r - d|;  s = 0.8 - s if s > r2 else 1
        z0 = max(0.1 (0.1 - d z), 0);  d = sqrt(d² + z0²)
        s  = (r + r2 - d) s / (d + 1e-11) / (1 + z)
        v  = (s (y - yc) + 0.1 (x - xc), -s (x - xc) + 0.1 (y - yc), s z0)
    """
    cx, cy, cz = (np.asarray(a, dtype=np.float64) for a in (cx, cy, cz))  # broadcast lazily: per-slice
    s, z0, dx, dy = _swirl(cx, cy, cz, t, rotation)
    out = np.empty(np.broadcast_shapes(cx.shape, cy.shape, cz.shape) + (3,))
    out[..., 0] = s * dy + 0.1 * dx
    out[..., 1] = -s * dx + 0.1 * dy
    out[..., 2] = s * z0
    return out


def grid_points(resolution: tuple[int, int, int]) -> tuple[F64, F64, F64]:
    """Unit coordinates (ux, uy, uz) of the grid points: i / (n - 1) along each axis, as in gen_tornado."""
    return tuple(np.arange(n, dtype=np.float64) / (n - 1) for n in resolution)  # type: ignore[return-value]


def wind_grid(resolution: tuple[int, int, int], size: ArrayLike, t: float, rotation: float,
              wind_scale: float) -> F64:
    """The field on the grid as field-space velocities in m/s, shape (nx, ny, nz, 3), index [ix, iy(up), iz].

    Crawfis' vector (vx, vy, vz) in unit-cube lengths per time becomes (vx Sx, vz Sy, -vy Sz) · wind_scale,
    written straight into the output (the same operations, in the same order, as mapping crawfis_tornado's).
    """
    ux, uy, uz = grid_points(resolution)
    # engine axes [ix, iy (up), iz] -> Crawfis (x, z, y = 1 - uz), as broadcastable 1-D axes
    slices = tuple(a[None, :, None] for a in _slices(uy, t, rotation))
    s, z0, dx, dy = _swirl(ux[:, None, None], (1.0 - uz)[None, None, :], uy[None, :, None], t, rotation, slices)
    return _field_velocity(s, z0, dx, dy, size, wind_scale, np.empty(tuple(resolution) + (3,)))


def wind_at_nodes(resolution: tuple[int, int, int], size: ArrayLike, t: float, rotation: float, wind_scale: float,
                  nodes: NDArray[np.intp]) -> F64:
    """``wind_grid(...)[ix, iy, iz]`` for the (N, 3) grid indices ``nodes``, bit for bit, without evaluating the
    rest of the grid (the per-slice terms are computed over the whole height axis as the grid does, then
    gathered; everything after them is exactly rounded per element)."""
    ux, uy, uz = grid_points(resolution)
    ix, iy, iz = nodes[:, 0], nodes[:, 1], nodes[:, 2]
    slices = tuple(np.take(a, iy) for a in _slices(uy, t, rotation))
    s, z0, dx, dy = _swirl(np.take(ux, ix), np.take(1.0 - uz, iz), np.take(uy, iy), t, rotation, slices)
    return _field_velocity(s, z0, dx, dy, size, wind_scale, np.empty((len(nodes), 3)))


def _field_velocity(s: F64, z0: F64, dx: F64, dy: F64, size: ArrayLike, wind_scale: float, out: F64) -> F64:
    """Crawfis' (vx, vy, vz) into ``out`` as field-space m/s: (vx Sx, vz Sy, -vy Sz) · wind_scale."""
    size = np.asarray(size, dtype=np.float64)
    for axis, (value, scale) in enumerate([(s * dy + 0.1 * dx, size[0]),  # vx Sx
                                           (s * z0, size[1]),  # vz Sy
                                           (-s * dx + 0.1 * dy, -size[2])]):  # -vy Sz
        value *= scale
        value *= wind_scale
        out[..., axis] = value
    return out


class WindField:
    """The field at one instant (time ``t``, centre-line rotation), looked up at particles (2.1, seeds/004).

    The grid is filled lazily: a lookup evaluates the formula at just the grid points it reads that no earlier
    lookup of this instant evaluated (the midpoint step's two lookups share most of them, and a vortex's
    particles crowd into few cells: ~2,000 evaluations a step for 5,000 particles on a 32³ grid instead of
    32,768), never more than the whole grid.  Values are bit for bit the full grid's (``wind_at_nodes``)."""

    def __init__(self, resolution: tuple[int, int, int], size: ArrayLike, t: float, rotation: float,
                 wind_scale: float) -> None:
        self.resolution = tuple(int(n) for n in resolution)
        self.size, self.t, self.rotation, self.wind_scale = size, t, rotation, wind_scale
        self.dims = np.array(self.resolution, dtype=np.intp)
        self.nodes = int(np.prod(self.resolution))
        self._flat = np.empty((self.nodes, 3))  # grid values, valid where _known
        self._known = np.zeros(self.nodes, bool)
        self.evaluated = 0  # formula evaluations so far (tests, profiling)
        ux, uy, uz = grid_points(self.resolution)
        self._lines = (ux, 1.0 - uz, uy)  # the grid lines in Crawfis' axes (x, y, z), for kernel_args

    def reset(self, size: ArrayLike, t: float, rotation: float, wind_scale: float) -> None:
        """The field at another instant on the same grid: every grid point unknown again (the arrays are kept,
        so a step allocates nothing)."""
        self.size, self.t, self.rotation, self.wind_scale = size, t, rotation, wind_scale
        self._known.fill(False)
        self.evaluated = 0

    @property
    def grid(self) -> F64:
        """The whole grid, (nx, ny, nz, 3) m/s (the points not evaluated yet are evaluated now)."""
        self._ensure(np.arange(self.nodes))
        return self._flat.reshape(self.resolution + (3,))

    def _ensure(self, flat: NDArray[np.intp]) -> None:
        """Evaluate the grid points ``flat`` (repeats allowed) that are not known yet."""
        wanted = np.zeros(self.nodes, bool)
        wanted[flat] = True
        wanted &= ~self._known
        todo = np.flatnonzero(wanted)
        if len(todo) == 0:
            return
        ny_nz = self.resolution[1] * self.resolution[2]
        ix, rest = np.divmod(todo, ny_nz)
        iy, iz = np.divmod(rest, self.resolution[2])
        self._flat[todo] = wind_at_nodes(self.resolution, self.size, self.t, self.rotation, self.wind_scale,
                                         np.stack([ix, iy, iz], axis=-1))
        self._known[todo] = True
        self.evaluated += len(todo)

    def kernel_args(self) -> tuple:
        """What :func:`systems.dust_devil.kernels.advance_particles` evaluates grid points from: the unit
        coordinates of the grid lines (ux, 1 - uz, uy), the per-height terms (xc, yc, r, r2; the float64
        trigonometry, by numpy as in :func:`wind_at_nodes`), the box size and the wind scale."""
        ux, cy, uy = self._lines
        xc, yc, r, r2 = _slices(uy, self.t, self.rotation)
        return (ux, cy, uy, xc, yc, r, r2, np.asarray(self.size, dtype=np.float64), float(self.wind_scale))

    def sample(self, unit: F64, mode: str = "nearest") -> F64:
        """Velocity (N, 3) at unit coordinates (N, 3), as :func:`sample_wind` on the whole grid."""
        nodes, fraction = lookup_nodes(self.dims, unit, mode)
        if fraction is None:
            self._ensure(nodes)
        else:  # the 8 corners of each particle's cell
            sx, sy = self.resolution[1] * self.resolution[2], self.resolution[2]
            self._ensure((nodes[:, None] + np.array([0, 1, sy, sy + 1, sx, sx + 1, sx + sy, sx + sy + 1])).ravel())
        return gather_wind(self._flat, self.dims, nodes, fraction)


def to_unit(points: F64, size: ArrayLike) -> F64:
    """Field-space metres (N, 3) to the box's unit coordinates (ux, uy, uz) in [0, 1]³ inside the box."""
    size = np.asarray(size, dtype=np.float64)
    u = points / size
    u[:, 0] += 0.5
    u[:, 2] += 0.5
    return u


def lookup_nodes(dims: NDArray[np.intp], unit: F64, mode: str = "nearest") -> tuple[NDArray[np.intp], F64 | None]:
    """The grid points a lookup at unit coordinates (N, 3), clamped into the box, reads: ``nearest``, the flat
    index (N,) of the nearest point, and None; ``trilinear``, the flat index (N,) of the lower corner of the
    surrounding cell (the others at strides ``ny·nz``, ``nz``, 1) and the position (N, 3) inside it."""
    dims = np.asarray(dims)
    g = np.clip(unit, 0.0, 1.0)
    g *= dims - 1
    if mode == "nearest":
        np.rint(g, out=g)  # whole numbers: the flat index below is exact in float64
        flat = g[..., 0] * float(dims[1] * dims[2]) + g[..., 1] * float(dims[2]) + g[..., 2]
        return flat.astype(np.intp), None
    if mode != "trilinear":
        raise ValueError(f"unknown lookup mode {mode!r}; expected 'nearest' or 'trilinear'")
    i0 = np.minimum(np.floor(g).astype(np.intp), dims - 2)
    return i0[:, 0] * (dims[1] * dims[2]) + i0[:, 1] * dims[2] + i0[:, 2], g - i0


def gather_wind(flat_grid: F64, dims: NDArray[np.intp], nodes: NDArray[np.intp], fraction: F64 | None) -> F64:
    """Velocities (N, 3) from the flattened grid (nx·ny·nz, 3) at :func:`lookup_nodes`' result."""
    if fraction is None:
        return np.take(flat_grid, nodes, axis=0)
    sx, sy = dims[1] * dims[2], dims[2]  # strides of ix, iy in the flattened grid (iz stride 1)
    fx, fy, fz = fraction[:, 0:1], fraction[:, 1:2], fraction[:, 2:3]

    def lerp_x(offset: int) -> F64:
        a = np.take(flat_grid, nodes + offset, axis=0)
        return a + (np.take(flat_grid, nodes + offset + sx, axis=0) - a) * fx

    c00, c10, c01, c11 = lerp_x(0), lerp_x(sy), lerp_x(1), lerp_x(sy + 1)
    c0 = c00 + (c10 - c00) * fy
    c1 = c01 + (c11 - c01) * fy
    return c0 + (c1 - c0) * fz


def sample_wind(grid: F64, unit: F64, mode: str = "nearest") -> F64:
    """Velocity (N, 3) at unit coordinates (N, 3) clamped into the box.

    ``nearest``: the vector of the nearest grid point (2.1, seeds/004); ``trilinear``: interpolation of the 8
    surrounding grid points.
    """
    dims = np.array(grid.shape[:3])
    nodes, fraction = lookup_nodes(dims, unit, mode)
    return gather_wind(grid.reshape(-1, 3), dims, nodes, fraction)
