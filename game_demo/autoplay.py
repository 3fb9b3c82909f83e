"""The autoplay: a scripted player that plays the demo to the win screen.

It reads the game state and pushes :class:`~engine.input.InputEvent` objects into the world's
``InputQueue`` before every tick: the same path the window's keyboard and mouse events take, so the
game scripts cannot tell it from a person.  It reads only simulation state, so a run is deterministic:
same seed, same events, same final hash.

Policy, each tick: when the dust devil comes close, release the look button and drag the dust devil
away from the player in the top view (press, move, release); otherwise hold the right button and turn
(mouse motion) towards the nearest target, walk towards it when it is far, and press Space when aimed.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from components.energy_wave import EnergyWaveEmitter
from engine.app import App
from engine import exact
from engine.builtin import find_named
from engine.exact import matmul, matvec
from engine.input import InputEvent, InputQueue
from engine.render.components import Camera, camera_matrices, window_size
from engine.script import Scripts
from engine.spatial import Transform
from game_demo.scripts.common import GameState, Target
from game_demo.scripts.chaser import DustDevilChaser
from game_demo.scripts.player import Player
from game_demo.scripts.rules import GameRules


def script_params(world, entity_name: str, script_cls):
    """The parameters of ``script_cls`` on the entity named ``entity_name`` as the scene configured them (the
    script's defaults when the entity or the script is missing)."""
    entity = find_named(world, entity_name)
    scripts = None if entity is None else world.try_get(entity, Scripts)
    for slot in (scripts.slots if scripts is not None else []):
        if slot.name == script_cls.script_name:
            return slot.script.params
    return script_cls.Params()


def player_params(world) -> Player.Params:
    """The ``demo.player`` script's parameters as the scene configured them (its defaults without the script):
    the autoplay aims and fires with the look sensitivity and fire cooldown the player script applies."""
    return script_params(world, "player", Player)


def fire_range(world, share: float = 0.85) -> float:
    """Metres within which the pilot fires: ``share`` of the player's beam range (its EnergyWaveEmitter's
    ``beam_range``, as the scene or its preset sets it), so that a retuned beam keeps the pilot in reach."""
    player = find_named(world, "player")
    emitter = None if player is None else world.try_get(player, EnergyWaveEmitter)
    return share * (emitter.beam_range if emitter is not None else EnergyWaveEmitter.model_fields["beam_range"].default)


def danger_radius(world, reaction_seconds: float = 2.5) -> float:
    """Metres at which the pilot drags the dust devil away: the rules' ``lose_radius`` plus the distance the
    devil drifts (the chaser script's ``speed``) in ``reaction_seconds``."""
    rules = script_params(world, "game", GameRules)
    chaser = script_params(world, "dust_devil", DustDevilChaser)
    return rules.lose_radius + chaser.speed * reaction_seconds


@dataclass
class AutoPilot:
    fire_range: float | None = None  # metres; None: from the player's beam range (see fire_range())
    danger_radius: float | None = None  # metres; None: from the rules and the chaser (see danger_radius())
    drag_distance: float = 22.0
    max_turn_px: float = 60.0
    window: tuple[int, int] | None = None  # pixels; None: the engine's window size (the renderer's when one is
    # attached, else the scene's [render] size), the one the dust devil's drag turns pixels back into metres with
    holding: set[str] = field(default_factory=set)
    drag_plan: list[list[InputEvent]] = field(default_factory=list)
    fire_cooldown: int = 0
    mouse: tuple[float, float] = (480.0, 270.0)
    drags: int = 0
    shots: int = 0

    def __call__(self, app) -> None:
        queue = app.world.resource(InputQueue)
        for event in self.events(app.world):
            queue.push(event)

    # ---------------------------------------------------------------- helpers
    def _press(self, key: str, out: list[InputEvent]) -> None:
        if key not in self.holding:
            self.holding.add(key)
            kind = "button_down" if key in ("left", "right") else "key_down"
            out.append(InputEvent(kind, key, x=self.mouse[0], y=self.mouse[1]))

    def _release(self, key: str, out: list[InputEvent]) -> None:
        if key in self.holding:
            self.holding.discard(key)
            kind = "button_up" if key in ("left", "right") else "key_up"
            out.append(InputEvent(kind, key, x=self.mouse[0], y=self.mouse[1]))

    def _move_mouse(self, x: float, y: float, out: list[InputEvent]) -> None:
        out.append(InputEvent("mouse_move", x=x, y=y, dx=x - self.mouse[0], dy=y - self.mouse[1]))
        self.mouse = (x, y)

    def _turn(self, dx: float, dy: float, out: list[InputEvent]) -> None:
        """Relative look motion; the cursor is re-centred like a captured mouse."""
        out.append(InputEvent("mouse_move", x=self.mouse[0], y=self.mouse[1], dx=dx, dy=dy))

    # ------------------------------------------------------------------ policy
    def events(self, world) -> list[InputEvent]:
        out: list[InputEvent] = []
        state = world.try_resource(GameState)
        player = find_named(world, "player")
        if state is None or player is None or state.phase != "playing":
            for key in sorted(self.holding):
                self._release(key, out)
            return out
        if self.drag_plan:
            out.extend(self.drag_plan.pop(0))
            return out
        p = world.get(player, Transform)
        devil = find_named(world, "dust_devil")
        if devil is not None:
            d = world.get(devil, Transform).position
            danger = self.danger_radius if self.danger_radius is not None else danger_radius(world)
            if exact.hypot_scalar(d[0] - p.position[0], d[2] - p.position[2]) < danger:
                if self._plan_drag(world, p.position, d, out):
                    return out
        self._press("right", out)
        self._hunt(world, p, out)
        return out

    def _hunt(self, world, p: Transform, out: list[InputEvent]) -> None:
        params = player_params(world)
        sensitivity = params.look_sensitivity  # degrees per pixel
        targets = [(e, world.get(e, Transform).position) for e, _ in world.query(Target)]
        if not targets:
            self._release("w", out)
            return
        pos = p.position
        entity, goal = min(targets, key=lambda t: (exact.hypot_scalar(t[1][0] - pos[0], t[1][2] - pos[2]), t[0]))
        dx, dz = goal[0] - pos[0], goal[2] - pos[2]
        dist = exact.hypot_scalar(dx, dz)
        f = p.forward()
        yaw, pitch = exact.atan2(-f[0], -f[2]), exact.asin(max(-1.0, min(1.0, f[1])))
        want_yaw = exact.atan2(-dx, -dz)
        want_pitch = exact.atan2(goal[1] - pos[1], dist)
        err_yaw = (want_yaw - yaw + math.pi) % (2 * math.pi) - math.pi
        err_pitch = want_pitch - pitch
        px = float(np.clip(-math.degrees(err_yaw) / sensitivity, -self.max_turn_px, self.max_turn_px))
        py = float(np.clip(math.degrees(err_pitch) / sensitivity, -self.max_turn_px, self.max_turn_px))
        if abs(px) > 0.01 or abs(py) > 0.01:
            self._turn(px, py, out)
        reach = self.fire_range if self.fire_range is not None else fire_range(world)
        if dist > reach * 0.8:
            self._press("w", out)
        else:
            self._release("w", out)
        self.fire_cooldown = max(0, self.fire_cooldown - 1)
        if "space" in self.holding:
            self._release("space", out)
        elif abs(math.degrees(err_yaw)) < 2.5 and dist < reach and self.fire_cooldown == 0:
            self._press("space", out)
            # the player's cooldown in ticks, + 1 for its float countdown's rounding
            self.fire_cooldown = math.ceil(params.fire_cooldown / world.resource(App).dt - 1e-9) + 1
            self.shots += 1

    def _plan_drag(self, world, player_pos, devil_pos, out: list[InputEvent]) -> bool:
        """Press on the dust devil in the top view, move it away from the player, release."""
        top = find_named(world, "top_camera")
        if top is None:
            return False
        away = np.array([devil_pos[0] - player_pos[0], 0.0, devil_pos[2] - player_pos[2]])
        n = float(exact.length(away))
        away = away / n if n > 1e-6 else np.array([1.0, 0.0, 0.0])
        goal = devil_pos + away * self.drag_distance
        start_px = self._to_pixels(world, top, devil_pos)
        end_px = self._to_pixels(world, top, goal)
        if start_px is None or end_px is None:
            return False
        self._release("right", out)
        self._release("w", out)
        self._move_mouse(*start_px, out)
        self._press("left", out)
        steps = 6
        plan = []
        prev = start_px
        for i in range(1, steps + 1):
            cur = (start_px[0] + (end_px[0] - start_px[0]) * i / steps, start_px[1] + (end_px[1] - start_px[1]) * i / steps)
            plan.append([InputEvent("mouse_move", x=cur[0], y=cur[1], dx=cur[0] - prev[0], dy=cur[1] - prev[1])])
            prev = cur
        plan.append([InputEvent("button_up", "left", x=end_px[0], y=end_px[1])])
        self.mouse = end_px
        self.holding.discard("left")
        self.drag_plan = plan
        self.drags += 1
        return True

    def _to_pixels(self, world, camera_entity: int, point) -> tuple[float, float] | None:
        """Window pixel (origin bottom-left) of a world point seen by a camera, or None when outside."""
        view, proj, (x, y, pw, ph) = camera_matrices(world.get(camera_entity, Camera),
                                                      world.get(camera_entity, Transform),
                                                      self.window or window_size(world))
        clip = matvec(matmul(proj, view), [point[0], point[1], point[2], 1.0])
        ndc = clip[:3] / clip[3]
        if np.any(np.abs(ndc[:2]) > 0.98):
            return None
        return (x + (ndc[0] + 1.0) / 2.0 * pw, y + (ndc[1] + 1.0) / 2.0 * ph)
