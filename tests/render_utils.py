"""Headless rendering for tests: one shared EGL context, small offscreen renders, golden-image checks.

``render_app(app, width, height, frames)`` renders an App headless and returns a PIL image;
``assert_golden(image, name)`` compares it with ``tests/golden/<name>.png`` using a tolerance on the
mean channel difference and the share of pixels that differ.  On failure it writes ``<name>.actual.png`` and
``<name>.diff.png`` next to the reference.  Run pytest with ``--regen-golden`` (or set
``REGEN_GOLDEN=1``) to write the references on purpose.  Render tests never skip: with no context
they fail with a message naming the system packages to install.
"""

from __future__ import annotations

import os
from contextlib import contextmanager
from pathlib import Path

import numpy as np
import pytest

GOLDEN_DIR = Path(__file__).parent / "golden"
_CONTEXT = None
REGEN = {"on": bool(os.environ.get("REGEN_GOLDEN"))}


def gl_context():
    """The session's shared headless context; fails the test (never skips) when EGL is missing."""
    global _CONTEXT
    if _CONTEXT is None:
        from engine.render.frontend import ContextError, create_headless_context

        try:
            _CONTEXT = create_headless_context()
        except ContextError as exc:
            pytest.fail(str(exc), pytrace=False)
    return _CONTEXT


def make_renderer(app, width: int = 160, height: int = 120):
    from engine.render.renderer import Renderer

    return Renderer(app, gl_context(), width, height)


@contextmanager
def rendered(app, width: int = 160, height: int = 120):
    """A renderer for ``app``, after one tick and one frame; released and detached from the app on exit."""
    renderer = make_renderer(app, width, height)
    try:
        app.step(1)
        app.render_frame()
        yield renderer
    finally:
        renderer.release()
        app.renderer = None


def render_app(app, width: int = 160, height: int = 120, frames: int = 1, steps_per_frame: int = 1):
    """Render ``frames`` frames (each after ``steps_per_frame`` ticks); return the last as a PIL image."""
    renderer = app.renderer if app.renderer is not None else make_renderer(app, width, height)
    try:
        for _ in range(frames):
            app.step(steps_per_frame)
            app.render_frame()
        return renderer.read_image()
    finally:
        renderer.release()
        app.renderer = None


def view_hdr_frames(app, frames: int = 1, width: int = 160, height: int = 120) -> np.ndarray:
    """(frames, h, w, 3) float64: the first view's HDR colour after its passes, at the view's size (before any
    upscale), over ``frames`` frames drawn without stepping the simulation."""
    renderer = make_renderer(app, width, height)
    out = []
    try:
        for _ in range(frames):
            renderer.extract(app.world)
            graph = renderer.declare()
            view = renderer.views[0]

            def setup(b, view=view):
                b.read(view.color)

            def execute(pc, view=view):
                raw = np.frombuffer(pc.get(view.color).read(), np.float16).astype(np.float64)
                out.append(raw.reshape(view.height, view.width, 4)[..., :3])

            graph.add_pass("test.read_hdr", setup, execute, side_effect=True)
            graph.execute()
            renderer.frame_index += 1
    finally:
        renderer.release()
        app.renderer = None
    return np.array(out)


def world_pixel(view, point) -> tuple[int, int]:
    """(row, column) of a world point in a view's image (row 0 at the top)."""
    clip = view.view_proj.astype(np.float64) @ np.array([*point, 1.0])
    ndc = clip[:3] / clip[3]
    return int((1.0 - ndc[1]) * 0.5 * view.height), int((ndc[0] + 1.0) * 0.5 * view.width)


def ground_of_pixels(view, y: float = 0.0) -> np.ndarray:
    """(height, width, 3) where each pixel's ray through a view meets the plane at height ``y``."""
    inverse = np.linalg.inv(view.view_proj.astype(np.float64))
    rows, cols = np.mgrid[0:view.height, 0:view.width]
    ndc_x, ndc_y = (cols + 0.5) / view.width * 2 - 1, 1 - (rows + 0.5) / view.height * 2

    def unproject(depth: float) -> np.ndarray:
        h = np.stack([ndc_x, ndc_y, np.full(rows.shape, depth), np.ones(rows.shape)], axis=-1) @ inverse.T
        return h[..., :3] / h[..., 3:]

    near, far = unproject(-1.0), unproject(1.0)
    t = (near[..., 1] - y) / (near[..., 1] - far[..., 1])
    return near + t[..., None] * (far - near)


def image_difference(a, b) -> tuple[float, int, np.ndarray]:
    """(mean absolute channel difference, max channel difference, per-pixel difference image)."""
    x = np.asarray(a.convert("RGB"), np.int16)
    y = np.asarray(b.convert("RGB"), np.int16)
    diff = np.abs(x - y)
    return float(diff.mean()), int(diff.max()), diff.max(axis=2).astype(np.uint8)


