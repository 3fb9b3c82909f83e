"""The application: a registry, a world built from a scene, the schedule and the fixed-step clock.

    app = App("configs/scenes/sandbox.toml", seed=3)
    app.step(120)              # exactly 120 fixed ticks (the manual clock used by tests)
    print(app.state_hash())

A tick runs the input, script, simulation and post-simulation stages, applying deferred commands
after every system (the sync points) and advancing the event buffers at its end; after a batch of ticks
(:meth:`step`) the frame-update stage runs once (display-only state, engine/schedule.py).  Frames
(:meth:`advance`) run as many ticks as the accumulator holds, then render-extract and render when a
renderer is attached.
"""

from __future__ import annotations

import logging
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from engine.builtin import InputSource
from engine.config import ConfigError, Problem
from engine.input import InputQueue, InputState, KeySet
from engine.registry import Registry, available_plugins, default_registry
from engine.scene import SceneConfig, ScenePlan, plan_scene, read_scene, spawn_plan
from engine.schedule import FRAME_STAGES, TICK_STAGES, FixedClock, Stage
from engine.script import ScriptRuntime
from engine.state import Snapshot, restore, snapshot, state_hash
from engine.threads import limit_blas_threads
from engine.world import World

log = logging.getLogger("engine")
MAX_SEED = 2**63 - 1  # the [scene] seed's range (engine/scene.py)


@dataclass
class TimeControl:
    """World state resource: pause (simulation stages skipped) and a pending restart."""

    paused: bool = False
    restart_requested: bool = False


def is_paused(world: World) -> bool:
    """Whether ``world``'s game is paused (``engine.pause``): its simulation stages are skipped; input and scripts
    still run, and what advances game time there (a drag, a countdown, an animation) should wait too."""
    control = world.try_resource(TimeControl)
    return bool(control is not None and control.paused)


