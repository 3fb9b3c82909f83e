"""Every shipped scene (and gallery stage) builds, simulates and renders headless without an error."""

from pathlib import Path

import numpy as np
import pytest

from engine.app import App
from tests.render_utils import render_app

ROOT = Path(__file__).resolve().parents[1]
SCENES = sorted((ROOT / "configs" / "scenes").glob("*.toml")) + sorted((ROOT / "configs" / "gallery").glob("*.toml"))


@pytest.mark.parametrize("scene", SCENES, ids=lambda p: f"{p.parent.name}/{p.stem}")
def test_scene_runs_and_renders(scene):
    from engine.render.components import Camera

    app = App(scene, strict=True)
    image = np.asarray(render_app(app, 64, 40, frames=2, steps_per_frame=2), np.int16)
    assert image.std() > 1.0  # a picture, not a flat clear colour
    assert app.world.tick == 4
    # its entities draw something: the same frame without them (cameras kept) is a different picture
    bare = App(scene, strict=True)
    bare.step(4)
    for entity in [e for e in bare.world.entities if bare.world.try_get(e, Camera) is None]:
        bare.world.commands.despawn(entity)
    bare.world.commands.apply()
    empty = np.asarray(render_app(bare, 64, 40, frames=1, steps_per_frame=0), np.int16)
    assert (np.abs(image - empty).max(axis=2) > 24).mean() > 0.02


def test_gallery_command_renders_a_preset(tmp_path):
    import subprocess
    import sys

    out = tmp_path / "gallery"
    (out / "dust_devil").mkdir(parents=True)
    (out / "dust_devil" / "paper.png").write_bytes(b"rendered by an earlier run")
    res = subprocess.run([sys.executable, "-m", "engine", "gallery", "--out", str(out), "--only",
                          "toon_smoke/explosion", "--size", "96", "64"], capture_output=True, text=True, cwd=ROOT)
    assert res.returncode == 0, res.stderr[-2000:]
    assert (out / "toon_smoke" / "explosion.png").exists()
    index = (tmp_path / "gallery.md").read_text()
    assert "toon_smoke/explosion" in index and "explosion.png" in index
    # --only re-renders one preset; the page keeps the presets an earlier run drew (and lists no missing picture)
    assert "dust_devil/paper.png" in index and "small_whirl" not in index
