"""The toon_smoke effect plugin: cartoon smoke and clouds (Kuroda, Dobashi & Yamamoto, seeds/002).

Registers the ``ToonSmokeVolume`` component (presets in configs/effects/toon_smoke/), the simulation system
(stable fluids + particles, every tick), the display system (display grid with blobs and noise, and marching
cubes: once per frame, after the frame's ticks), the
script commands ``toon_smoke.set_source`` and ``toon_smoke.puff`` (and the ``toon_smoke_puffer`` script that fires
puffs on a timer), and the render feature (toon-ramp isosurface and
outline passes), which is imported lazily so that simulation never imports GL.
"""

from __future__ import annotations

from components.toon_smoke import SourceState, ToonSmokeState, ToonSmokeVolumeConfig, build_toon_smoke
from engine.registry import Registry
from engine.schedule import Stage
from systems.toon_smoke.commands import puff, set_source
from systems.toon_smoke.scripts import SCRIPTS
from systems.toon_smoke.simulate import display_system, simulate_system


# Hot reload.  Structural: the grids' shapes (simulation and display resolution), the cell size and every
# precomputed coordinate (Geometry from extent) and the particle array (particle_count).
STRUCTURAL = ("simulation_resolution", "display_resolution", "extent", "particle_count")
_OBSTACLE_KEYS = ("obstacle_radius", "obstacle_center", "open_sides")  # solid masks and the Poisson hierarchy
_NOISE_KEYS = ("noise_scale", "noise_strength", "noise_octaves")  # the noise factor, computed once


def live_update(old: ToonSmokeVolumeConfig, new: ToonSmokeVolumeConfig, world, entity: int) -> None:
    """After an in-place swap: drop the caches built from the changed keys and re-read the sources.

    The solid masks and hierarchy are cached on the transforms and colliders only, the noise factor is computed
    once, and the sources are copied into the state at build time (scripts change those copies): so they are
    rebuilt here when their keys changed.  A source whose config did not change keeps its runtime state.
    """
    state = world.try_get(entity, ToonSmokeState)
    if state is None:
        return
    state.display_step = -1  # re-derive the display grid and mesh with the new values, even while paused
    if any(getattr(old, k) != getattr(new, k) for k in _OBSTACLE_KEYS):
        state.solid_key = None  # update_obstacles rebuilds the masks and the hierarchy at the next step
        state.noise_factor = state.noise_key = None  # the noise is masked with the display solid
    if any(getattr(old, k) != getattr(new, k) for k in _NOISE_KEYS):
        state.noise_base = None
        state.noise_factor = state.noise_key = None
    if old.sources != new.sources:
        before = {cfg.name: cfg for cfg in old.sources}
        current = {s.name: s for s in state.sources}
        state.sources = [current[cfg.name] if before.get(cfg.name) == cfg and cfg.name in current
                         else SourceState.from_config(cfg) for cfg in new.sources]


def _make_feature(renderer):
    from systems.toon_smoke.render import ToonSmokeFeature

    return ToonSmokeFeature(renderer)


class ToonSmokePlugin:
    name = "toon_smoke"

    def build(self, registry: Registry) -> None:
        registry.add_component("ToonSmokeVolume", ToonSmokeVolumeConfig, build_toon_smoke, preset_dir="toon_smoke",
                               structural=STRUCTURAL, live_update=live_update)
        registry.add_system(simulate_system, Stage.SIMULATION, name="toon_smoke.simulate")
        registry.add_system(display_system, Stage.FRAME_UPDATE, name="toon_smoke.display")
        registry.add_command("toon_smoke.set_source", set_source)
        registry.add_command("toon_smoke.puff", puff)
        registry.add_scripts(SCRIPTS)
        registry.add_render_feature(_make_feature, "toon_smoke")


plugin = ToonSmokePlugin()
