"""Colour layers (engine.render.feature.ColorLayer): light a pass adds to a view's HDR colour, which the view's
tone map adds instead when no later pass writes the colour."""

import numpy as np
import pytest

from engine.app import App
from engine.render.feature import TRANSPARENT, ColorLayer, RenderFeature
from engine.render.graph import TextureDesc
from engine.render.passes import add_color_layer
from tests.render_utils import make_renderer

SCENE = "configs/scenes/sandbox.toml"
MATRIX = np.array([[2.0, 0.0, 0.0], [0.0, 1.0, 0.5], [0.0, 0.0, 0.25]])  # columns: what each channel adds


class LayerFeature(RenderFeature):
    """A half-size buffer filled with constant weights (0.3, 0.2, 0.8), added over the view's middle."""

    name = "test_layer"
    phase = TRANSPARENT

    def __init__(self, renderer) -> None:
        super().__init__(renderer)
        self.layers = []

    def extract(self, world):
        return True

    def add_passes(self, graph, view, data):
        h = {}
        size = (view.width // 2, view.height // 2)

        def setup(b):
            h["buffer"] = b.write(b.create(f"test_layer.{view.name}", TextureDesc(*size, "rgba16f")))

        def execute(pc):
            fbo = self.renderer.framebuffer(pc.get(h["buffer"]))
            fbo.use()
            fbo.clear(0.3, 0.2, 0.8, 0.0)

        graph.add_pass(f"test_layer.fill.{view.name}", setup, execute)
        region = (view.width // 4, view.height // 4, view.width // 2, view.height // 2)
        self.layers.append(add_color_layer(graph, self.renderer, f"test_layer.add.{view.name}", view,
                                           ColorLayer(h["buffer"], MATRIX, region)))


class WriteAfter(RenderFeature):
    """A later transparent pass that writes the view's colour (and draws nothing)."""

    name = "test_write_after"
    phase = TRANSPARENT

    def extract(self, world):
        return True

    def add_passes(self, graph, view, data):
        def setup(b):
            view.color = b.write(view.color)

        graph.add_pass(f"test_write_after.{view.name}", setup, lambda pc: None)


def _picture(fold: bool, features=(LayerFeature,), render_scale: float = 1.0, size=(128, 96)):
    app = App(SCENE)
    app.config.render.render_scale = render_scale
    app.config.render.static_layer_cache = False
    renderer = make_renderer(app, *size)
    renderer.fold_color_layers = fold
    added = [f(renderer) for f in features]
    renderer.features += added
    renderer._ordered = sorted(enumerate(renderer.features), key=lambda kv: (kv[1].phase, kv[0]))
    try:
        app.step(1)
        app.render_frame()
        picture = np.asarray(renderer.read_image(), np.int16)
        layers = added[0].layers if added and isinstance(added[0], LayerFeature) else []
        return picture, [layer.folded for layer in layers]
    finally:
        renderer.release()
        app.renderer = None


@pytest.mark.parametrize("render_scale", [1.0, 0.5])
def test_a_last_layer_is_folded_into_the_tone_map_with_the_passs_picture(render_scale):
    folded_picture, folded = _picture(True, render_scale=render_scale)
    drawn_picture, drawn = _picture(False, render_scale=render_scale)
    plain, _ = _picture(True, features=(), render_scale=render_scale)
    assert folded == [True] and drawn == [False]
    assert np.abs(folded_picture - drawn_picture).max() <= 1
    # the layer brightens its region (red by 0.6, green by 0.2 + 0.4, blue by 0.2) and nothing outside it
    h, w = plain.shape[:2]
    inside = (slice(h // 4 + 2, 3 * h // 4 - 2), slice(w // 4 + 2, 3 * w // 4 - 2))
    assert (folded_picture[inside].sum(axis=-1) > plain[inside].sum(axis=-1) + 20).all()
    outside = np.ones((h, w), bool)
    outside[h // 4 - 2: 3 * h // 4 + 2, w // 4 - 2: 3 * w // 4 + 2] = False
    assert np.array_equal(folded_picture[outside], plain[outside])


def test_a_layer_with_a_colour_write_after_it_is_drawn_by_its_pass():
    picture, folded = _picture(True, features=(LayerFeature, WriteAfter))
    reference, _ = _picture(False, features=(LayerFeature,))
    assert folded == [False]
    assert np.array_equal(picture, reference)
