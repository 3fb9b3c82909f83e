"""What an effect plugin implements to draw: a :class:`RenderFeature`, and the :class:`View` it draws into.

Per frame the renderer:
1. calls ``feature.extract(world)`` once (render-extract stage): copy what the passes need out of the
   simulation state (numpy copies, never references to arrays the simulation keeps mutating);
2. for every view (main camera, minimap / top view, ...), calls ``feature.add_passes(graph, view, data)``
   with features ordered by ``phase`` (OPAQUE, SKY, TRANSPARENT, OVERLAY) and then by registration order;
3. compiles and executes the render graph; each view is tone-mapped straight into its rectangle of the
   window image, and OVERLAY features draw over that.

A pass that draws into a view declares it in its setup callback, which also orders it::

    def add_passes(self, graph, view, data):
        def setup(b):
            view.color = b.write(view.color)   # HDR rgba16f colour; write returns the new version
            b.read(view.depth)                 # depth-tested, no depth writes (transparent phase)
        def execute(pc):
            fbo = self.renderer.framebuffer(pc.get(view.color), pc.get(view.depth))
            fbo.use(); ...
        graph.add_pass(f"{self.name}.{view.name}", setup, execute)

Opaque passes write both ``view.color`` and ``view.depth``.  Persistent GPU data (an impostor atlas, a
height-field texture) is owned by the feature and imported with ``graph.import_resource`` when another
pass reads it.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np

if TYPE_CHECKING:
    from engine.render.graph import RenderGraph, ResourceHandle
    from engine.render.renderer import Renderer
    from engine.render.shadows import ShadowCasters
    from engine.world import World

OPAQUE = 0  # writes colour and depth
SKY = 1  # the sky fills what the opaque passes left empty (depth test at the far plane)
TRANSPARENT = 2  # reads depth, blends colour
OVERLAY = 3  # drawn once over the composited window image (HUD)


@dataclass
class View:
    """One camera's image this frame: matrices (float32, column-vector convention) and graph handles."""

    name: str
    width: int
    height: int
    view: np.ndarray  # 4x4 world -> camera
    proj: np.ndarray  # 4x4 camera -> clip
    camera_pos: np.ndarray  # (3,)
    camera_forward: np.ndarray  # (3,) unit
    near: float
    far: float
    fov_y: float  # radians (perspective); 0 for orthographic
    ortho: bool
    color: ResourceHandle | None = None
    depth: ResourceHandle | None = None
    is_main: bool = True
    camera_entity: int = 0
    extra: dict[str, Any] = field(default_factory=dict)
    # the view's pixels per window pixel (the render scale: dynamic resolution lowers it); sizes set in window
    # pixels (a point's, a line's) are this many of the view's pixels
    pixel_scale: float = 1.0

    def view_pixels(self, window_pixels: float) -> float:
        """A size given in window pixels (a point's side, an outline's width: what configs set) in this view's
        pixels, so that it looks the same at any render scale."""
        return float(window_pixels) * self.pixel_scale

    @property
    def view_proj(self) -> np.ndarray:
        return (self.proj @ self.view).astype(np.float32)

    def mvp_bytes(self) -> bytes:
        """``view_proj`` as bytes for a ``mat4`` uniform (moderngl expects column-major)."""
        return self.view_proj.T.astype(np.float32).tobytes()


def write_view_color(b, view: View, region: tuple[int, int, int, int] | None) -> None:
    """In a pass's setup: declare a write of ``view``'s colour (``view.color`` becomes the new version) that
    changes at most the pixels of ``region`` (x, y, width, height in the view's pixels, as a scissor box; None:
    anywhere).  The renderer then tone-maps only those pixels of a view whose static layer was restored, and
    copies the rest from the layer's tone-mapped picture (Renderer._partial_present).  A pass that writes the
    colour with a plain ``b.write(view.color)`` is fine too: the whole view is tone-mapped then."""
    view.color = b.write(view.color)
    view.extra.setdefault("color_regions", []).append(None if region is None else tuple(int(v) for v in region))


@dataclass(eq=False)
class ColorLayer:
    """Light a pass adds to a view's HDR colour: ``colour += matrix · texture`` inside ``region``, the texture (a
    graph handle) sampled bilinearly at the view's texture coordinates (a smaller buffer upsampled: off-screen
    particles with their bloom).  ``matrix`` (3 × 3, its columns multiply the texture's channels) turns the
    channels into colour (the identity for an RGB buffer).

    Declared with :func:`engine.render.passes.add_color_layer`, which adds the pass that draws it.  When no later
    pass writes the view's colour, the renderer applies the layer in the view's tone map instead (post-processing
    stacks fold their bloom into the tone map the same way) and sets ``folded``: that pass then draws nothing.
    On a software rasteriser that saves a read-modify-write of the HDR target over the region."""

    texture: Any
    matrix: np.ndarray
    region: tuple[int, int, int, int]
    folded: bool = False


class RenderFeature:
    """Base class of a plugin's render passes; GL objects are created lazily and released in ``release``."""

    name: str = "feature"
    phase: int = OPAQUE
    #: True for a feature that writes every pixel the opaque passes leave at the far plane (the sky): the view's
    #: colour target then needs no clear, only its depth (on a software rasteriser a colour clear of an HDR
    #: target is a pass of its own).
    fills_background: bool = False

    def __init__(self, renderer: Renderer) -> None:
        self.renderer = renderer
        self.ctx = renderer.ctx

    def extract(self, world: World) -> Any:
        """Copy what the passes need from the world (called once per frame)."""
        return None

    def add_passes(self, graph: RenderGraph, view: View, data: Any) -> None:
        """Declare this feature's passes for ``view``."""

    def static_key(self, view: View, data: Any) -> Any:
        """A hashable key of everything this feature draws into ``view`` apart from the view itself (camera,
        size, light, sky colours and fog are the renderer's part of the key), or None when it must draw every
        frame (the default).

        Only OPAQUE and SKY features may return a key, and only when their passes write colour and depth as a
        pure function of that key and the view: no time, no random numbers, no state outside ``data``.  While the
        key stays the same the renderer may copy the view's static layer back from a kept picture instead of
        running the passes (``[render] static_layer_cache``); returning a key that misses a change shows a stale
        picture.
        """
        return None

    def shadow_casters(self, data: Any) -> ShadowCasters | None:
        """What this feature draws into the sun's shadow maps this frame
        (:class:`engine.render.shadows.ShadowCasters`: a key, world bounds and a depth-only draw), or None when
        it casts no shadow (the default).  Called once per view that has shadows; a feature hidden in a view
        (Camera ``hide_features``) casts none there."""
        return None

    def release(self) -> None:
        """Free GL objects."""

    def release_texture(self, texture: Any) -> None:
        """Release a texture this feature made and drew into through ``renderer.framebuffer``: the framebuffers
        the renderer cached for it go too (``texture.release()`` alone leaves them, keyed by the texture's GL
        name, which a driver may give to the next texture it makes)."""
        self.renderer._free_resource(texture)
