"""The game's rules: timer, targets left, win and lose, pause, restart, help and HUD."""

from __future__ import annotations

from pydantic import Field

from engine import exact
from engine.config import ConfigModel
from engine.render.components import Hud
from engine.script import Script, script
from engine.spatial import Transform
from game_demo.scripts.common import Target, find_named, game_state

HELP = [
    "WASD  move            right mouse  look",
    "Space / left click    fire the energy wave",
    "1-8   beam pattern A-H",
    "drag in the top view  push the dust devil away",
    "Tab   minimap / split screen",
    "R restart   Esc pause   F1 help   F3 profiler   F5 reload configs",
]


@script("demo.rules")
class GameRules(Script):
    class Params(ConfigModel):
        time_limit: float = Field(120.0, gt=0.0, le=3600.0, description="Seconds to destroy every target.")
        lose_radius: float = Field(3.0, ge=0.0, le=100.0, description="Dust devil this close to the player: lost.")
        player: str = Field("player", description="Name of the player entity.")
        dust_devil: str = Field("dust_devil", description="Name of the dust devil entity.")

    def on_start(self) -> None:
        state = game_state(self.ctx)
        state.phase = "playing"
        state.time_left = self.params.time_limit
        state.paused = False
        self.ctx.call("render.hud", help=HELP, show_help=False, show_fps=True)

    def on_update(self, dt: float) -> None:
        state = game_state(self.ctx)
        inp = self.ctx.input
        if inp.was_pressed("r"):
            self.ctx.call("engine.restart")
        if inp.was_pressed("f1"):
            self.ctx.call("render.hud", show_help=not self.ctx.resource(Hud).show_help)
        if inp.was_pressed("escape") and state.phase == "playing":
            state.paused = self.ctx.call("engine.toggle_pause")
        targets = len(self.ctx.query(Target))
        state.targets_left = targets
        state.targets_total = max(state.targets_total, targets)
        if state.phase == "playing" and not state.paused:
            state.time_left = max(0.0, state.time_left - dt)
            if state.targets_total and targets == 0:
                state.phase = "won"
            elif state.time_left == 0.0:
                state.phase, state.message = "lost", "time is up"
            elif self._dust_devil_distance() < self.params.lose_radius:
                state.phase, state.message = "lost", "the dust devil caught you"
            if state.phase != "playing":
                self.ctx.call("engine.pause", paused=True)
        self._hud(state)

    def _dust_devil_distance(self) -> float:
        player = find_named(self.ctx, self.params.player)
        devil = find_named(self.ctx, self.params.dust_devil)
        if player is None or devil is None:
            return float("inf")
        a = self.ctx.get(Transform, player).position
        b = self.ctx.get(Transform, devil).position
        return float(exact.hypot_scalar(a[0] - b[0], a[2] - b[2]))

    def _hud(self, state) -> None:
        count = f"{state.targets_left}/{state.targets_total}" if state.targets_total else "-"  # none placed yet
        lines = [f"targets left {count}",
                 f"time {state.time_left:5.1f} s", f"pattern {state.pattern}", "F1 help"]
        center = ""
        if state.phase == "won":
            center = "YOU WIN!\npress R to play again"
        elif state.phase == "lost":
            center = f"YOU LOSE - {state.message}\npress R to try again"
        elif state.paused:
            center = "PAUSED\nEsc to resume"
        self.ctx.call("render.hud", lines=lines, center=center)
