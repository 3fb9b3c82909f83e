"""WaterSurface and RigidBody: config models and runtime state (seeds/003, Kosuge 2004, "Real-time water-surface
simulation considering wave generation and reflection by rigid bodies", plus floating bodies after its ref. [11]).

The water is a height field of (nx × nz) vertices P[i, j] with spacing h (section 2.2.1): ``heights[j, i]`` is the
displacement of P[i, j] above the water entity's position (engine axes: +y up, so the paper's z is our y and the
paper's horizontal (x, y) is our (x, z)). Waves follow the explicit wave equation (eq. 2.8–2.10); bodies cutting
the surface add points on their cross-section outline (2.2.2–2.2.3) that make waves (eq. 2.5–2.7) and take part
in the propagation (eq. 2.11, 2.12).

Units: metres, seconds, kilograms. No GL here: the simulation lives in ``systems/water_surface/``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Annotated, Literal

import numpy as np
from numpy.typing import NDArray
from pydantic import AfterValidator, Field, ValidationInfo, model_validator

from engine.collider import Collider
from engine.config import Color3, ConfigModel, CrossFieldError, Vec2, Vec3
from engine.heightfield import HeightField
from engine.registry import BuildContext

__all__ = [
    "MIN_FIXED_DT",
    "RigidBody",
    "RigidBodyState",
    "STABILITY_LIMIT",
    "WaterState",
    "WaterSurface",
    "build_rigid_body",
    "build_water_surface",
    "check_stability",
]

F64 = NDArray[np.float64]

STABILITY_LIMIT = 1.0 / math.sqrt(2.0)  # c·Δt/h of the explicit 2D scheme (k = c²Δt²/h² ≤ 1/2)
MIN_FIXED_DT = 1.0 / 1000.0  # the smallest [scene] fixed_dt the engine accepts (engine/scene.py)
MAX_GRID_POINTS = 1 << 22  # nx · nz cap (4 M vertices, 32 MB per float64 field)

GridCount = Annotated[int, Field(ge=3, le=2048)]


def _as_pair(v: list[int]) -> tuple[int, int]:
    return int(v[0]), int(v[1])


Resolution = Annotated[list[GridCount], Field(min_length=2, max_length=2), AfterValidator(_as_pair)]


def check_stability(wave_speed: float, spacing: float, dt: float, where: str = "") -> None:
    """Raise ``ValueError`` (a :class:`CrossFieldError` on wave_speed and spacing) if c·Δt/h exceeds the 2D
    limit 1/√2 of the explicit scheme (section 2.3.2).

    eq. 2.8 is stable for k = c²Δt²/h² ≤ 1/2 on the regular grid (each vertex has 4 neighbours: the update's
    coefficient 2 − 4k must stay ≥ 0).
    """
    courant = wave_speed * dt / spacing
    if courant <= STABILITY_LIMIT * (1.0 + 1e-12):
        return
    prefix = f"{where}: " if where else ""
    raise CrossFieldError(
        ("wave_speed", "spacing"),
        f"{prefix}wave_speed c = {wave_speed:g} m/s with spacing h = {spacing:g} m and fixed_dt Δt = {dt:g} s gives "
        f"c·Δt/h = {courant:.4f}, above the 2D stability limit 1/√2 ≈ {STABILITY_LIMIT:.4f} of the explicit "
        f"height-field scheme; lower 'wave_speed' to ≤ {STABILITY_LIMIT * spacing / dt:.4g} m/s, raise 'spacing' "
        f"to ≥ {wave_speed * dt / STABILITY_LIMIT:.4g} m, or lower [scene] fixed_dt to ≤ "
        f"{STABILITY_LIMIT * spacing / wave_speed:.4g} s")


class WaterSurface(ConfigModel):
    """A height-field water surface with waves generated and reflected at the outline of bodies (seeds/003)."""

    resolution: Resolution = Field(
        (32, 32), description="Grid vertices (nx, nz) along x and z: P[i, j] with 0 ≤ i < nx, 0 ≤ j < nz "
                              "(section 2.2.1; the paper's pool is 26 × 26). Each in [3, 2048].")
    spacing: float = Field(0.5, gt=0.0, le=100.0,
                           description="h: distance between neighbouring grid vertices in metres (section 2.2.1).")
    extent: Vec2 | None = Field(
        None, description="Size of the pool (x, z) in metres; when given, spacing h = extent / (resolution - 1) "
                          "(must be the same along x and z: the paper's cells are square).")
    wave_speed: float = Field(2.0, gt=0.0, le=1000.0,
                              description="c: wave speed in m/s (eq. 2.8). c·Δt/h must stay ≤ 1/√2 ≈ 0.707.")
    damping: float = Field(0.996, ge=0.0, le=1.0,
                           description="Factor every height (about the mean level) is multiplied by after each "
                                       "update (section 2.3.2, in [0, 1); 1 turns damping off).")
    outline_constant: float = Field(
        1.0, ge=0.0, le=100.0, description="α: wave size per metre a body's outline moves (eq. 2.6, 2.7): an "
                                           "added point rises (or sinks) by α·d(t).")
    wave_source: Literal["outline", "grid"] = Field(
        "outline", description="'outline': the paper's method, waves start and reflect at points added on the "
                               "body's cross-section (fig. 3.5); 'grid': the older method that displaces the grid "
                               "vertices under the body by the change of its submerged depth (fig. 3.4).")
    sphere_segments: int = Field(16, ge=6, le=64,
                                 description="Vertices of a sphere's cross-section polygon D' (section 2.2.2).")
    water_density: float = Field(1000.0, gt=0.0, le=20000.0,
                                 description="ρ: density of the water in kg/m³ (buoyancy ρ·g·V_submerged).")
    depth: float = Field(2.0, gt=0.01, le=1000.0,
                         description="Depth of the pool below the rest level in metres: its floor stops sinking "
                                     "bodies and the depth tint uses it.")
    linear_drag: float = Field(1.5, ge=0.0, le=100.0,
                               description="Water drag on a body per second, per kilogram of displaced water "
                                           "(force = -linear_drag · ρ·V_submerged · relative velocity).")
    angular_drag: float = Field(1.0, ge=0.0, le=100.0,
                                description="Water drag on a body's spin per second, scaled by its submerged fraction.")
    disturbance_rate: float = Field(0.0, ge=0.0, le=10000.0,
                                    description="Random drops (wind gusts, rain) per second over the whole surface.")
    disturbance_height: float = Field(0.05, ge=0.0, le=10.0,
                                      description="Largest depth in metres a random drop pushes the water down by (each "
                                                  "drop takes this times a uniform 0.5..1).")
    disturbance_radius: float = Field(0.5, gt=0.0, le=100.0,
                                      description="Radius in metres of each random drop's dent.")
    shallow_color: Color3 = Field((0.10, 0.45, 0.50), description="Water colour where it is shallow (linear RGB).")
    deep_color: Color3 = Field((0.01, 0.06, 0.12), description="Water colour where it is deep (linear RGB).")
    clarity: float = Field(2.0, gt=0.0, le=1000.0,
                           description="Distance in metres through the water at which the depth tint is 63 % deep.")
    wireframe: bool = Field(False, description="Debug view: draw the re-triangulated mesh, the body outline "
                                               "highlighted (fig. 3.2).")

    @model_validator(mode="after")
    def _grid(self, info: ValidationInfo) -> WaterSurface:
        nx, nz = self.resolution
        if nx * nz > MAX_GRID_POINTS:
            raise CrossFieldError("resolution", f"resolution {nx} × {nz} has {nx * nz} vertices, more than the "
                                                f"{MAX_GRID_POINTS} allowed")
        if self.extent is not None:
            ex, ez = self.extent
            if ex <= 0.0 or ez <= 0.0:
                raise CrossFieldError("extent", f"extent must be positive in metres, got {list(self.extent)}")
            hx, hz = ex / (nx - 1), ez / (nz - 1)
            if abs(hx - hz) > 1e-9 * max(hx, hz):
                raise CrossFieldError(("extent", "resolution"),
                                     f"extent {list(self.extent)} over resolution {[nx, nz]} gives cells of "
                                 f"{hx:g} × {hz:g} m; the cells must be square (the same spacing h along x and z)")
            if "spacing" in self.model_fields_set and abs(self.spacing - hx) > 1e-9 * hx:
                raise CrossFieldError(("spacing", "extent"),
                                     f"spacing {self.spacing:g} disagrees with extent {list(self.extent)} over "
                                 f"resolution {[nx, nz]} (which gives h = {hx:g}); give only one of them")
            object.__setattr__(self, "spacing", hx)
        if self.spacing > 100.0:
            raise CrossFieldError(("extent", "resolution"), f"spacing h = {self.spacing:g} m is above 100 m")
        # With the scene's fixed step (validation context from the scene loader) the check is exact; on its
        # own (a preset validated alone) only the static part: unstable at every fixed step the engine accepts.
        scene_dt = (info.context or {}).get("fixed_dt") if info is not None else None
        if scene_dt is not None:
            check_stability(self.wave_speed, self.spacing, float(scene_dt), "with the scene's fixed_dt")
        else:
            check_stability(self.wave_speed, self.spacing, MIN_FIXED_DT, "even at the smallest fixed_dt 1/1000 s")
        return self

    @property
    def size(self) -> tuple[float, float]:
        """Pool size (x, z) in metres: ((nx − 1)·h, (nz − 1)·h)."""
        nx, nz = self.resolution
        return (nx - 1) * self.spacing, (nz - 1) * self.spacing


def _empty(*shape: int, dtype=np.float64) -> np.ndarray:
    return np.zeros(shape, dtype=dtype)


@dataclass
class WaterState:
    """Runtime water: heights at t and t − 1, the solid mask, the added points and last step's body outlines.

    Added points persist from step to step under a key (body, feature, grid line) so their own heights (eq. 2.12)
    carry over; positions are in grid units (u, v) = ((x − x0)/h, (z − z0)/h).
    """

    heights: F64  # (nz, nx) z(t) of P[i, j] (row j, column i)
    previous: F64  # (nz, nx) z(t − 1)
    solid: NDArray[np.bool_]  # (nz, nx) inside a body's cross-section (outline method): a reflecting obstacle
    origin: F64  # (x0, z0) of P[0, 0], relative to the water entity's position
    point_keys: NDArray[np.int64] = field(default_factory=lambda: _empty(0, dtype=np.int64))
    point_uv: F64 = field(default_factory=lambda: _empty(0, 2))
    point_heights: F64 = field(default_factory=lambda: _empty(0))  # N_z(t)
    point_previous: F64 = field(default_factory=lambda: _empty(0))  # N_z(t − 1)
    point_kind: NDArray[np.int8] = field(default_factory=lambda: _empty(0, dtype=np.int8))  # 0/1 on u/v line, 2 L'
    segments: NDArray[np.int64] = field(default_factory=lambda: _empty(0, 2, dtype=np.int64))  # outline, CCW
    body_entities: NDArray[np.int64] = field(default_factory=lambda: _empty(0, dtype=np.int64))
    polygons: F64 = field(default_factory=lambda: _empty(0, 0, 2))  # (B, V, 2) cross-sections D' at t, grid units
    polygon_counts: NDArray[np.int64] = field(default_factory=lambda: _empty(0, dtype=np.int64))
    column_depth: F64 | None = None  # (nz, nx) submerged body depth per vertex at t ('grid' method)
    splashes: list = field(default_factory=list)  # pending (u, v, height) dents from impacts, applied next step
    last_raised: F64 = field(default_factory=lambda: _empty(0), metadata={"hash": False})  # diagnostics
    degree: F64 | None = field(default=None, metadata={"hash": False})  # cached neighbour count of a free grid
    coefficient: F64 | None = field(default=None, metadata={"hash": False})  # cached 2 − k·degree (eq. 2.8)
    coefficient_k: float = field(default=-1.0, metadata={"hash": False})
    scratch: F64 | None = field(default=None, metadata={"hash": False})  # work array
    slots: NDArray[np.int64] | None = field(default=None, metadata={"hash": False})  # work array (flat indices)
    section_edges: tuple | None = field(default=None, metadata={"hash": False})  # (polygons, their edge table) cache
    solid_index: tuple | None = field(default=None, metadata={"hash": False})  # (solid, its flat indices) cache

    @property
    def shape(self) -> tuple[int, int]:
        return self.heights.shape


def build_water_surface(cfg: WaterSurface, ctx: BuildContext) -> list:
    """[config, WaterState, Collider(heightfield)]: the surface is also a collider (layer 'water') so effects
    that strike it (energy-wave particles) send Impact events to it."""
    dt = _scene_dt(ctx)
    if dt is not None:
        check_stability(cfg.wave_speed, cfg.spacing, dt)
    nx, nz = cfg.resolution
    size_x, size_z = cfg.size
    origin = np.array([-0.5 * size_x, -0.5 * size_z])
    state = WaterState(np.zeros((nz, nx)), np.zeros((nz, nx)), np.zeros((nz, nx), bool), origin)
    collider = Collider(shape="heightfield", heightfield=HeightField(np.zeros((nz, nx)), cfg.spacing, origin.copy()),
                        layer="water")
    return [cfg, state, collider]


def _scene_dt(ctx: BuildContext) -> float | None:
    from engine.app import App

    app = ctx.world.try_resource(App)
    return None if app is None else float(app.dt)


# ----------------------------------------------------------------------------------------------- rigid bodies
# a body's box: no flat or empty side (its inertia and volume divide by them)
BoxHalfExtents = Annotated[list[Annotated[float, Field(ge=1e-3, le=10000.0)]], Field(min_length=3, max_length=3),
                           AfterValidator(lambda v: tuple(v))]
class RigidBody(ConfigModel):
    """A 6-DOF rigid body (box or sphere) that floats on WaterSurface, makes waves and takes impulses.

    Its size is the shape's size in local units times the entity's Transform scale, like the engine's Collider
    (the build adds a matching Collider, so do not add one yourself). Inertia follows from the shape and mass.
    """

    shape: Literal["box", "sphere"] = Field("box", description="Collision and inertia shape.")
    half_extents: BoxHalfExtents = Field((0.5, 0.5, 0.5),
                                         description="Box half sizes in local units (× Transform scale).")
    radius: float = Field(0.5, ge=1e-3, le=10000.0, description="Sphere radius in local units (× max scale).")
    mass: float = Field(100.0, gt=0.0, le=1e7, description="Mass in kg (floats when below ρ·volume).")
    linear_damping: float = Field(0.05, ge=0.0, le=100.0, description="Velocity lost per second (air drag).")
    angular_damping: float = Field(0.05, ge=0.0, le=100.0, description="Spin lost per second.")
    velocity: Vec3 = Field((0.0, 0.0, 0.0), description="Initial velocity in m/s (world).")
    angular_velocity: Vec3 = Field((0.0, 0.0, 0.0), description="Initial angular velocity in rad/s (world).")
    gravity: float = Field(9.81, ge=0.0, le=1000.0, description="g: downward acceleration in m/s².")
    kinematic: bool = Field(False, description="Moved by scripts only (no forces); still makes waves.")
    restitution: float = Field(0.2, ge=0.0, le=1.0, description="Bounce off the pool's floor and walls.")
    friction: float = Field(0.5, ge=0.0, le=2.0, description="Coulomb friction on the pool's floor and walls.")
    max_speed: float = Field(1000.0, gt=0.0, le=1.0e5,
                             description="Speed limit in m/s, applied every sub-step: impulses from scripts and "
                                         "impacts cannot make a body's state overflow.")
    max_angular_speed: float = Field(100.0, gt=0.0, le=1000.0,
                                     description="Spin limit in rad/s, applied every sub-step (as PhysX's "
                                                 "maxAngularVelocity): the explicit gyroscopic term ω × Iω grows "
                                                 "without bound at high spin.")

    @model_validator(mode="after")
    def _speeds(self) -> RigidBody:
        for key, limit_key in (("velocity", "max_speed"), ("angular_velocity", "max_angular_speed")):
            value, limit = getattr(self, key), getattr(self, limit_key)
            length = math.sqrt(sum(x * x for x in value))
            if length > limit:
                raise CrossFieldError((key, limit_key), f"{key} {list(value)} has length {length:g}, above "
                                                        f"{limit_key} = {limit:g}; "
                                 f"lower it or raise {limit_key}")
        return self


@dataclass
class RigidBodyState:
    """Runtime rigid body: velocities (world), pending impulses and forces from scripts and impacts."""

    velocity: F64
    angular_velocity: F64
    impulse: F64 = field(default_factory=lambda: np.zeros(3))  # linear impulse to apply next step (N·s)
    angular_impulse: F64 = field(default_factory=lambda: np.zeros(3))  # about the centre of mass (N·m·s)
    force: F64 = field(default_factory=lambda: np.zeros(3))  # applied for the next step only (N)
    torque: F64 = field(default_factory=lambda: np.zeros(3))
    submerged_volume: float = 0.0  # V_submerged at the last step (m³)
    previous_position: F64 | None = None  # kinematic bodies: velocity from the motion scripts gave them


def build_rigid_body(cfg: RigidBody, ctx: BuildContext) -> list:
    """[config, RigidBodyState, Collider]: the collider matches the body's shape for the other effects' queries."""
    # A RigidBodyState already there means a hot-reload rebuild of this body: the Collider is its own, replaced.
    if ctx.world.has(ctx.entity, Collider) and not ctx.world.has(ctx.entity, RigidBodyState):
        raise ValueError("this entity already has a Collider: a RigidBody adds its own from 'shape', "
                         "'half_extents' and 'radius'; remove the [Collider] table")
    state = RigidBodyState(np.array(cfg.velocity, float), np.array(cfg.angular_velocity, float))
    collider = Collider(shape=cfg.shape, half_extents=np.array(cfg.half_extents, float), radius=cfg.radius)
    return [cfg, state, collider]
