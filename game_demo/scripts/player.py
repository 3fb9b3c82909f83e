"""The player: WASD to move, right mouse to look, Space / left click to fire, 1-8 for the beam pattern,
Tab to switch the top view between minimap and split screen.  A third-person camera follows."""

from __future__ import annotations

import math

import numpy as np
from pydantic import Field

from engine import exact
from engine.config import ConfigModel, Vec4
from engine.script import Script, script
from engine.spatial import Transform, quat_from_euler, quat_rotate
from game_demo.scripts.common import PATTERNS, find_named, game_state, ground_height, terrain_extent


@script("demo.player")
class Player(Script):
    class Params(ConfigModel):
        move_speed: float = Field(9.0, ge=0.0, le=100.0, description="Metres per second.")
        look_sensitivity: float = Field(0.25, ge=0.0, le=10.0, description="Degrees per pixel of mouse motion.")
        eye_height: float = Field(1.6, ge=0.0, le=20.0, description="Metres above the ground.")
        camera_distance: float = Field(7.0, ge=0.0, le=100.0, description="Third-person camera distance.")
        camera_height: float = Field(2.5, ge=0.0, le=100.0, description="Third-person camera height.")
        fire_cooldown: float = Field(0.6, ge=0.0, le=10.0, description="Seconds between shots.")
        main_camera: str = Field("main_camera", description="Name of the camera entity that follows the player.")
        top_camera: str = Field("top_camera", description="Name of the top-view camera entity.")
        minimap_viewport: Vec4 = Field((0.72, 0.62, 0.27, 0.36), description="Top view as a minimap.")
        split_main_viewport: Vec4 = Field((0.0, 0.0, 0.5, 1.0), description="Main view in split screen.")
        split_top_viewport: Vec4 = Field((0.5, 0.0, 0.5, 1.0), description="Top view in split screen.")
        minimap_update_interval: int = Field(2, ge=1, le=10,
                                             description="The minimap redraws every N frames (a small picture: "
                                                         "half the rate saves ~a fifth of the frame on a software "
                                                         "rasteriser); the split screen's top view every frame.")
        start_yaw: float = Field(0.0, ge=-360.0, le=360.0, description="Initial heading in degrees.")
        start_pitch: float = Field(-4.0, ge=-89.0, le=89.0, description="Initial pitch in degrees (negative: down).")
        pitch_min: float = Field(-60.0, ge=-89.0, le=0.0, description="Lowest look pitch in degrees.")
        pitch_max: float = Field(40.0, ge=0.0, le=89.0, description="Highest look pitch in degrees.")
        edge_margin: float = Field(2.0, ge=0.0, le=100.0,
                                   description="Metres kept between the player and the terrain's edge.")
        camera_look_down: float = Field(8.0, ge=-45.0, le=45.0,
                                        description="Degrees the follow camera looks below the player's aim.")
        start_pattern: str = Field("A", pattern="^[A-H]$",
                                   description="Beam pattern (A-H, the paper's figure 3.1) set when the run starts; "
                                               "the HUD shows it. Keys 1-8 pick another.")
        area_half_size: float = Field(50.0, gt=0.0, le=10000.0,
                                      description="Half the side of the playable square (metres) when the scene "
                                                  "has no terrain (with one, the terrain's extent).")

    def on_start(self) -> None:
        self.yaw = math.radians(self.params.start_yaw)
        self.pitch = math.radians(self.params.start_pitch)
        self.cooldown = 0.0
        state = game_state(self.ctx)
        state.top_view = "minimap"
        self._apply_viewports(state)
        self.ctx.call("energy_wave.set_pattern", pattern=self.params.start_pattern)  # the beam is what the HUD says
        state.pattern = self.params.start_pattern

    # -------------------------------------------------------------- helpers
    def _top_rect(self) -> tuple[float, float, float, float]:
        return tuple(self.params.minimap_viewport if game_state(self.ctx).top_view == "minimap"
                     else self.params.split_top_viewport)

    def _apply_viewports(self, state) -> None:
        main = find_named(self.ctx, self.params.main_camera)
        top = find_named(self.ctx, self.params.top_camera)
        full = (0.0, 0.0, 1.0, 1.0)
        main_rect = full if state.top_view == "minimap" else self.params.split_main_viewport
        top_rect = self.params.minimap_viewport if state.top_view == "minimap" else self.params.split_top_viewport
        top_interval = self.params.minimap_update_interval if state.top_view == "minimap" else 1
        for entity, rect, interval in ((main, main_rect, 1), (top, top_rect, top_interval)):
            if entity is not None:
                self.ctx.call("render.camera", camera=entity, viewport=tuple(rect), update_interval=interval)

    # -------------------------------------------------------------- update
    def on_update(self, dt: float) -> None:
        state = game_state(self.ctx)
        inp = self.ctx.input
        if inp.was_pressed("tab"):
            state.top_view = "split" if state.top_view == "minimap" else "minimap"
            self._apply_viewports(state)
        if state.phase != "playing" or state.paused:
            self._follow_camera()
            return
        for i, letter in enumerate(PATTERNS):
            if inp.was_pressed(str(i + 1)):
                self.ctx.call("energy_wave.set_pattern", pattern=letter)
                state.pattern = letter
        if inp.is_down("mouse_right"):
            dx, dy = inp.mouse_delta
            self.yaw -= math.radians(dx * self.params.look_sensitivity)
            self.pitch = float(np.clip(self.pitch + math.radians(dy * self.params.look_sensitivity),
                                       math.radians(self.params.pitch_min), math.radians(self.params.pitch_max)))
        t = self.ctx.get(Transform)
        move = np.array([inp.is_down("d") - inp.is_down("a"), 0.0, inp.is_down("s") - inp.is_down("w")], float)
        if move.any():
            heading = quat_from_euler(self.yaw, 0.0, 0.0)
            step = quat_rotate(heading, move / exact.length(move)) * self.params.move_speed * dt
            limit = max(terrain_extent(self.ctx, self.params.area_half_size) - self.params.edge_margin, 0.0)
            t.position[0] = float(np.clip(t.position[0] + step[0], -limit, limit))
            t.position[2] = float(np.clip(t.position[2] + step[2], -limit, limit))
        t.position[1] = ground_height(self.ctx, t.position[0], t.position[2]) + self.params.eye_height
        t.rotation = quat_from_euler(self.yaw, self.pitch, 0.0)
        self.cooldown = max(0.0, self.cooldown - dt)
        fire = inp.was_pressed("space") or (inp.was_pressed("mouse_left") and not self._mouse_in_top_view())
        if fire and self.cooldown == 0.0:
            self.ctx.call("energy_wave.fire")
            self.cooldown = self.params.fire_cooldown
        self._follow_camera()

    def _mouse_in_top_view(self) -> bool:
        w, h = self.ctx.window_size
        x, y, rw, rh = self._top_rect()
        mx, my = self.ctx.input.mouse
        return x * w <= mx <= (x + rw) * w and y * h <= my <= (y + rh) * h

    def _follow_camera(self) -> None:
        cam = find_named(self.ctx, self.params.main_camera)
        if cam is None:
            return
        t = self.ctx.get(Transform)
        ct = self.ctx.get(Transform, cam)
        look = quat_from_euler(self.yaw, self.pitch - math.radians(self.params.camera_look_down), 0.0)
        back = quat_rotate(look, np.array([0.0, 0.0, 1.0]))
        ct.position = t.position + back * self.params.camera_distance + np.array([0.0, self.params.camera_height, 0.0])
        ct.rotation = look
