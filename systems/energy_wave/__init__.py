"""The energy_wave plugin (seeds/000): the EnergyWaveEmitter component, its simulation system, script commands
and (lazily, so the simulation never imports GL) its render feature.

Script commands (``ctx.call(name, ...)``; ``emitter=`` addresses another entity than the script's own):

- ``energy_wave.fire(duration=None, count=None)``: a burst at ``emission_rate`` for ``duration`` seconds
  (default ``burst_duration``), or ``count`` particles spread over ``burst_duration``;
- ``energy_wave.set_emitting(emitting=True)``: continuous emission on or off;
- ``energy_wave.set_pattern(pattern="A")``: apply the shape parameters of one of the patterns A–H;
- ``energy_wave.configure(**fields)``: change any EnergyWaveEmitter fields (validated; ConfigError on bad values).
"""

from __future__ import annotations

import math

from typing import Any

from components.energy_wave import PATTERN_PARAMETERS, EnergyWaveEmitter, EnergyWaveState, build_energy_wave
from engine.config import validate
from engine.registry import Registry
from engine.schedule import Stage
from engine.world import World

from .scripts import PatternCycle
from .simulate import simulate_system

__all__ = ["plugin", "fire", "set_emitting", "set_pattern", "configure"]


def _target(world: World, entity: int, emitter: int | str | None) -> tuple[int, EnergyWaveEmitter, EnergyWaveState]:
    from engine.builtin import entity_ref

    target = entity if emitter is None else entity_ref(world, emitter, "emitter")
    cfg = world.try_get(target, EnergyWaveEmitter)
    state = world.try_get(target, EnergyWaveState)
    if cfg is None or state is None:
        raise ValueError(f"entity {target} has no EnergyWaveEmitter (pass emitter=<entity id or name> to address another one)")
    return target, cfg, state


def fire(world: World, entity: int, duration: float | None = None, count: int | None = None,
         emitter: int | str | None = None) -> None:
    """Command ``energy_wave.fire``: start a burst (see the module docstring)."""
    _, cfg, state = _target(world, entity, emitter)
    seconds = float(duration) if duration is not None else cfg.burst_duration
    if not (math.isfinite(seconds) and seconds > 0.0):
        raise ValueError(f"energy_wave.fire: duration must be a finite number > 0, got {duration}")
    if count is not None:
        if not (math.isfinite(float(count)) and count >= 0):
            raise ValueError(f"energy_wave.fire: count must be a finite number >= 0, got {count}")
        state.burst_rate = float(count) / seconds
    else:
        state.burst_rate = cfg.emission_rate
    state.burst_time_left = seconds


def set_emitting(world: World, entity: int, emitting: bool = True, emitter: int | str | None = None) -> None:
    """Command ``energy_wave.set_emitting``: continuous emission on or off."""
    _, _, state = _target(world, entity, emitter)
    state.emitting = bool(emitting)


def configure(world: World, entity: int, emitter: int | str | None = None, **fields: Any) -> EnergyWaveEmitter:
    """Command ``energy_wave.configure``: replace fields of the emitter's config; raises ConfigError when invalid."""
    target, cfg, _ = _target(world, entity, emitter)
    data = {**cfg.model_dump(mode="json", warnings=False), **fields}
    new = validate(EnergyWaveEmitter, data, f"<energy_wave.configure entity {target}>")
    world.add(target, new)
    return new


def set_pattern(world: World, entity: int, pattern: str = "A", emitter: int | str | None = None) -> EnergyWaveEmitter:
    """Command ``energy_wave.set_pattern``: make every hit particle join ``pattern`` (A–H) from now on."""
    key = str(pattern).strip().upper()
    if key not in PATTERN_PARAMETERS:
        raise ValueError(f"energy_wave.set_pattern: unknown pattern {pattern!r}; expected one of "
                         f"{', '.join(PATTERN_PARAMETERS)}")
    return configure(world, entity, emitter=emitter, **PATTERN_PARAMETERS[key])


def live_update(old: EnergyWaveEmitter, new: EnergyWaveEmitter, world: World, entity: int) -> None:
    """Hot reload, after the config was swapped in place: adjust the state the build derived from the config.

    ``max_particles`` resizes the particle buffer keeping the live particles (the first ``max_particles`` when it
    shrinks); ``emitting`` seeds ``state.emitting`` at build time, so an edit of it in the file switches the
    emission now (scripts keep switching it with ``energy_wave.set_emitting`` between edits).
    """
    state = world.try_get(entity, EnergyWaveState)
    if state is None:
        return
    if state.particles.capacity != new.max_particles:
        state.particles.grow(new.max_particles)
    if new.emitting != old.emitting:
        state.emitting = new.emitting


def _make_feature(renderer):
    from .render import EnergyWaveFeature

    return EnergyWaveFeature(renderer)


class _Plugin:
    name = "energy_wave"

    def build(self, registry: Registry) -> None:
        # Hot reload: nothing needs a rebuild.  The state holds the particles (sized by max_particles: resized by
        # live_update, keeping them), the emission clock and a noise seed drawn from the entity's stream; every
        # other key is read from the config each step (simulate.py) or each frame (render.py).
        registry.add_component("EnergyWaveEmitter", EnergyWaveEmitter, build_energy_wave, preset_dir="energy_wave",
                               structural=(), live_update=live_update)
        registry.add_system(simulate_system, Stage.SIMULATION, name="energy_wave.simulate")
        registry.add_command("energy_wave.fire", fire)
        registry.add_command("energy_wave.set_emitting", set_emitting)
        registry.add_command("energy_wave.set_pattern", set_pattern)
        registry.add_command("energy_wave.configure", configure)
        registry.add_script(PatternCycle)
        registry.add_render_feature(_make_feature, "energy_wave")


plugin = _Plugin()
