"""Sun shadows: one depth map per view seen from the sun, fitted to the view's first ``shadow_distance`` metres.

Casters are what render features return from :meth:`~engine.render.feature.RenderFeature.shadow_casters` (the
engine's lit meshes; a plugin's feature may add its own); receivers (the terrain, the meshes, a plugin's shaders
through ``shadow.glsl``) read the map in their pass with :func:`receiver_uniforms`.

The light's box is an orthographic projection along the sun direction around the bounding sphere of the view's
frustum slice ``[near, min(far, shadow_distance)]``: its size does not change as the camera turns, and its centre
moves in whole texels (in the light's plane), so a shadow edge keeps its texels while the camera moves instead
of crawling (the stable fit of cascaded shadow maps, here one cascade).  Its depth range reaches back towards the
sun to the farthest caster, so that a caster outside the view still shadows what the view sees.

The map is kept per camera and redrawn only when its key (the light box and every caster's key) changes: a still
scene costs one texture fetch per receiving pixel and no shadow pass.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Hashable
from dataclasses import dataclass

import numpy as np

from engine.render.feature import View
from engine.render.graph import ResourceHandle

SHADOW_UNIT = 7  # the texture unit receivers bind the shadow map to (features use the low units)
DEPTH_REACH = 2000.0  # metres the light's box may reach back towards the sun for casters outside the view


@dataclass
class ShadowCasters:
    """What one feature draws into a view's shadow map this frame.

    ``key``: hashable, and changes whenever what ``draw`` draws changes (the map is redrawn only then).
    ``boxes``: (n, 2, 3) world-space boxes (min, max corners), together holding every caster (one a caster, or
    one around them all): they fit the map's depth range and tell receivers where shadows can fall
    (:func:`may_be_shadowed`).
    ``draw(light_view_proj)``: draws the casters' depth with that 4 × 4 matrix (float32, column-vector
    convention; write it transposed, like a view's ``mvp_bytes``) into the bound framebuffer, depth test on, no
    colour target.
    """

    key: Hashable
    boxes: np.ndarray
    draw: Callable[[np.ndarray], None]


@dataclass
class Shadow:
    """A view's shadow map for this frame (``view.extra["shadow"]``), as its receivers need it."""

    texture: ResourceHandle  # the depth map (sampled with a depth comparison)
    matrix: np.ndarray  # 4x4 float32: world -> (u, v, depth) in [0, 1] of the map
    light_view_proj: np.ndarray  # 4x4 float32: world -> the map's clip space (what the casters were drawn with)
    texel: float  # metres a texel covers
    normal_offset: float  # metres receivers move their look-up along their normal
    distance: float  # shadows end (fade out) at this distance from the camera
    size: int
    soft: bool
    key: tuple  # the light box and the casters' keys: the map's content
    basis: np.ndarray  # (3, 3) float64 rows: right, up, towards the sun
    caster_boxes: np.ndarray  # (n, 2, 3): the casters' boxes in the light's frame (right, up, depth from the sun)
    extent: np.ndarray  # (2, 2): the map's box across the light (min, max of right and up)


def light_boxes(basis: np.ndarray, boxes: np.ndarray) -> np.ndarray:
    """(n, 2, 3): world boxes (n, 2, 3) as boxes in the light's frame (right, up, depth away from the sun)."""
    frame = np.asarray(basis, np.float64) * np.array([[1.0], [1.0], [-1.0]])
    boxes = np.asarray(boxes, np.float64)
    centre, half = (boxes[:, 0] + boxes[:, 1]) * 0.5, (boxes[:, 1] - boxes[:, 0]) * 0.5
    c = np.einsum("ij,nj->ni", frame, centre)
    h = np.einsum("ij,nj->ni", np.abs(frame), half)
    return np.stack([c - h, c + h], axis=1)


def may_be_shadowed(shadow: Shadow | None, boxes: np.ndarray) -> np.ndarray:
    """(m,) bool: which world boxes (m, 2, 3) a shadow of this frame's casters may fall on: seen along the
    light, the box overlaps a caster's box and the map, and reaches farther from the sun than the caster's
    nearest point.  Receivers draw the others with their plain shader (receiver culling: on a software
    rasteriser the shadow look-up is paid per pixel).

    A shadow reaches past its caster's box across the light by what ``shadow.glsl`` adds: the look-up point
    moved along the normal (``normal_offset``) and the filter's reach (the bilinear comparison takes texels up
    to one away, the four taps one more), so the casters' boxes grow by that much plus half a texel."""
    boxes = np.asarray(boxes, np.float64).reshape(-1, 2, 3)
    if shadow is None or len(boxes) == 0:
        return np.zeros(len(boxes), bool)
    r = light_boxes(shadow.basis, boxes)[:, None]  # (m, 1, 2, 3)
    c = shadow.caster_boxes[None]  # (1, n, 2, 3)
    reach = shadow.normal_offset + (2.5 if shadow.soft else 1.5) * shadow.texel
    across = np.all((r[..., 0, :2] <= c[..., 1, :2] + reach) & (r[..., 1, :2] >= c[..., 0, :2] - reach), axis=-1)
    behind = r[..., 1, 2] > c[..., 0, 2]
    inside = np.all((r[:, 0, 0, :2] <= shadow.extent[1]) & (r[:, 0, 1, :2] >= shadow.extent[0]), axis=-1)
    return np.any(across & behind, axis=1) & inside


