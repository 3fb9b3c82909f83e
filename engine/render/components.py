"""Rendering components and camera math; no GL here, so headless simulation can use them.

* :class:`CameraConfig` / :class:`Camera`: perspective or orthographic, a viewport rectangle (so a
  second camera is a minimap or a split screen), and a controller driven by input in the input stage
  (``orbit``, ``fly``, ``top``), which keeps camera motion part of the deterministic simulation.
* :class:`MeshConfig`: a lit box, sphere or plane drawn with the entity's Transform.
* :class:`Hud`: text that scripts set and the overlay pass draws.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Literal

import numpy as np
from pydantic import Field, model_validator

from engine.config import Color3, ConfigModel, CrossFieldError, Vec3, Vec4
from engine import exact
from engine.exact import length, matvec, vecmat
from engine.input import InputState
from engine.spatial import Transform, cross, quat_from_euler, quat_rotate
from engine.world import World


class CameraConfig(ConfigModel):
    """A camera: projection, viewport rectangle and controller."""

    projection: Literal["perspective", "orthographic"] = Field("perspective")
    fov: float = Field(60.0, ge=5.0, le=150.0, description="Vertical field of view in degrees (perspective).")
    ortho_height: float = Field(40.0, ge=1e-3, le=1e5, description="World height of the view (orthographic).")
    near: float = Field(0.1, ge=1e-4, le=1e4, description="Near clip distance (a tenth of a millimetre at least: the projection is single precision).")
    far: float = Field(500.0, gt=0.0, le=1e6, description="Far clip distance.")
    viewport: Vec4 = Field((0.0, 0.0, 1.0, 1.0),
                           description="x, y, width, height as fractions of the window (origin bottom-left).")
    priority: int = Field(0, ge=-100, le=100, description="Views render in ascending priority; the lowest is main.")
    controller: Literal["none", "orbit", "fly", "top"] = Field("orbit")
    target: Vec3 = Field((0.0, 0.0, 0.0), description="Orbit / top-view centre.")
    distance: float = Field(20.0, ge=1e-3, le=1e5, description="Orbit distance.")
    yaw: float = Field(30.0, ge=-360.0, le=360.0, description="Initial yaw in degrees.")
    pitch: float = Field(-25.0, ge=-89.0, le=89.0, description="Initial pitch in degrees (negative looks down).")
    move_speed: float = Field(10.0, ge=0.0, le=1000.0, description="Fly speed in metres per second.")
    look_sensitivity: float = Field(0.2, ge=0.0, le=10.0, description="Degrees per pixel of mouse motion.")
    border_color: Color3 = Field((0.9, 0.9, 0.9), description="Frame colour drawn around a partial viewport.")
    hide_features: list[str] = Field(default_factory=list, max_length=32,
                                     description="Render features not drawn in this view (e.g. 'grass_field' "
                                                 "in a minimap).")
    update_interval: int = Field(1, ge=1, le=60,
                                 description="Render this view every N frames and show its last picture in "
                                             "between (minimaps, monitors); the main view always renders.")
    shadows: bool = Field(True, description="Draw sun shadows in this view (with [render] shadows on); a map-like "
                                            "top view may leave them out.")
    enabled: bool = True

    @model_validator(mode="after")
    def _consistent(self) -> CameraConfig:
        if self.near >= self.far:
            raise CrossFieldError(("near", "far"), f"near ({self.near:g}) must be less than far ({self.far:g})")
        x, y, w, h = self.viewport
        if not (0.0 <= x < 1.0 and 0.0 <= y < 1.0 and 0.0 < w <= 1.0 and 0.0 < h <= 1.0
                and x + w <= 1.0 + 1e-6 and y + h <= 1.0 + 1e-6):
            raise CrossFieldError("viewport", f"viewport {list(self.viewport)} must lie inside the window: "
                                              "x, y in [0, 1), "
                             "width, height in (0, 1], x + width <= 1 and y + height <= 1")
        return self


@dataclass
class Camera:
    """Runtime camera: its config and the controller's angles."""

    config: CameraConfig
    yaw: float = 0.0
    pitch: float = 0.0
    distance: float = 20.0
    target: np.ndarray = field(default_factory=lambda: np.zeros(3))
    placed: tuple | None = field(default=None, repr=False, metadata={"hash": False})  # last _place: a cache


