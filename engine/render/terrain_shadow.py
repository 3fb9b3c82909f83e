"""Shadows the terrain casts: a shadow-height map of the height field, for the sun's current direction.

The sun's shadow maps (engine/render/shadows.py) cover each view's first ``shadow_distance`` metres and only the
casters drawn into them; a valley wall throwing its shadow across the valley floor a kilometre away needs neither.
A height field has a cheaper exact answer (the horizon-map idea of Max 1988 and of Stewart's horizon maps, kept
to one direction): for every grid point p, the **shadow height**

    S(p) = max( h(p), max over t > 0 of h(p + t·u) − t·tan θ )

where u is the sun's horizontal direction and θ its elevation: a point straight above or below p is in the
terrain's shadow exactly when its height is below S(p) (the ray from it towards the sun enters the ground).  It
is found column by column (or row by row, along the sun's dominant axis) from the sun's side, :func:`shadow_heights`:
the first few columns along each grid point's own ray, the rest along parallel lines towards the sun one row
apart, each line's S past a column from the one past the next, S = max(ground, S_next − |step|·tan θ), with the
field's bilinear surface sampled where the line crosses each column; a grid point takes the two lines beside its
ray.  Axis-aligned and diagonal suns are exact; others blur the shadows of the farther occluders by less than a
row across the sun's path, the same at any distance.  (Taking each column's S from the previous column's,
interpolated at the step's fractional row, blurs sideways at every step: a narrow peak's shadow lost half its
length 100 cells out.)

The map is re-made only when the sun, the height field or its placement changes.  Receivers read it with a
bilinear fetch: a point at local height y over (x, z) gets the sun's light times
``clip((y − S(x, z)) / penumbra + 1, 0, 1)`` (:func:`visibility`), ``penumbra`` the sun's drop over one grid
step, so a shadow's edge is about one cell wide wherever it falls.  The terrain bakes this into its shade
texture (engine/render/terrain.py's ``shade_texels``); meshes look it up per pixel and the grass per plant
(``terrain_shadow.glsl``, :meth:`TerrainShadow.uniforms`, :meth:`TerrainShadow.visibility`).

The first terrain (lowest entity id) casts on meshes and grass; every terrain shades itself with its own map.
Points outside the field's footprint are lit (no terrain beside a field: it is finite, as its collider is), and
with the sun at or below the terrain's horizon everything is in its shadow.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import moderngl
import numpy as np

from engine.heightfield import HeightField
from engine.render.terrain import texel_uv

__all__ = ["TERRAIN_SHADOW_UNIT", "TerrainShadow", "penumbra_height", "receiver", "shadow_heights", "sun_in_local",
           "visibility"]

TERRAIN_SHADOW_UNIT = 6  # the texture unit receivers bind the map to (the sun's shadow map takes 7, features 0-5)

_BELOW = 1e30  # S where the sun is at or below the horizon: every point is under it
_NEAR = 8  # columns towards the sun followed along each grid point's own ray before the lines take over


def sun_in_local(model: np.ndarray, sun_dir: np.ndarray) -> np.ndarray:
    """The world's direction towards the sun in a height field's local frame (unit): directions map by the inverse
    of the model matrix's 3 × 3 part, so rotated, tilted or unevenly scaled fields see the sun where it is."""
    local = np.linalg.solve(np.asarray(model, np.float64)[:3, :3], np.asarray(sun_dir, np.float64))
    n = float(np.linalg.norm(local))
    return local / n if n > 0.0 else np.array([0.0, 1.0, 0.0])


def _tan_elevation(sun: np.ndarray) -> float:
    return float(sun[1]) / max(float(np.hypot(sun[0], sun[2])), 1e-12)


def penumbra_height(spacing: float, sun: np.ndarray) -> float:
    """How far below its shadow height a point is fully shadowed (local units): the sun's drop over one grid step,
    so the soft edge spans about one cell on the ground at any elevation."""
    if sun[1] <= 0.0:
        return float(spacing)
    return float(spacing) * float(np.clip(_tan_elevation(sun), 1e-3, 1e3))


