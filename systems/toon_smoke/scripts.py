"""Scripts shipped with the toon_smoke plugin (they use only the public scripting API)."""

from __future__ import annotations

from pydantic import Field

from engine.config import ConfigModel, Vec3
from engine.script import Script, script


@script("toon_smoke_puffer")
class Puffer(Script):
    """Fires ``toon_smoke.puff`` (an explosion burst) every ``interval`` seconds inside the entity's volume."""

    class Params(ConfigModel):
        interval: float = Field(2.0, gt=0.0, le=600.0, description="Seconds between puffs.")
        position: Vec3 = Field((0.0, -0.5, 0.0), description="Puff centre in the volume's local frame, metres.")
        radius: float = Field(0.6, gt=0.0, le=100.0, description="Puff radius, metres.")
        density: float = Field(2.5, ge=0.0, le=1000.0, description="Density added at the puff's centre.")
        temperature: float = Field(3.0, ge=0.0, le=1000.0, description="Temperature added at the centre.")
        speed: float = Field(2.0, ge=-100.0, le=100.0, description="Outward blast speed at the rim, m/s.")
        particles: int = Field(150, ge=0, le=100_000, description="Oldest particles moved into the puff.")
        volume: str | None = Field(None, description="Name of the volume entity (default: this entity).")

    def on_start(self) -> None:
        self.timer = 0.0  # the first puff after one interval

    def on_update(self, dt: float) -> None:
        self.timer += dt
        if self.timer >= self.params.interval:
            self.timer -= self.params.interval
            p = self.params
            self.ctx.call("toon_smoke.puff", position=p.position, local=True, radius=p.radius, density=p.density,
                          temperature=p.temperature, speed=p.speed, particles=p.particles, volume=p.volume)


SCRIPTS = [Puffer]