def build_camera(cfg: CameraConfig, ctx) -> Camera:
    cam = Camera(cfg, cfg.yaw, cfg.pitch, cfg.distance, np.array(cfg.target, float))
    transform = ctx.world.try_get(ctx.entity, Transform)
    if transform is not None and cfg.controller in ("orbit", "top"):
        _place(cam, transform)
    return cam


def _place(cam: Camera, t: Transform) -> None:
    """Set the transform of an orbit / top camera from its angles (float64 trig: deterministic).  Skipped when
    neither the angles, distance and target nor the transform changed since the last placement (most ticks)."""
    key = (cam.config.controller, cam.yaw, cam.pitch, cam.distance, tuple(cam.target))
    last = cam.placed
    if (last is not None and last[0] == key and np.array_equal(t.position, last[1])
            and np.array_equal(t.rotation, last[2])):
        return
    if cam.config.controller == "top":
        t.rotation = quat_from_euler(0.0, -math.pi / 2, 0.0)
        t.position = cam.target + np.array([0.0, cam.distance, 0.0])
    else:
        t.rotation = quat_from_euler(math.radians(cam.yaw), math.radians(cam.pitch), 0.0)
        back = quat_rotate(t.rotation, np.array([0.0, 0.0, 1.0]))
        t.position = cam.target + back * cam.distance
    cam.placed = (key, np.array(t.position, copy=True), np.array(t.rotation, copy=True))


def _inside(rect, point) -> bool:
    x, y, w, h = rect
    return x <= point[0] <= x + w and y <= point[1] <= y + h


def camera_controllers(world: World, dt: float) -> None:
    """Input stage: move cameras from this tick's input.

    A right-button drag turns the camera in whose viewport the press started (the highest-priority one
    there); the wheel zooms the orbit camera under the cursor.
    """
    inp = world.resource(InputState)
    cams = [(e, cam, t) for e, (cam, t) in world.query(Camera, Transform) if cam.config.enabled]
    window = window_size(world)
    under = None
    for e, cam, _ in sorted(cams, key=lambda c: (-c[1].config.priority, c[0])):
        if _inside(viewport_pixels(cam.config.viewport, window), inp.mouse):
            under = e
            break
    if inp.was_pressed("mouse_right"):
        cam_state = world.try_resource(CameraInput)
        if cam_state is None:
            cam_state = CameraInput()
            world.insert_resource(cam_state, state=True)
        cam_state.dragging = under
    drag = world.try_resource(CameraInput)
    dragging = drag.dragging if drag is not None and inp.is_down("mouse_right") else None
    for entity, cam, t in cams:
        cfg = cam.config
        if cfg.controller == "none":
            continue
        looking = dragging == entity
        dx, dy = inp.mouse_delta
        if looking and cfg.controller in ("orbit", "fly"):
            cam.yaw = (cam.yaw - dx * cfg.look_sensitivity) % 360.0
            cam.pitch = float(np.clip(cam.pitch + dy * cfg.look_sensitivity, -89.0, 89.0))
        if cfg.controller == "orbit":
            if inp.scroll and under == entity:
                cam.distance = float(np.clip(cam.distance * (0.9 ** inp.scroll), cfg.near * 4, cfg.far * 0.5))
            _place(cam, t)
        elif cfg.controller == "top":
            _place(cam, t)
        elif cfg.controller == "fly":
            t.rotation = quat_from_euler(math.radians(cam.yaw), math.radians(cam.pitch), 0.0)
            move = np.array([inp.is_down("d") - inp.is_down("a"), inp.is_down("e") - inp.is_down("q"),
                             inp.is_down("s") - inp.is_down("w")], float)
            if move.any():
                t.position = t.position + quat_rotate(t.rotation, move / length(move)) * cfg.move_speed * dt


@dataclass
class CameraInput:
    """Which camera a right-button drag started on (state: it decides what later ticks turn)."""

    dragging: int | None = None