def shadow_heights(heights: np.ndarray, spacing: float, sun: np.ndarray) -> np.ndarray:
    """(rows, cols) float64: per grid point the height S below which a point there is hidden from the sun by the
    field (``heights[row, col]`` at x = col·spacing, z = row·spacing; ``sun`` the unit direction towards the sun in
    that frame).  S ≥ h everywhere, S = h where the ground itself is lit.  See the module docstring."""
    h = np.asarray(heights, np.float64)
    if sun[1] <= 0.0:
        return np.full(h.shape, _BELOW)
    horizontal = float(np.hypot(sun[0], sun[2]))
    if horizontal < 1e-9 * max(float(sun[1]), 1e-30):  # straight overhead: nothing throws a shadow
        return h.copy()
    transposed = abs(sun[2]) > abs(sun[0])
    if transposed:  # sweep along the dominant axis: rows of the transposed grid become its columns
        h = h.T
        along, across = float(sun[2]), float(sun[0])
    else:
        along, across = float(sun[0]), float(sun[2])
    if along < 0.0:  # mirrored so that the sun lies towards the higher columns
        h = h[:, ::-1]
    rows, cols = h.shape
    slope = across / abs(along)  # rows moved per column stepped towards the sun, |slope| <= 1
    drop = spacing * np.sqrt(1.0 + slope * slope) * _tan_elevation(sun)
    offset = np.arange(cols + _NEAR) * slope  # a ray's row, column by column, from where it starts
    shift = np.floor(offset).astype(np.int64)
    t = offset - shift
    floor = float(h.min()) - 1e9  # "no occluder" beside the grid (a ray between the last row and the one
    # beyond it has left the grid too: that row's share sinks it)
    # near: the first columns along each grid point's own ray, each step a shifted copy of the grid
    margin = _NEAR + 1
    padded = np.full((rows + 2 * margin, cols + _NEAR), floor)
    padded[margin:margin + rows, :cols] = h
    s = h.copy()
    for j in range(1, _NEAR):
        lo = padded[margin + shift[j]:margin + shift[j] + rows + 1, j:j + cols]
        sample = lo[1:] - lo[:-1]
        sample *= t[j]
        sample += lo[:-1]
        sample -= j * drop
        np.maximum(s, sample, out=s)
    # far: lines towards the sun, line k crossing column c at row k + shift[c] + t[c] (the column's linear
    # interpolation is the field's bilinear surface there), each line's S past each column in one sweep; a grid
    # point's ray runs between lines r - shift[c] - 1 and r - shift[c], t[c] and 1 - t[c] of a row away, and
    # parallel to them: one interpolation, however far the shadow reaches
    low, high = int(shift[:cols].min()), int(shift[:cols].max())
    first, n = -high - 1, rows + high - low + 1  # the lines' first number and their count
    pad = high - low + 1
    columns = np.full((cols, pad + n), floor)  # the grid's columns, contiguous, "no occluder" around
    columns[:, pad:pad + rows] = h.T
    along_line = np.empty((cols, n))  # per column and line: S of the line's points past that column
    beyond = np.full(n, floor)  # the line's S at the column stepped from, the ground there included
    for c in range(cols - 1, -1, -1):
        along_line[c] = beyond - drop
        column = columns[c, pad + first + shift[c]:]
        ground = column[:n] if t[c] == 0.0 else (1.0 - t[c]) * column[:n] + t[c] * column[1:n + 1]
        beyond = np.maximum(ground, beyond - drop)
    past = np.minimum(np.arange(cols) + _NEAR - 1, cols - 1)  # where the near steps ended
    windows = np.lib.stride_tricks.sliding_window_view(along_line[past], rows + 1, axis=1)
    beside = windows[np.arange(cols), -shift[:cols] - first - 1].T  # (rows + 1, cols): lines k - 1 and k
    far = beside[1:] - beside[:-1]
    far *= 1.0 - t[:cols]
    far += beside[:-1] - (_NEAR - 1) * drop
    np.maximum(s, far, out=s)
    if along < 0.0:
        s = s[:, ::-1]
    return s.T.copy() if transposed else s


def visibility(y: np.ndarray, shadow_height: np.ndarray, penumbra: float) -> np.ndarray:
    """How much of the sun reaches points at height ``y`` whose shadow height is ``shadow_height``: 1 above it,
    falling to 0 over ``penumbra`` below it (terrain_shadow.glsl's ``terrain_sun``)."""
    return np.clip((np.asarray(y, np.float64) - shadow_height) / penumbra + 1.0, 0.0, 1.0)


