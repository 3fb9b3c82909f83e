"""DustDevil: a whirlwind of sand the user drags over the terrain (Nakajima, Ohno, Fujishiro; seeds/004).

The config is what a modder writes under ``[entities.components.DustDevil]``; the runtime state holds the
particles in *field space* (section 4 of the paper): metres in the frame of the field box, whose origin is the
centre of the box's bottom face and which the entity's ``Transform`` places in the world. Moving the Transform
(dragging) moves the whole dust devil.  No GL here.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Annotated, Any, Literal

import numpy as np
from pydantic import AfterValidator, Field, ValidationInfo, field_validator, model_validator

from engine.config import Color3, ConfigModel, CrossFieldError, _as_tuple
from engine.registry import BuildContext

__all__ = ["MAX_PBVR_POINTS", "MAX_POINT_FILL", "MAX_PREWARM_WORK", "DustDevilConfig", "DustDevilState",
           "build_dust_devil"]

MAX_PBVR_POINTS = 8_000_000  # points a frame (particle_count · sub_particles · repeats): 5000 · 2 · 16 in the paper
MAX_POINT_FILL = 4 * MAX_PBVR_POINTS  # points · point_size² (pixels rasterised a frame): the cap above at 2 px
MAX_PREWARM_WORK = 100_000_000  # particle_count · substeps · prewarm steps: 5000 · 1 · 300 in the paper preset

Size3 = Annotated[list[Annotated[float, Field(ge=1.0, le=1000.0)]], Field(min_length=3, max_length=3),
                  AfterValidator(_as_tuple)]
Grid3 = Annotated[list[Annotated[int, Field(ge=4, le=96)]], Field(min_length=3, max_length=3),
                  AfterValidator(lambda v: tuple(int(x) for x in v))]
AngleRange = Annotated[list[Annotated[float, Field(ge=0.0, le=180.0)]], Field(min_length=2, max_length=2),
                       AfterValidator(_as_tuple)]


class DustDevilConfig(ConfigModel):
    """A dust devil: Crawfis' tornado field in a draggable box, sand particles, PBVR rendering (seeds/004)."""

    # -- the field box and its grid (sections 2.1, 4)
    field_size: Size3 = Field((24.0, 30.0, 24.0),
                              description="Field box size in metres (x, height y, z); the unit cube of Crawfis' "
                                          "tornado is stretched onto it. The entity's Transform places the centre "
                                          "of the box's bottom face.")
    grid_resolution: Grid3 = Field((32, 32, 32),
                                   description="Grid points of the vector field along x, y (up), z (each 4..96); "
                                               "the paper's particles follow the vector of the nearest grid point.")
    lookup: Literal["nearest", "trilinear"] = Field("nearest",
                                                    description="Velocity lookup: 'nearest' grid point (the "
                                                                "paper's, 2.1) or 'trilinear' interpolation.")
    integrator: Literal["euler", "midpoint"] = Field("midpoint",
                                                     description="'euler': move along the looked-up vector (the "
                                                                 "paper's step); 'midpoint': look up again half a "
                                                                 "step ahead (RK2), which keeps particles in the "
                                                                 "fast core instead of flinging them out.")
    substeps: int = Field(1, ge=1, le=8, description="Advection substeps per fixed step.")
    time_speed: float = Field(10.0, ge=0.0, le=1000.0,
                              description="Crawfis' time parameter t advanced per second (the funnel's centre line "
                                          "sways with sin(0.04 t + 10 z), cos(0.03 t + 3 z)).")
    wind_scale: float = Field(1.0, ge=0.0, le=100.0,
                              description="Velocity in box lengths per second per unit of the field "
                                          "(field magnitudes are about 0..0.4).")
    # -- randomness (2.2)
    rotation_interval: float = Field(0.5, gt=0.0, le=600.0,
                                     description="Seconds between rotations of the vortex centre line (2.2: not "
                                                 "every step, or particles gather at the centre).")
    rotation_angle_range: AngleRange = Field((5.0, 25.0),
                                             description="Range [min, max] in degrees of the random angle the "
                                                         "centre line turns by, clockwise seen from above (2.2).")
    # -- particles
    particle_count: int = Field(5000, ge=1, le=200_000,
                                description="Real particles (paper: 3,500-5,000).")
    emission_radius: float = Field(1.0, ge=0.0, le=500.0,
                                   description="Radius in metres of the disc around the funnel's foot where "
                                               "particles are (re-)emitted.")
    emission_height: float = Field(1.0, ge=0.0, le=500.0,
                                   description="Particles start up to this many metres above the ground.")
    particle_lifetime: float = Field(15.0, gt=0.0, le=600.0,
                                     description="Seconds a particle lives before it is emitted again "
                                                 "(also when it leaves the field box).")
    lifetime_jitter: float = Field(0.5, ge=0.0, le=1.0,
                                   description="Each lifetime is particle_lifetime times a uniform factor in "
                                               "[1 - jitter, 1].")
    prewarm_time: float = Field(5.0, ge=0.0, le=60.0,
                                description="Seconds simulated at the first step so the whirl is already formed.")
    terrain_interaction: bool = Field(True,
                                      description="Wind blowing into the terrain follows the slope, "
                                                  "r = v - ((n·v)/|n|²) n (eq. 1, 3.2); particles stay above it.")
    # -- rendering: particle-based volume rendering (2.3)
    pbvr: bool = Field(True, description="Particle-based volume rendering; when off the real particles are drawn.")
    sub_particles: int = Field(2, ge=1, le=16,
                               description="K: random pseudo-particles generated around each real particle per "
                                           "repeat (paper: 2).")
    sub_particle_radius: float = Field(0.35, ge=0.0, le=100.0,
                                       description="Radius in metres of the ball the pseudo-particles are drawn in.")
    repeats: int = Field(16, ge=1, le=64,
                         description="R: ensemble images averaged per frame (paper: 16 per time step).")
    drag_repeats: int = Field(4, ge=1, le=64,
                              description="R while the field is being dragged (cheaper frames while moving), at "
                                          "most `repeats`: a larger value (a preset's default over a scene's "
                                          "smaller `repeats`) keeps R at `repeats` while dragging.")
    point_size: float = Field(2.0, ge=1.0, le=32.0, description=(
        "Point size in window pixels (a view rendered at a lower scale draws as many fewer of its pixels: the dust "
        "looks the same)."))
    color: Color3 = Field((0.86, 0.70, 0.47), description="Sand colour (linear RGB).")
    show_markers: bool = Field(True,
                               description="Draw the field box's 8 corners and its centre as red spheres (4).")
    marker_radius: float = Field(0.5, gt=0.0, le=100.0, description="Radius of the marker spheres in metres.")
    # -- dragging (4)
    drag_camera: str = Field("top", max_length=128,
                             description="Name of the camera entity (the top view) in whose viewport a mouse "
                                         "drag moves the field; empty disables mouse dragging.")
    drag_button: Literal["left", "middle", "right"] = Field("left", description="Mouse button that drags.")

    @field_validator("rotation_angle_range")
    @classmethod
    def _ordered(cls, value: tuple[float, float]) -> tuple[float, float]:
        if value[0] > value[1]:
            raise ValueError(f"min {value[0]} must not exceed max {value[1]}")
        return value

    def _pbvr_points(self) -> int:
        return self.particle_count * self.sub_particles * self.repeats

    def _point_fill(self) -> float:
        return (self._pbvr_points() if self.pbvr else self.particle_count) * self.point_size ** 2

    def _prewarm_work(self, fixed_dt: float) -> int:
        return self.particle_count * self.substeps * round(self.prewarm_time / fixed_dt)

    def scene_budgets(self, fixed_dt: float) -> list[tuple[str, float, float]]:
        """(what, cost, limit) that every entity of a scene shares (engine.scene: the sum of each is capped)."""
        return [("PBVR points a frame (particle_count * sub_particles * repeats)",
                 self._pbvr_points() if self.pbvr else 0, MAX_PBVR_POINTS),
                ("point pixels a frame (points * point_size²)", self._point_fill(), MAX_POINT_FILL),
                ("prewarm particle steps (particle_count * substeps * prewarm_time / fixed_dt)",
                 self._prewarm_work(fixed_dt), MAX_PREWARM_WORK)]

    @model_validator(mode="after")
    def _point_budget(self) -> DustDevilConfig:
        """PBVR draws particle_count · sub_particles · repeats points a frame: each bound alone is sane, all three
        at their maxima would be 200 million points, minutes a frame on a software rasteriser."""
        points = self._pbvr_points()
        if self.pbvr and points > MAX_PBVR_POINTS:
            raise CrossFieldError(("particle_count", "sub_particles", "repeats"),
                                 f"particle_count * sub_particles * repeats = {points} points a frame exceeds "
                             f"{MAX_PBVR_POINTS}; lower particle_count, sub_particles or repeats")
        fill = self._point_fill()
        if fill > MAX_POINT_FILL:
            raise CrossFieldError(("point_size", "particle_count", "sub_particles", "repeats"),
                                 f"{'particle_count * sub_particles * repeats' if self.pbvr else 'particle_count'} * "
                             f"point_size² = {fill:.4g} pixels a frame exceeds {MAX_POINT_FILL:.4g}; lower "
                             "point_size or the point count")
        return self

    @model_validator(mode="after")
    def _prewarm_budget(self, info: ValidationInfo) -> DustDevilConfig:
        """The first step runs prewarm_time / fixed_dt steps of particle_count · substeps particles at once: at
        the smallest fixed_dt and the largest counts that was hours before the first frame."""
        dt = (info.context or {}).get("fixed_dt") if info is not None else None
        dt = float(dt) if dt else 1.0 / 60.0
        work = self._prewarm_work(dt)
        if work > MAX_PREWARM_WORK:
            raise CrossFieldError(("prewarm_time", "particle_count", "substeps"),
                                 f"particle_count * substeps * (prewarm_time / fixed_dt = "
                                 f"{round(self.prewarm_time / dt)}"
                             f" steps) = {work} particle steps before the first frame exceeds {MAX_PREWARM_WORK}; "
                             "lower prewarm_time, particle_count or substeps")
        return self

    @property
    def dragging_repeats(self) -> int:
        """R while the field is dragged: ``drag_repeats``, never more than ``repeats`` (R only drops)."""
        return min(self.drag_repeats, self.repeats)


