"""The toon_smoke effect plugin: cartoon smoke and clouds (Kuroda, Dobashi & Yamamoto, seeds/002).

Registers the ``ToonSmokeVolume`` component (presets in configs/effects/toon_smoke/), the simulation system
(stable fluids + particles + noise on the display grid), the meshing system (marching cubes every step), the
script commands ``toon_smoke.set_source`` and ``toon_smoke.puff`` (and the ``toon_smoke_puffer`` script that fires
puffs on a timer), and the render feature (toon-ramp isosurface and
outline passes), which is imported lazily so that simulation never imports GL.
"""

from __future__ import annotations

from components.toon_smoke import ToonSmokeVolumeConfig, build_toon_smoke
from engine.registry import Registry
from engine.schedule import Stage
from systems.toon_smoke.commands import puff, set_source
from systems.toon_smoke.scripts import SCRIPTS
from systems.toon_smoke.simulate import mesh_system, simulate_system


def _make_feature(renderer):
    from systems.toon_smoke.render import ToonSmokeFeature

    return ToonSmokeFeature(renderer)


class ToonSmokePlugin:
    name = "toon_smoke"

    def build(self, registry: Registry) -> None:
        registry.add_component("ToonSmokeVolume", ToonSmokeVolumeConfig, build_toon_smoke, preset_dir="toon_smoke")
        registry.add_system(simulate_system, Stage.SIMULATION, name="toon_smoke.simulate")
        registry.add_system(mesh_system, Stage.POST_SIMULATION, name="toon_smoke.mesh")
        registry.add_command("toon_smoke.set_source", set_source)
        registry.add_command("toon_smoke.puff", puff)
        registry.add_scripts(SCRIPTS)
        registry.add_render_feature(_make_feature)


plugin = ToonSmokePlugin()
