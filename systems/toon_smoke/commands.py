"""Script commands of the toon_smoke plugin (``ctx.call("toon_smoke.set_source", ...)``, ``"toon_smoke.puff"``).

Both act on the caller's own ToonSmokeVolume unless ``volume`` names another entity (by id or by its scene name).
"""

from __future__ import annotations

from typing import Any

import numpy as np
from pydantic import ValidationError

from components.toon_smoke import SmokeSourceConfig, SourceState, ToonSmokeState, ToonSmokeVolumeConfig
from engine.config import ConfigError, model_problems, suggest
from engine.spatial import Transform, quat_conjugate, quat_rotate
from engine.world import World
from systems.toon_smoke.simulate import _geometry, ball_points


def _volume(world: World, entity: int, volume: int | str | None) -> tuple[int, ToonSmokeVolumeConfig,
                                                                          ToonSmokeState]:
    from engine.builtin import entity_ref

    target = entity if volume is None else entity_ref(world, volume, "volume")
    cfg = world.try_get(target, ToonSmokeVolumeConfig)
    state = world.try_get(target, ToonSmokeState)
    if cfg is None or state is None:
        raise ValueError(f"entity {target} has no ToonSmokeVolume (pass volume=<entity id or name>)")
    return target, cfg, state


def set_source(world: World, entity: int, name: str, volume: int | str | None = None, **changes: Any) -> None:
    """Change a source of a volume: any of ``enabled``, ``density_rate``, ``temperature_rate``, ``velocity``,
    ``velocity_jitter``, ``radial_speed``, ``position``, ``radius``, ``start_time``, ``duration`` (validated like
    the TOML keys; a bad value raises ConfigError naming the key)."""
    _, _, state = _volume(world, entity, volume)
    found = {s.name: s for s in state.sources}
    if name not in found:
        close = suggest(name, found)
        raise ValueError(f"no smoke source named '{name}'" + (f"; did you mean '{close}'?" if close else "")
                         + f" (sources: {', '.join(found) or 'none'})")
    source = found[name]
    current = {"name": source.name, "position": list(source.position), "radius": source.radius,
               "density_rate": source.density_rate, "temperature_rate": source.temperature_rate,
               "velocity": list(source.velocity), "velocity_jitter": source.velocity_jitter,
               "radial_speed": source.radial_speed,
               "start_time": source.start_time, "duration": source.duration, "enabled": source.enabled}
    values = {k: list(v) if isinstance(v, (tuple, np.ndarray)) else v for k, v in changes.items()}
    try:
        cfg = SmokeSourceConfig.model_validate({**current, **values})
    except ValidationError as exc:
        raise ConfigError(model_problems(exc, SmokeSourceConfig, "toon_smoke.set_source", ())) from None
    updated = SourceState.from_config(cfg)
    for attr in vars(updated):
        setattr(source, attr, getattr(updated, attr))


def puff(world: World, entity: int, position=None, radius: float = 0.6, density: float = 2.0,
         temperature: float = 3.0, speed: float = 3.0, particles: int = 0, volume: int | str | None = None,
         local: bool = False) -> None:
    """An explosion burst: add ``density`` and ``temperature`` inside a sphere and blow it outwards with ``speed``
    m/s at its surface (a divergence source 3·speed/radius for the next projection, Feldman et al. 2003);
    optionally move the ``particles`` oldest particles into it so blobs appear at once.

    ``position`` is in world coordinates (local to the volume with ``local=True``; default: the volume's centre).
    """
    target, cfg, state = _volume(world, entity, volume)
    if not (0.0 < radius <= 1000.0 and 0.0 <= density <= 1000.0 and 0.0 <= temperature <= 1000.0
            and -100.0 <= speed <= 100.0 and 0 <= particles):
        raise ValueError(f"toon_smoke.puff: radius {radius} must be in (0, 1000], density and temperature in "
                         f"[0, 1000], speed in [-100, 100], particles ≥ 0")
    transform = world.get(target, Transform)
    centre = np.zeros(3) if position is None else np.asarray(position, float)
    if position is not None and not local:
        centre = quat_rotate(quat_conjugate(transform.rotation), centre - transform.position)
    geo = _geometry(cfg, state)
    x, y, z = geo.local_centres()
    dist2 = (x - centre[0]) ** 2 + (y - centre[1]) ** 2 + (z - centre[2]) ** 2
    profile = np.clip(1.0 - dist2 / radius ** 2, 0.0, 1.0).astype(np.float32)
    if state.solid is not None:
        profile[state.solid] = 0.0
    state.density = np.minimum(state.density + np.float32(density) * profile, np.float32(cfg.density_limit))
    state.temperature = np.minimum(state.temperature + np.float32(temperature) * profile,
                                   np.float32(cfg.temperature_limit))
    state.expansion = state.expansion + np.float32(3.0 * speed / radius) * (profile > 0.0)
    count = min(int(particles), len(state.particles))
    if count:
        rng = world.random.stream("toon_smoke", target)
        oldest = np.argsort(-state.particle_age, kind="stable")[:count]
        points = ball_points(rng, centre, radius, count)
        state.particles[oldest] = np.clip(points, -0.5 * geo.extent, 0.5 * geo.extent)
        state.particle_age[oldest] = 0.0