@dataclass
class DustDevilState:
    """Runtime state: particles in field space (metres, origin at the box's bottom centre), field clock."""

    positions: np.ndarray  # (N, 3) float64, field space
    ages: np.ndarray  # (N,) seconds since emission
    lifetimes: np.ndarray  # (N,) seconds
    field_time: float = 0.0  # Crawfis' t
    centre_rotation: float = 0.0  # accumulated clockwise (seen from above) turn of the centre line, radians
    rotation_count: int = 0
    steps: int = 0  # fixed steps simulated (prewarm included)
    started: bool = False
    mouse_dragging: bool = False
    drag_anchor: np.ndarray = field(default_factory=lambda: np.zeros(3))  # world pick point of the mouse drag
    last_drag_tick: int = -10  # world tick of the last drag (mouse or command)
    wind: Any = field(default=None, metadata={"hash": False})  # the last step's tornado.WindField (a cache)

    @property
    def count(self) -> int:
        return int(self.positions.shape[0])

    def dragging(self, tick: int) -> bool:
        """True while the mouse holds the field or a drag happened in the last tick."""
        return self.mouse_dragging or self.last_drag_tick >= tick - 1


def build_dust_devil(cfg: DustDevilConfig, ctx: BuildContext) -> list:
    """Component factory: the config and an empty state (particles are emitted at the first step, when the
    terrain exists)."""
    n = cfg.particle_count
    state = DustDevilState(positions=np.zeros((n, 3)), ages=np.zeros(n), lifetimes=np.ones(n))
    return [cfg, state]
