"""A terrain's ground texture (TerrainConfig.texture): tiled at texture_size metres, multiplied with the lit
colour ramp, the same on both shader paths; strength 0 is the plain terrain."""

import numpy as np
from PIL import Image

from engine.app import App
from engine.render import passes
from tests.render_utils import make_renderer, render_app

# straight down on a flat field: every pixel sees the same light, so the texture is all the image shows
SCENE = """
[scene]
name = "terrain-texture"
seed = 3

[render]
width = 160
height = 160
fog_density = 0.0

[[entities]]
name = "ground"
[entities.components.Transform]
[entities.components.Terrain]
size_exponent = 5
spacing = 2.0
amplitude = 0.0
{terrain}

[[entities]]
name = "camera"
[entities.components.Transform]
[entities.components.Camera]
projection = "orthographic"
ortho_height = 32.0
controller = "top"
target = [0.0, 0.0, 0.0]
distance = 40.0
"""


def _stripes(root) -> None:
    """64 x 64: the left half dark, the right half white (sRGB), so the picture is a square wave along x."""
    image = np.full((64, 64), 255, np.uint8)
    image[:, :32] = 40
    Image.fromarray(image, "L").save(root / "stripes.png")


def _render(tmp_path, terrain: str, vertex_shade: bool | None = None, level: int | None = None, monkeypatch=None):
    _stripes(tmp_path)
    path = tmp_path / "scene.toml"
    path.write_text(SCENE.format(terrain=terrain))
    if level is not None:
        monkeypatch.setattr(passes, "select_levels", lambda mesh, *a, **k: np.full(mesh.chunks, level, np.int64))
    app = App(path)
    renderer = make_renderer(app, 160, 160)
    if vertex_shade is not None:
        next(f for f in renderer.features if isinstance(f, passes.TerrainFeature)).vertex_shade = vertex_shade
    return np.asarray(render_app(app, 160, 160), np.float64)[..., :3].mean(axis=-1)


def _period(profile: np.ndarray) -> float:
    """The strongest period (pixels) of a 1-D profile, from its spectrum."""
    spectrum = np.abs(np.fft.rfft(profile - profile.mean()))
    k = int(np.argmax(spectrum[1:])) + 1
    return len(profile) / k


def test_the_texture_repeats_every_texture_size_metres(tmp_path):
    # 160 px for 32 m: 5 px a metre, so 8 m repeats every 40 px and 4 m every 20 px
    for size, pixels in ((8.0, 40.0), (4.0, 20.0)):
        image = _render(tmp_path, f'texture = "stripes.png"\ntexture_size = {size}')
        rows = image[20:140, :]
        assert rows.max() - rows.min() > 80  # dark and white stripes both show
        assert abs(_period(rows.mean(axis=0)) - pixels) < 1.0, size  # along x
        assert rows.std(axis=0).mean() < 3.0  # constant down each column: the stripes run along z


def test_the_texture_multiplies_the_plain_terrain_and_strength_zero_is_the_plain_terrain(tmp_path):
    plain = _render(tmp_path, "")
    none = _render(tmp_path, 'texture = "stripes.png"\ntexture_strength = 0.0')
    half = _render(tmp_path, 'texture = "stripes.png"\ntexture_size = 8.0\ntexture_strength = 0.5')
    full = _render(tmp_path, 'texture = "stripes.png"\ntexture_size = 8.0')
    assert plain.std() < 2.0 and np.abs(none - plain).max() <= 2.0
    # white texels keep the plain colour; dark ones (sRGB 40: 0.021 linear) darken it, half as much in linear
    # light at half strength (x 0.51; the tone map and sRGB output make that about 0.6 of the plain pixel value)
    assert np.isclose(full.max(), plain.mean(), atol=3.0) and np.isclose(half.max(), plain.mean(), atol=3.0)
    assert full.min() < 0.2 * plain.mean() and 0.5 * plain.mean() < half.min() < 0.7 * plain.mean()


def test_both_shader_paths_draw_the_same_texture(tmp_path, monkeypatch):
    """Full-detail chunks shade per vertex (Gouraud) and coarse ones per pixel; both multiply by the texture
    per pixel, so the stripes match."""
    terrain = 'texture = "stripes.png"\ntexture_size = 8.0'
    per_vertex = _render(tmp_path, terrain, vertex_shade=True, level=0, monkeypatch=monkeypatch)
    per_pixel = _render(tmp_path, terrain, vertex_shade=False, level=0, monkeypatch=monkeypatch)
    coarse = _render(tmp_path, terrain, vertex_shade=True, level=3, monkeypatch=monkeypatch)
    assert per_vertex.max() - per_vertex.min() > 80
    assert np.abs(per_vertex - per_pixel).mean() < 1.0 and np.abs(per_vertex - coarse).mean() < 1.0
