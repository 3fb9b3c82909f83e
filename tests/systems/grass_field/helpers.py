"""Shared helpers of the grass_field tests: small configs, fields and scenes."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from components.grass_field import GrassFieldConfig
from engine.config import read_toml
from systems.grass_field.layout import draw_field
from systems.grass_field.lod import CameraInput
from systems.grass_field.simulate import field_data

ROOT = Path(__file__).resolve().parents[3]
PRESETS = ROOT / "configs" / "effects" / "grass_field"
SHOWCASE = ROOT / "configs" / "scenes" / "grass_field_showcase.toml"


def paper_config(**overrides) -> GrassFieldConfig:
    """The paper preset (configs/effects/grass_field/paper.toml) with ``overrides``."""
    data, _ = read_toml(PRESETS / "paper.toml")
    data.update(overrides)
    return GrassFieldConfig.model_validate(data)


def make_field(cfg: GrassFieldConfig, seed: int = 1, height=None):
    """(state, data) of a field centred at the origin."""
    state = draw_field(cfg, np.random.default_rng(seed))
    return state, field_data(cfg, state, np.zeros(3), height)


def level_camera(position, yaw_deg: float, width: int = 640, fov_x_deg: float = 60.0,
                 pitch_deg: float = 0.0) -> CameraInput:
    """A camera at ``position`` looking along azimuth ``yaw_deg`` (0 = +x, 90 = +z), tilted by ``pitch_deg``."""
    yaw, pitch = np.radians(yaw_deg), np.radians(pitch_deg)
    forward = np.array([np.cos(pitch) * np.cos(yaw), np.sin(pitch), np.cos(pitch) * np.sin(yaw)])
    fov_y = 2.0 * np.arctan(np.tan(np.radians(fov_x_deg) / 2.0) * 0.75)
    return CameraInput(np.asarray(position, float), forward, np.radians(fov_x_deg), width, fov_y=fov_y)


def walkthrough(frames: int = 47, eye_height: float = 30.0):
    """The benchmark's fixed walk near the grid centre: (position, yaw) per frame (paper: 47 frames)."""
    t = np.linspace(0.0, 1.0, frames)
    x = -60.0 + 140.0 * t
    z = -30.0 + 60.0 * np.sin(np.pi * t)
    yaw = 20.0 + 100.0 * t
    return [((xi, eye_height, zi), yi) for xi, zi, yi in zip(x, z, yaw)]


def scene_text(grass: str, camera: str = "", terrain: bool = True, seed: int = 3) -> str:
    """A scene TOML with a GrassField table body ``grass`` (and optionally a camera table body)."""
    parts = [f'[scene]\nname = "grass_test"\nseed = {seed}\nplugins = ["render", "grass_field"]\n',
             "[render]\nfog_density = 0.0005\n"]
    if terrain:
        parts.append('[[entities]]\nname = "ground"\n[entities.components.Transform]\n'
                     '[entities.components.Terrain]\nsize_exponent = 5\nspacing = 80.0\namplitude = 12.0\n')
    parts.append(f'[[entities]]\nname = "grass"\n[entities.components.Transform]\n'
                 f'[entities.components.GrassField]\n{grass}\n')
    if camera:
        parts.append(f'[[entities]]\nname = "camera"\n{camera}\n')
    return "\n".join(parts)


def write_scene(tmp_path: Path, text: str, name: str = "scene.toml") -> Path:
    """Write a scene under ``tmp_path/configs/scenes`` with the repository's presets reachable."""
    scenes = tmp_path / "configs" / "scenes"
    scenes.mkdir(parents=True, exist_ok=True)
    effects = tmp_path / "configs" / "effects"
    if not effects.exists():
        effects.symlink_to(ROOT / "configs" / "effects")
    path = scenes / name
    path.write_text(text, encoding="utf-8")
    return path
