"""The LOD cache's CPU side: the cache key, the disk cache, coverage-preserving mipmaps, the atlas, progress."""

from __future__ import annotations

import io

import numpy as np
import pytest

from systems.grass_field.impostor import (DiskCache, Progress, atlas_layout, bake_view_proj, cache_key,
                                          coverage_mipmaps, impostor_basis, tile_bounds, tile_frame, tile_pixels)
from systems.grass_field.layout import draw_field
from tests.systems.grass_field.helpers import paper_config


def _key(seed=1, **overrides):
    cfg = paper_config(**overrides)
    return cache_key(cfg, draw_field(cfg, np.random.default_rng(seed)), {"sun": [0.0, 1.0, 0.0]})


def test_cache_key_follows_what_the_images_depend_on():
    base = _key()
    assert base == _key()  # stable (hashlib on canonical JSON, never hash())
    assert len(base) == 64
    assert _key(leaf_width=1.3) != base  # the plants look different
    assert _key(seed=2) != base  # other random layouts
    assert _key(max_level=3, debug_levels=True, merge_distance=900.0) == base  # selection only


def test_cache_key_is_the_same_in_another_process():
    import subprocess
    import sys

    code = ("import numpy as np; from tests.systems.grass_field.helpers import paper_config;"
            "from systems.grass_field.layout import draw_field; from systems.grass_field.impostor import cache_key;"
            "cfg = paper_config(); print(cache_key(cfg, draw_field(cfg, np.random.default_rng(1)),"
            " {'sun': [0.0, 1.0, 0.0]}))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == _key()


def test_disk_cache_round_trip(tmp_path):
    cache = DiskCache(tmp_path / "cache")
    rng = np.random.default_rng(0)
    atlas = rng.integers(0, 255, (8, 16, 4), dtype=np.uint8)
    depth = rng.random((8, 16, 2)).astype(np.float16)
    normal = rng.integers(0, 255, (8, 16, 4), dtype=np.uint8)
    shapes = (atlas.shape, depth.shape, normal.shape)
    assert cache.load("k" * 64, *shapes) is None
    path = cache.store("k" * 64, atlas, depth, normal)
    assert path.is_file()
    loaded = cache.load("k" * 64, *shapes)
    assert all(np.array_equal(a, b) for a, b in zip(loaded, (atlas, depth, normal)))
    assert cache.load("k" * 64, (8, 8, 4), depth.shape, normal.shape) is None  # another layout: rebake
    assert cache.load("k" * 64, atlas.shape, (8, 8, 2), normal.shape) is None
    assert cache.load("k" * 64, atlas.shape, depth.shape, (8, 8, 4)) is None
    assert cache.load("j" * 64, *shapes) is None  # another key (the file name holds only its first 40 digits)
    np.savez_compressed(path, atlas=atlas, depth=depth, key=np.array("k" * 64))  # an older format: no normal image
    assert cache.load("k" * 64, *shapes) is None
    path.write_bytes(b"not a zip")
    assert cache.load("k" * 64, *shapes) is None  # unreadable: ignored, rebaked


def test_coverage_preserving_mipmaps():
    rng = np.random.default_rng(3)
    image = np.zeros((64, 64, 4), np.uint8)
    blades = rng.random((64, 64)) < 0.15  # thin, scattered grass texels
    image[blades] = (40, 90, 20, 255)
    mips = coverage_mipmaps(image, 3)
    assert [m.shape[:2] for m in mips] == [(32, 32), (16, 16), (8, 8)]
    base = (image[..., 3] >= 128).mean()
    for mip in mips:
        assert abs((mip[..., 3] >= 128).mean() - base) < 0.08  # up to the steps of a 2^k-texel box
    plain = image.astype(float).reshape(16, 4, 16, 4, 4).mean(axis=(1, 3))
    assert (plain[..., 3] >= 128).mean() < base / 10  # a plain box filter thins the grass out with distance


def test_tiles_cover_the_cell_in_every_view():
    frame = tile_frame(100.0, 10.0, 20.0, np.radians(10.0))
    c, s = np.cos(np.radians(30.0)), np.sin(np.radians(30.0))
    assert frame.half_width == pytest.approx(60.0 * (c + s))  # the widest of the 12 views: 15° off a diagonal
    corners = np.array([[x, y, z] for x in (-60, 60) for y in (0, 20) for z in (-60, 60)], float)
    for view in range(12):
        clip = bake_view_proj(view, frame) @ np.column_stack([corners, np.ones(8)]).T
        assert np.all(np.abs(clip[:3] / clip[3]) <= 1.0 + 1e-9)
    cfg = paper_config()
    w, h = tile_pixels(frame, cfg)
    assert w == pytest.approx(2 * frame.half_width * 0.75 / 0.5, abs=1)  # P₃₄ / L texels per unit


def test_impostor_basis_is_a_right_handed_frame_facing_the_viewer():
    right, up, normal = impostor_basis(np.radians(40.0), np.radians(10.0))
    assert np.allclose(np.cross(right, up), normal)
    assert np.allclose(normal[[0, 2]] / np.linalg.norm(normal[[0, 2]]), [np.cos(np.radians(40)), np.sin(np.radians(40))])


def test_atlas_layout_and_trimmed_tiles():
    lay = atlas_layout(96, 268, 75, 4096)
    assert lay.cols * lay.rows >= 96 and max(lay.size) <= 4096
    small = atlas_layout(96, 268, 75, 1024)
    assert max(small.size) <= 1024 and small.tile_w < 268
    image = np.zeros((lay.size[1], lay.size[0], 4), np.uint8)
    x, y, w, h = lay.viewport(7)
    image[y + 10:y + 20, x + 50:x + 60, 3] = 255
    bounds = tile_bounds(image, lay, margin=0)
    assert np.allclose(bounds[7], [50 / w, 10 / h, 60 / w, 20 / h])
    assert not bounds[6].any()  # an empty tile draws nothing


def test_progress_bar_only_for_long_bakes():
    now = [0.0]
    out = io.StringIO()
    bar = Progress("baking", 10, after=1.0, stream=out, clock=lambda: now[0])
    bar.update(3)
    assert out.getvalue() == ""
    now[0] = 2.0
    bar.update(5)
    bar.update(10)
    text = out.getvalue()
    assert "baking [" in text and "5/10" in text and "10/10" in text and text.endswith("s)\n")
