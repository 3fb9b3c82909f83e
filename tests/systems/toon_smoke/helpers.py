"""Shared helpers of the toon_smoke tests: small configs, states and scenes."""

from __future__ import annotations

import tomllib
from pathlib import Path

import numpy as np

from components.toon_smoke import ToonSmokeVolumeConfig
from systems.toon_smoke import simulate

ROOT = Path(__file__).resolve().parents[3]
CONFIGS = ROOT / "configs"
PRESETS = CONFIGS / "effects" / "toon_smoke"
PRESET_NAMES = ("paper", "chimney", "explosion")


def preset(name: str, **overrides) -> ToonSmokeVolumeConfig:
    data = tomllib.loads((PRESETS / f"{name}.toml").read_text(encoding="utf-8"))
    data.update(overrides)
    return ToonSmokeVolumeConfig.model_validate(data)


def small(**overrides) -> ToonSmokeVolumeConfig:
    """A 16³ / 32³ volume of 2 m with one source below a sphere obstacle (fast enough for unit tests)."""
    data = dict(simulation_resolution=[16, 16, 16], display_resolution=[32, 32, 32], extent=[2.0, 2.0, 2.0],
                particle_count=200, obstacle_radius=0.3, blob_radius=0.1, blob_radius_max=0.15,
                blob_stretch_max=1.5, noise_octaves=1,
                sources=[dict(name="jet", position=[0.0, -0.7, 0.0], radius=0.25, density_rate=6.0,
                              temperature_rate=4.0, velocity=[0.0, 1.5, 0.0])])
    data.update(overrides)
    return ToonSmokeVolumeConfig.model_validate(data)


def run_state(cfg: ToonSmokeVolumeConfig, steps: int, seed: int = 0, dt: float = 1.0 / 30.0, mesh: bool = False):
    """A state stepped ``steps`` times without a world (the volume at the origin, unrotated)."""
    from engine.spatial import Transform

    rng = np.random.default_rng(seed)
    state = simulate.new_state(cfg, rng)
    transform = Transform()
    for _ in range(steps):
        simulate.step_volume(None, 1, transform, cfg, state, dt, rng)
        if mesh:
            simulate.mesh_step(cfg, state)
    return state


def scene_text(preset_name: str, seed: int = 3, camera: bool = True, extra: str = "") -> str:
    """A scene with one volume using ``preset_name`` (and a camera looking at it)."""
    cam = """
[[entities]]
name = "camera"
[entities.components.Transform]
[entities.components.Camera]
controller = "orbit"
target = [0.0, 0.2, 0.0]
distance = 6.5
yaw = 15.0
pitch = -6.0
""" if camera else ""
    return f"""
[scene]
name = "toon_smoke_test"
seed = {seed}
fixed_dt = 0.0333333
plugins = ["render", "toon_smoke"]
{cam}
[[entities]]
name = "smoke"
[entities.components.Transform]
position = [0.0, 0.0, 0.0]
[entities.components.ToonSmokeVolume]
preset = "toon_smoke/{preset_name}"
{extra}
"""


def make_app(tmp_path: Path, text: str, seed: int | None = None):
    from engine.app import App

    path = tmp_path / "scene.toml"
    path.write_text(text, encoding="utf-8")
    return App(path, seed=seed, configs_root=CONFIGS)