def light_basis(sun_direction: np.ndarray) -> np.ndarray:
    """(3, 3) float64 rows: right, up, towards the sun (orthonormal): the light's view axes."""
    toward = np.asarray(sun_direction, np.float64)
    toward = toward / math.sqrt(float(toward @ toward))
    helper = np.array([0.0, 1.0, 0.0]) if abs(toward[1]) < 0.99 else np.array([1.0, 0.0, 0.0])
    right = np.cross(helper, toward)
    right /= math.sqrt(float(right @ right))
    return np.array([right, np.cross(toward, right), toward])


def frustum_sphere(view: View, distance: float) -> tuple[np.ndarray, float]:
    """(centre, radius), float64: the smallest sphere around the view's frustum slice from its near plane to
    ``min(far, distance)`` (a slice of an orthographic view is a box).  The radius depends only on the
    projection, not on where the camera looks."""
    near, far = float(view.near), min(float(view.far), float(distance))
    far = max(far, near + 1e-3)
    aspect = view.width / max(view.height, 1)
    if view.ortho:
        half_h = 1.0 / float(view.proj[1, 1])
        half_w = 1.0 / float(view.proj[0, 0])
        rn2 = rf2 = half_w * half_w + half_h * half_h
    else:
        t = math.tan(view.fov_y / 2.0)
        rn2 = (near * t) ** 2 * (1.0 + aspect * aspect)
        rf2 = (far * t) ** 2 * (1.0 + aspect * aspect)
    # centre on the axis at depth c, equally far from the near and far corners: (c - n)² + rn² = (f - c)² + rf²
    c = (far * far + rf2 - near * near - rn2) / (2.0 * (far - near))
    c = min(max(c, near), far)
    radius = math.sqrt(max((far - c) ** 2 + rf2, (c - near) ** 2 + rn2))
    rotation = np.asarray(view.view, np.float64)[:3, :3]  # world -> camera; its rows are the camera's axes
    forward = -rotation[2]
    centre = np.asarray(view.camera_pos, np.float64) + forward * c
    return centre, radius


def fit_light(view: View, basis: np.ndarray, distance: float, size: int,
              nearest_caster: float | None) -> tuple[np.ndarray, np.ndarray, float, np.ndarray]:
    """(light_view_proj, texture matrix, texel size, extent) of the view's shadow map: float32 matrices (see the
    module docstring for the fit) and the map's box across the light, (2, 2) min and max of right and up.
    ``basis``: :func:`light_basis`; ``nearest_caster``: the depth from the sun of the casters' nearest point (their
    :func:`light_boxes`' smallest depth), None without casters."""
    right, up, toward = basis
    centre, radius = frustum_sphere(view, distance)
    half = radius * size / (size - 2)  # one texel of margin: the snapped box still holds the whole sphere
    texel = 2.0 * half / size
    cx = math.floor(float(centre @ right) / texel) * texel  # whole texels: edges keep their texels
    cy = math.floor(float(centre @ up) / texel) * texel
    depth_centre = -float(centre @ toward)  # depth grows away from the sun
    near, far = depth_centre - radius, depth_centre + radius
    if nearest_caster is not None:
        near = max(min(near, float(nearest_caster) - 0.01 * radius), depth_centre - radius - DEPTH_REACH)
    m = np.zeros((4, 4))
    m[0, :3], m[0, 3] = right / half, -cx / half  # the box: [cx - half, cx + half] across the light
    m[1, :3], m[1, 3] = up / half, -cy / half
    # z_clip = 2 (d - near) / (far - near) - 1 with d = -toward·p
    m[2, :3] = -2.0 * toward / (far - near)
    m[2, 3] = -2.0 * near / (far - near) - 1.0
    m[3, 3] = 1.0
    bias = np.array([[0.5, 0, 0, 0.5], [0, 0.5, 0, 0.5], [0, 0, 0.5, 0.5], [0, 0, 0, 1.0]])
    extent = np.array([[cx - half, cy - half], [cx + half, cy + half]])
    return m.astype(np.float32), (bias @ m).astype(np.float32), texel, extent


def receiver_uniforms(shadow: Shadow | None, pc) -> tuple[tuple[str, ...], dict]:
    """In a receiving pass's execute: binds the view's shadow map (``pc`` the pass context) and returns the
    program defines (``SHADOWS``, ``SHADOW_SOFT``) and the uniforms ``shadow.glsl`` reads; ``((), {})`` when
    the view has no shadow map this frame.  The pass's setup must have called :func:`read_shadow`."""
    if shadow is None:
        return (), {}
    pc.get(shadow.texture).use(SHADOW_UNIT)
    defines = ("SHADOWS", "SHADOW_SOFT") if shadow.soft else ("SHADOWS",)
    return defines, dict(shadow_map=SHADOW_UNIT, shadow_matrix=shadow.matrix.T.copy(),
                         shadow_params=(shadow.normal_offset, shadow.distance, 1.0 / shadow.size))


def read_shadow(b, view: View) -> None:
    """In a receiving pass's setup: declare the read of the view's shadow map, when it has one.  The read does
    not wait (``wait=False``): the map's pass is small and queued first, so the frame's synchronisation point,
    where the renderer overlaps the next ticks with the GPU's work, stays after the opaque passes."""
    shadow = view.extra.get("shadow")
    if shadow is not None:
        b.read(shadow.texture, wait=False)
