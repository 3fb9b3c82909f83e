"""The dust devil drifts towards the player (the threat); the player drags it away in the top view."""

from __future__ import annotations

import numpy as np
from pydantic import Field

from engine import exact
from engine.config import ConfigModel
from engine.script import Script, script
from engine.spatial import Transform
from game_demo.scripts.common import find_named, game_state


@script("demo.dust_devil_chaser")
class DustDevilChaser(Script):
    class Params(ConfigModel):
        speed: float = Field(1.5, ge=0.0, le=50.0, description="Drift speed towards the player, m/s.")
        player: str = Field("player", description="Name of the player entity.")

    def on_update(self, dt: float) -> None:
        state = game_state(self.ctx)
        if state.phase != "playing" or state.paused:  # scripts run while paused (menus): the threat waits
            return
        player = find_named(self.ctx, self.params.player)
        if player is None:
            return
        here = self.ctx.get(Transform).position
        there = self.ctx.get(Transform, player).position
        d = np.array([there[0] - here[0], 0.0, there[2] - here[2]])
        dist = float(exact.length(d))
        if dist > 1e-6:
            step = d / dist * min(self.params.speed * dt, dist)
            self.ctx.call("dust_devil.drag", delta=step)
