"""Small builders shared by the water_surface tests: grids, bodies, states and scenes written to tmp_path."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from components.water_surface import WaterState, WaterSurface
from engine.spatial import quat_from_euler, quat_to_matrix
from systems.water_surface.geometry import BOX, SPHERE, Bodies, Grid

ROOT = Path(__file__).resolve().parents[3]
CONFIGS = ROOT / "configs"


def make_grid(n: int = 26, h: float = 0.4) -> Grid:
    """An n × n grid centred on the origin at rest level 0."""
    half = 0.5 * (n - 1) * h
    return Grid(n, n, h, -half, -half, 0.0)


def make_state(grid: Grid) -> WaterState:
    shape = (grid.nz, grid.nx)
    return WaterState(np.zeros(shape), np.zeros(shape), np.zeros(shape, bool), np.array([grid.x0, grid.z0]))


def box(x: float, z: float, half=(1.0, 0.5, 0.6), yaw: float = 0.0, pitch: float = 0.0, roll: float = 0.0,
        y: float = 0.0, entity: int = 7) -> Bodies:
    rot = quat_to_matrix(quat_from_euler(yaw, pitch, roll))[None]
    return Bodies(np.array([entity]), np.array([BOX], np.int8), np.array([half], float), np.array([0.5]),
                  np.array([[x, y, z]]), rot)


def sphere(x: float, z: float, radius: float = 0.5, y: float = 0.0, entity: int = 8) -> Bodies:
    return Bodies(np.array([entity]), np.array([SPHERE], np.int8), np.full((1, 3), 0.5), np.array([radius]),
                  np.array([[x, y, z]]), np.eye(3)[None])


def rigid_body_entity(name: str, position, scale=(1.0, 0.6, 0.8), rotation=(0.0, 0.0, 0.0), **rigid) -> str:
    """A scene's [[entities]] table: a RigidBody (its keys ``rigid``, written as TOML) with a Transform."""
    fields = "\n".join(f"{k} = {v!r}".replace("'", '"').replace("True", "true").replace("False", "false")
                       for k, v in rigid.items())
    return f"""
[[entities]]
name = "{name}"
[entities.components.Transform]
position = {list(position)}
rotation = {list(rotation)}
scale = {list(scale)}
[entities.components.RigidBody]
{fields}
"""


def water_config(**values) -> WaterSurface:
    base = dict(resolution=[26, 26], spacing=0.4, wave_speed=1.5, damping=1.0)
    base.update(values)
    return WaterSurface.model_validate(base)


def write_scene(tmp_path: Path, water: str, bodies: str = "", seed: int = 1, extra: str = "") -> Path:
    """A scene file with a water entity (TOML body ``water``) and optional extra entities."""
    text = f"""
[scene]
name = "test"
seed = {seed}
plugins = ["water_surface"]
{extra}
[[entities]]
name = "water"
[entities.components.Transform]
position = [0.0, 0.0, 0.0]
[entities.components.WaterSurface]
{water}
{bodies}
"""
    path = tmp_path / "scene.toml"
    path.write_text(text, encoding="utf-8")
    return path
