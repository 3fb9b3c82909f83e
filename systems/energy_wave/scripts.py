"""Scripts that ship with the energy-wave plugin (they use only the public scripting API)."""

from __future__ import annotations

from pydantic import Field, field_validator

from components.energy_wave import PATTERNS
from engine.config import ConfigModel
from engine.script import Script, ScriptRuntime, script


@script("energy_wave_pattern_cycle")
class PatternCycle(Script):
    """Every ``interval`` seconds: switch the emitter to the next pattern (A–H) and fire a burst."""

    class Params(ConfigModel):
        interval: float = Field(2.0, gt=0.0, le=600.0, description="Seconds between bursts.")
        burst: float = Field(0.5, gt=0.0, le=600.0, description="Seconds each burst lasts.")
        patterns: str = Field("ABCDEFGH", min_length=1, max_length=64,
                              description="Patterns to cycle through, in order (letters A–H).")
        show_on_hud: bool = Field(True, description="Write the current pattern on the HUD when there is one.")

        @field_validator("patterns")
        @classmethod
        def _letters(cls, value: str) -> str:
            bad = sorted(set(value.upper()) - set(PATTERNS))
            if bad:
                raise ValueError(f"unknown pattern letters {bad}; expected letters from {''.join(PATTERNS)}")
            return value.upper()

    def on_start(self) -> None:
        self.timer = self.params.interval  # fire at once
        self.index = -1

    def on_update(self, dt: float) -> None:
        self.timer += dt
        if self.timer < self.params.interval:
            return
        self.timer = 0.0
        self.index = (self.index + 1) % len(self.params.patterns)
        pattern = self.params.patterns[self.index]
        self.ctx.call("energy_wave.set_pattern", pattern=pattern)
        self.ctx.call("energy_wave.fire", duration=self.params.burst)
        commands = self.ctx.resource(ScriptRuntime).registry.commands
        if self.params.show_on_hud and "render.hud" in commands:
            self.ctx.call("render.hud", lines=[f"energy wave pattern {pattern}"])