class App:
    """One running game: world + schedule + clock (+ an optional renderer)."""

    def __init__(self, scene: str | Path | None = None, *, registry: Registry | None = None,
                 seed: int | None = None, strict: bool = False, configs_root: Path | None = None) -> None:
        limit_blas_threads()  # many small arrays: BLAS threads only contend with the rasteriser (engine/threads.py)
        self.scene_path = Path(scene) if scene is not None else None
        if seed is not None and not (isinstance(seed, int) and 0 <= seed <= MAX_SEED):
            raise ConfigError([Problem("<arguments>", "seed", f"expected an integer in [0, {MAX_SEED}]", seed)])
        settings = self._read_settings(registry, configs_root) if self.scene_path else SceneConfig()
        self.config: SceneConfig = settings
        self.registry = registry or self._registry_for(settings)
        self.plan: ScenePlan | None = None
        if self.scene_path is not None:
            self.plan = plan_scene(self.scene_path, self.registry, configs_root)
            self.config = self.plan.config
            for warning in self.plan.warnings:
                log.warning("%s", warning)
        self.seed = int(self.config.scene.seed if seed is None else seed)
        self.seed_from_scene = seed is None  # hot reload: a [scene] seed edit then applies on restart (R)
        self.strict = strict
        self.schedule = self.registry.schedule
        self.clock = FixedClock(self.config.scene.fixed_dt, self.config.scene.max_catchup_steps)
        self.records = []
        self.restart_errors: list[str] = []  # why the last restart kept the running world (an asset broke)
        self.world = self._new_world()
        self.renderer: Any = None
        self.started = False
        self.frame_hooks: list[Callable[[App], None]] = []
        self.pre_tick: list[Callable[[App], None]] = []

    def _read_settings(self, registry: Registry | None, configs_root: Path | None) -> SceneConfig:
        """The scene's settings (they name the plugins); when they are bad, every problem of the file is
        reported at once, not only those of the ``[scene]`` table."""
        try:
            return read_scene(self.scene_path)[0]
        except ConfigError:
            plan_scene(self.scene_path, registry or default_registry(), configs_root)  # raises with them all
            raise

    def _registry_for(self, settings: SceneConfig) -> Registry:
        """The registry of the plugins the scene names (all installed ones when it names none).  A name that no
        installed package declares is left out here and reported by plan_scene, with the file, the key and the
        nearest name, as it is when App is given a registry, and together with the scene's other problems."""
        names = settings.scene.plugins
        if names is not None:
            available = set(available_plugins())
            names = [name for name in names if name in available]
        return default_registry(names)

    def _new_world(self) -> World:
        world = World(self.seed)
        world.insert_resource(ScriptRuntime(self.registry, strict=self.strict))
        world.insert_resource(self)  # systems reach the app (and its renderer) through the world
        world.insert_resource(TimeControl(), state=True)
        for setup in self.registry.world_setup:
            setup(world)
        records = spawn_plan(world, self.registry, self.plan) if self.plan is not None else []
        self.world, self.records = world, records  # only a fully built world replaces the running one
        return world

    @property
    def warnings(self) -> list[Problem]:
        """The scene's warnings (``Registry.add_scene_check``): legal but probably not meant; logged at load."""
        return list(self.plan.warnings) if self.plan is not None else []

    @property
    def dt(self) -> float:
        return self.clock.dt

    # ------------------------------------------------------------------ running
    def _run_stage(self, stage: Stage) -> None:
        world = self.world
        for system in self.schedule.stage(stage):
            system.fn(world, self.clock.dt)
            world.commands.apply()

    def startup(self) -> None:
        if not self.started:
            self.started = True
            self._run_stage(Stage.STARTUP)

    def tick(self) -> None:
        """One fixed step of game logic and simulation (simulation stages skipped while paused)."""
        self.startup()
        for hook in list(self.pre_tick):
            hook(self)  # e.g. an autopilot or a test harness injecting input for this tick
        control = self.world.resource(TimeControl)
        for stage in TICK_STAGES:
            if control.paused and stage in (Stage.SIMULATION, Stage.POST_SIMULATION):
                continue
            self._run_stage(stage)
        self.world.events.update()
        self.world.tick += 1
        if control.restart_requested:
            self.restart()

    def restart(self) -> None:
        """Rebuild the world from the current scene plan (same seed): the game's R key."""
        renderer, source = self.renderer, self.world.try_resource(InputSource)
        queue, held = self.world.try_resource(InputQueue), self.world.try_resource(InputState)
        try:
            self._new_world()
        except ConfigError as exc:  # an asset changed on disk since the scene loaded: keep playing this world
            self.world.resource(TimeControl).restart_requested = False
            self.restart_errors = [str(p) for p in exc.problems]
            log.error("restart failed; keeping the current world:\n%s", exc)
            return
        self.restart_errors = []
        if source is not None:
            self.world.insert_resource(source)
        if queue is not None:  # the window pushes its events into this object: it stays the world's queue
            self.world.insert_resource(queue)
        fresh = self.world.try_resource(InputState)
        if held is not None and fresh is not None:  # keys and buttons still held stay held (not pressed again)
            fresh.keys_down = KeySet(held.keys_down)
            fresh.mouse = held.mouse
        self.started = False
        self.renderer = renderer

    def step(self, n: int = 1) -> None:
        """Run exactly ``n`` ticks (the manual clock), then the frame-update stage once (when ``n`` >= 1)."""
        n = int(n)
        for _ in range(n):
            self.tick()
        if n > 0:
            self._run_stage(Stage.FRAME_UPDATE)

    def advance(self, real_dt: float, busy: float | None = None) -> int:
        """One frame: the ticks the accumulator allows and rendering. Returns the ticks run.

        ``busy``: how long the last frame's own work took, when the loop knows it apart from ``real_dt`` (a window
        with vsync, whose frame interval is rounded up to the display's refresh): what ``[render]
        dynamic_resolution`` judges (:meth:`engine.render.renderer.Renderer.frame_time`); else ``real_dt``.

        With ``[render] overlap_ticks`` (the default) the frame draws the state the previous frame left while
        its ticks run (:meth:`render_frame` ``overlap``): one frame more latency, the CPU and the GPU busy at
        once.  Otherwise the ticks run first, then the frame draws their result."""
        steps = self.clock.advance(real_dt)
        if self.renderer is not None:
            self.renderer.frame_time(real_dt if busy is None else busy)  # [render] dynamic_resolution
        if self.renderer is not None and self.config.render.overlap_ticks:
            self.render_frame(overlap=lambda: self.step(steps))
        else:
            self.step(steps)
            self.render_frame()
        return steps

    def render_frame(self, overlap: Callable[[], None] | None = None) -> None:
        """Render-extract and render stages (skipped when no renderer is attached).

        ``overlap``, typically the next frame's ticks (``lambda: app.step(1)``), runs exactly once during the
        frame: after render-extract has copied the state to draw, at the point where the renderer would first
        wait for the GPU (:meth:`engine.render.renderer.Renderer.draw`).  The picture is the one drawn without
        it, and the ticks are the same ticks, so state hashes do not change; the frame hooks run after both.
        """
        if self.renderer is None:
            if overlap is not None:
                overlap()
            return
        self.startup()
        self.renderer.pending_overlap = overlap
        try:
            for stage in FRAME_STAGES:
                for system in self.schedule.stage(stage):
                    system.fn(self.world, self.clock.dt)
        finally:
            overlap, self.renderer.pending_overlap = self.renderer.pending_overlap, None
        if overlap is not None:  # no render stage consumed it
            overlap()
        for hook in list(self.frame_hooks):
            hook(self)

    # ------------------------------------------------------------- determinism
    def state_hash(self) -> str:
        return state_hash(self.world)

    def snapshot(self) -> Snapshot:
        return snapshot(self.world)

    def restore(self, snap: Snapshot) -> None:
        restore(self.world, snap)