GOLDEN_MEAN_TOL = 0.5  # mean absolute channel difference, 0..255
GOLDEN_PIXEL_DIFF = 24  # a pixel "differs" when a channel is off by more than this
GOLDEN_PIXEL_TOL = 0.002  # the fraction of pixels that may differ


def assert_golden(image, name: str, mean_tol: float = GOLDEN_MEAN_TOL, pixel_tol: float = GOLDEN_PIXEL_TOL) -> None:
    """Compare ``image`` with ``tests/golden/<name>.png``: the mean channel difference at most ``mean_tol`` and at
    most ``pixel_tol`` of the pixels off by more than GOLDEN_PIXEL_DIFF.  The renders are bit-exact run to run on
    one machine; the tolerance absorbs another CPU's llvmpipe code paths (a few edge pixels, rounding), not a
    visible change: a white beam core turned blue or a sun glint removed moved the mean by about 1, which the
    old rule (mean 2, max 80) let through."""
    from PIL import Image

    ref_path = GOLDEN_DIR / f"{name}.png"
    if REGEN["on"] or not ref_path.exists():
        if not REGEN["on"]:
            pytest.fail(f"no reference image {ref_path}; run pytest --regen-golden to create it, then look at it",
                        pytrace=False)
        GOLDEN_DIR.mkdir(parents=True, exist_ok=True)
        image.save(ref_path)
        return
    ref = Image.open(ref_path)
    if ref.size != image.size:
        image.save(GOLDEN_DIR / f"{name}.actual.png")
        pytest.fail(f"{name}: size {image.size} differs from the reference {ref.size}", pytrace=False)
    mean, peak, diff = image_difference(image, ref)
    off = float((diff > GOLDEN_PIXEL_DIFF).mean())
    if mean > mean_tol or off > pixel_tol:
        image.save(GOLDEN_DIR / f"{name}.actual.png")
        Image.fromarray(np.clip(diff.astype(np.int32) * 4, 0, 255).astype(np.uint8)).save(GOLDEN_DIR / f"{name}.diff.png")
        pytest.fail(f"{name}: image differs from {ref_path} (mean {mean:.2f}, limit {mean_tol}; {off:.2%} of pixels off "
                    f"by more than {GOLDEN_PIXEL_DIFF}, limit {pixel_tol:.2%}; max {peak}); "
                    f"see {name}.actual.png and {name}.diff.png next to it", pytrace=False)


_GL_MAKERS = ("texture", "depth_texture", "texture_array", "texture3d", "texture_cube", "buffer", "vertex_array",
              "simple_vertex_array", "framebuffer", "renderbuffer", "depth_renderbuffer", "program",
              "compute_shader", "sampler", "query")


def track_gl_objects(monkeypatch):
    """Record every GL object made through a moderngl context from now on (until the test ends); returns a function
    giving how many of each kind are still live (not released), e.g. ``{"texture": 3, "framebuffer": 2}``.  An
    object dropped without ``release()`` counts as live: the context keeps it (moderngl's default gc_mode)."""
    import collections

    import moderngl

    made: list[tuple[str, object]] = []
    for kind in _GL_MAKERS:
        original = getattr(moderngl.Context, kind, None)
        if original is None:
            continue

        def maker(self, *args, _original=original, _kind=kind, **kwargs):
            obj = _original(self, *args, **kwargs)
            made.append((_kind, obj))
            return obj

        monkeypatch.setattr(moderngl.Context, kind, maker)

    def live() -> dict[str, int]:
        counts = collections.Counter(kind for kind, obj in made
                                     if not isinstance(getattr(obj, "mglo", None), moderngl.InvalidObject))
        return dict(counts)

    return live


def respawn(app, name: str) -> int:
    """Despawn the scene's entity called ``name`` and spawn it again from the scene's plan (a new entity id, as a
    hot reload that removes and re-adds it does); returns the new id."""
    from engine.builtin import find_named
    from engine.scene import spawn_entity

    app.world.despawn(find_named(app.world, name))
    index = next(i for i, ent in enumerate(app.plan.entities) if ent.name == name)
    return spawn_entity(app.world, app.registry, app.plan, index, app.plan.entities[index]).entity


def gl_objects_per_respawn(app, name: str, live, cycles: int = 4, frames: int = 3, width: int = 48,
                           height: int = 36) -> list[dict[str, int]]:
    """Render ``app`` headless while the entity called ``name`` is respawned ``cycles`` times (``frames`` frames
    after each: a view keeps its static layer from its second frame on); returns ``live()``
    (:func:`track_gl_objects`) after each cycle: the same counts every time unless something leaks."""
    renderer = make_renderer(app, width, height)
    counts = []
    try:
        for _ in range(cycles):
            respawn(app, name)
            for _ in range(frames):
                app.step(1)
                app.render_frame()
            counts.append(live())
    finally:
        renderer.release()
        app.renderer = None
    return counts