# ------------------------------------------------------------------------ matrices
def perspective(fov_y: float, aspect: float, near: float, far: float) -> np.ndarray:
    """OpenGL perspective projection (column-vector convention), float64."""
    f = 1.0 / exact.tan_scalar(fov_y / 2.0)
    m = np.zeros((4, 4))
    m[0, 0] = f / aspect
    m[1, 1] = f
    m[2, 2] = (far + near) / (near - far)
    m[2, 3] = 2.0 * far * near / (near - far)
    m[3, 2] = -1.0
    return m


def orthographic(height: float, aspect: float, near: float, far: float) -> np.ndarray:
    """OpenGL orthographic projection of a view ``height`` world units tall."""
    w, h = height * aspect / 2.0, height / 2.0
    m = np.eye(4)
    m[0, 0] = 1.0 / w
    m[1, 1] = 1.0 / h
    m[2, 2] = -2.0 / (far - near)
    m[2, 3] = -(far + near) / (far - near)
    return m


def view_matrix(t: Transform) -> np.ndarray:
    """World -> camera: the inverse of the camera's rigid transform (scale ignored)."""
    r = t.rotation_matrix()
    m = np.eye(4)
    m[:3, :3] = r.T
    m[:3, 3] = -vecmat(t.position, r)
    return m


def look_at(eye, target, up=(0.0, 1.0, 0.0)) -> np.ndarray:
    eye, target, up = (np.asarray(v, float) for v in (eye, target, up))
    f = target - eye
    f /= length(f)
    s = cross(f, up)
    s /= length(s)
    u = cross(s, f)
    m = np.eye(4)
    m[0, :3], m[1, :3], m[2, :3] = s, u, -f
    m[:3, 3] = -matvec(m[:3, :3], eye)
    return m


def viewport_pixels(viewport, window: tuple[int, int]) -> tuple[int, int, int, int]:
    """(x, y, width, height) in whole pixels (origin bottom-left) of a viewport given as window fractions."""
    vx, vy, vw, vh = (float(a) for a in viewport)
    w, h = window
    return (int(round(vx * w)), int(round(vy * h)), max(1, int(round(vw * w))), max(1, int(round(vh * h))))


def projection(cfg: CameraConfig, width: int, height: int) -> np.ndarray:
    """The camera's projection for a viewport of ``width`` x ``height`` pixels."""
    aspect = width / height
    if cfg.projection == "perspective":
        return perspective(math.radians(cfg.fov), aspect, cfg.near, cfg.far)
    return orthographic(cfg.ortho_height, aspect, cfg.near, cfg.far)


def camera_matrices(cam: Camera, t: Transform, window: tuple[int, int]):
    """(view, proj, viewport pixels) exactly as the renderer builds them: for picking and projecting."""
    rect = viewport_pixels(cam.config.viewport, window)
    return view_matrix(t), projection(cam.config, rect[2], rect[3]), rect


def window_size(world: World) -> tuple[int, int]:
    """The window (or offscreen target) size in pixels: the renderer's when attached, else the scene's."""
    from engine.app import App

    app = world.try_resource(App)
    if app is None:
        return 960, 540
    renderer = app.renderer
    if renderer is not None:
        return renderer.width, renderer.height
    return app.config.render.width, app.config.render.height


# --------------------------------------------------------------------------- meshes
class MeshConfig(ConfigModel):
    """A lit primitive drawn with the entity's Transform (scale sizes it)."""

    shape: Literal["box", "sphere", "plane"] = Field("box", description="Unit box, unit-diameter sphere, unit plane.")
    color: Color3 = Field((0.7, 0.7, 0.7), description="Albedo (linear RGB).")
    emissive: float = Field(0.0, ge=0.0, le=100.0, description="Self-illumination multiplier of the albedo.")
    cast_shadows: bool = Field(True, description="Cast a sun shadow ([render] shadows); every mesh receives them.")
    visible: bool = True


@dataclass
class Hud:
    """Text drawn over the frame: ``lines`` top-left, ``center`` large in the middle, ``help`` on demand."""

    lines: list[str] = field(default_factory=list)
    center: str = ""
    help: list[str] = field(default_factory=list)
    show_help: bool = False
    show_fps: bool = False  # the renderer appends its measured frame rate (display only, not state)