@dataclass
class TerrainShadow:
    """One terrain's shadow-height map on the GPU and how receivers reach it (see the module docstring)."""

    key: tuple  # what it was made from: the field, its model matrix, the sun (last; passes.py makes it)
    surface: HeightField  # the shadow heights S on the field's grid (local units), sampled as the field is
    ground: np.ndarray  # (rows, cols) float64 the sun's share on the ground itself (visibility at h)
    world_to_local: np.ndarray  # 4 × 4 (column-vector convention)
    penumbra: float
    below_horizon: bool  # the sun is at or below the field's horizon: everything is in shadow
    casts: bool  # some shadow falls on or above the ground (else nothing above the ground is in its shadow)
    texture: moderngl.Texture | None = None

    @classmethod
    def build(cls, key: tuple, field, model: np.ndarray, sun_dir: np.ndarray) -> TerrainShadow:
        sun = sun_in_local(model, sun_dir)
        heights = shadow_heights(field.heights, field.spacing, sun)
        below = bool(sun[1] <= 0.0)
        casts = below or bool((heights > field.heights).any())
        penumbra = penumbra_height(field.spacing, sun)
        return cls(key, HeightField(heights, field.spacing, field.origin),
                   visibility(field.heights, heights, penumbra), np.linalg.inv(np.asarray(model, np.float64)),
                   penumbra, below, casts)

    @property
    def ground_key(self) -> tuple:
        """Its key less the sun: the same while only the sun moved (the grass's band follows the light on its own
        tolerance)."""
        return self.key[:-1]

    @property
    def heights(self) -> np.ndarray:
        """(rows, cols) float64: the shadow heights."""
        return self.surface.heights

    def upload(self, ctx: moderngl.Context) -> moderngl.Texture:
        """The map as an rg32f texture (made on first use: r the shadow heights, g the ground's share of the
        sun), filtered bilinearly, clamped."""
        if self.texture is None:
            rows, cols = self.heights.shape
            texels = np.stack([self.heights, self.ground], axis=-1).astype(np.float32)
            self.texture = ctx.texture((cols, rows), 2, texels.tobytes(), dtype="f4")
            self.texture.filter = (moderngl.LINEAR, moderngl.LINEAR)
            self.texture.repeat_x = self.texture.repeat_y = False
        return self.texture

    def release(self) -> None:
        if self.texture is not None:
            self.texture.release()
            self.texture = None

    def uniforms(self, ctx: moderngl.Context, unit: int = TERRAIN_SHADOW_UNIT) -> dict[str, Any]:
        """Bind the map to texture ``unit`` and return the uniforms of terrain_shadow.glsl."""
        self.upload(ctx).use(unit)
        scale, offset = texel_uv(self.surface)
        return dict(terrain_shadow=unit, terrain_shadow_matrix=self.world_to_local.T.astype(np.float32).copy(),
                    terrain_shadow_uv=(*scale, *offset),
                    terrain_shadow_params=(1.0 / self.penumbra, 0.0 if self.below_horizon else 1.0))

    def visibility(self, points: np.ndarray) -> np.ndarray:
        """(n,) the sun's share reaching world ``points`` (n, 3), as the shader computes it (bilinear S)."""
        p = np.asarray(points, np.float64).reshape(-1, 3)
        local = p @ self.world_to_local[:3, :3].T + self.world_to_local[:3, 3]
        s = self.surface
        rows, cols = s.heights.shape
        gx, gz = (local[:, 0] - s.origin[0]) / s.spacing, (local[:, 2] - s.origin[1]) / s.spacing
        outside = (gx < -0.5) | (gz < -0.5) | (gx > cols - 0.5) | (gz > rows - 0.5)  # the texture's clamped margin
        vis = visibility(local[:, 1], s.height_at(local[:, 0], local[:, 2]), self.penumbra)
        return np.where(outside, 0.0 if self.below_horizon else 1.0, vis)


def receiver(shadow: TerrainShadow | None, ctx: moderngl.Context) -> tuple[tuple[str, ...], dict[str, Any]]:
    """In a receiving pass's execute: the program defines (``TERRAIN_SHADOW``) and the uniforms of
    terrain_shadow.glsl, the map bound; ``((), {})`` without a shadow (``Renderer.terrain_shadow_in(view)``)."""
    if shadow is None:
        return (), {}
    return ("TERRAIN_SHADOW",), shadow.uniforms(ctx)
