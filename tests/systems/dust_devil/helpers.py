"""Small scenes for the dust devil tests (written to a temporary folder)."""

from __future__ import annotations

from pathlib import Path

from components.dust_devil import DustDevilConfig, DustDevilState
from engine.app import App
from engine.spatial import Transform

TERRAIN = """
[[entities]]
name = "ground"
[entities.components.Transform]
position = [0.0, 0.0, 0.0]
[entities.components.Terrain]
size_exponent = {exponent}
spacing = 2.0
amplitude = {amplitude}
roughness = 0.55
"""

DEVIL = """
[[entities]]
name = "devil"
[entities.components.Transform]
position = [{x}, {y}, {z}]
[entities.components.DustDevil]
{options}
"""


def scene_text(seed: int = 1, terrain: bool = True, amplitude: float = 5.0, exponent: int = 5,
               position=(0.0, -3.0, 0.0), **options) -> str:
    lines = [f'[scene]\nseed = {seed}\nplugins = ["render", "dust_devil"]\n']
    if terrain:
        lines.append(TERRAIN.format(exponent=exponent, amplitude=amplitude))
    opts = "\n".join(f"{k} = {_toml(v)}" for k, v in options.items())
    lines.append(DEVIL.format(x=position[0], y=position[1], z=position[2], options=opts))
    return "\n".join(lines)


def _toml(v) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, str):
        return f'"{v}"'
    if isinstance(v, (list, tuple)):
        return "[" + ", ".join(_toml(x) for x in v) + "]"
    return repr(v)


def make_app(tmp_path: Path, name: str = "scene", seed: int = 1, extra: str = "", **kw) -> App:
    path = Path(tmp_path) / f"{name}.toml"
    path.write_text(scene_text(seed=seed, **kw) + extra, encoding="utf-8")
    return App(path, strict=True)


def devil(app: App):
    """(entity, Transform, DustDevilConfig, DustDevilState) of the first dust devil."""
    entity, (t, cfg, state) = app.world.query(Transform, DustDevilConfig, DustDevilState)[0]
    return entity, t, cfg, state
