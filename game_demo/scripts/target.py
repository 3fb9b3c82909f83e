"""A target: loses hit points to energy-wave impacts; destroyed, it bursts into a toon-smoke puff."""

from __future__ import annotations

from pydantic import Field

from engine import exact
from engine.config import ConfigModel
from engine.impacts import Impact
from engine.script import Script, script
from engine.spatial import Transform
from game_demo.scripts.common import Target, TargetDestroyed, game_state


@script("demo.target")
class TargetScript(Script):
    events = (Impact,)

    class Params(ConfigModel):
        hit_points: float = Field(30.0, gt=0.0, le=1e6, description="Damage it takes to destroy the target.")
        damage_per_impulse: float = Field(1.0, ge=0.0, le=1e6, description="Damage per N·s of impact impulse.")
        min_damage_per_hit: float = Field(1.0, ge=0.0, le=1e6, description="Damage of any energy-wave hit event.")
        smoke_prefab: str = Field("smoke_puff", description="Prefab spawned when destroyed (configs/prefabs/).")

    def on_start(self) -> None:
        self.destroyed = False
        self.ctx.commands.insert(self.ctx.entity, Target(self.params.hit_points, self.params.hit_points))

    def on_event(self, event: Impact) -> None:
        if self.destroyed or event.target != self.ctx.entity or event.kind != "energy_wave":
            return
        target = self.ctx.try_get(Target)
        if target is None:
            return
        damage = max(self.params.min_damage_per_hit,
                     float(exact.length(event.impulse)) * self.params.damage_per_impulse)
        target.hp = max(0.0, target.hp - damage)
        if target.hp == 0.0:
            self.destroyed = True
            pos = self.ctx.get(Transform).position.copy()
            self.ctx.spawn_prefab(self.params.smoke_prefab, position=pos)
            self.ctx.send(TargetDestroyed(self.ctx.entity, tuple(float(v) for v in pos)))
            game_state(self.ctx).destroyed.append(self.ctx.entity)
            self.ctx.despawn()
