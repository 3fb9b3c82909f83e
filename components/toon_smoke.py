"""ToonSmokeVolume: cel-animation smoke and clouds (Kuroda, Dobashi & Yamamoto, "Cartoon Rendering of Gaseous
Phenomena", seeds/002).

The config is what a modder writes in TOML; the runtime state holds the fluid on a coarse MAC grid (§3.1), the
particles (§3.3) and the display-grid products derived from them each step (the upsampled, blob-splatted,
noise-multiplied density of §3.2–3.4 and its isosurface mesh of §3.5).  No GL here.

Coordinates: the volume is a box of ``extent`` metres centred on its entity's position and turned by its
rotation (scale is ignored so that metres stay metres).  Arrays are indexed [x, y, z] with +y up in the local frame.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Annotated, Any, Literal

import numpy as np
from pydantic import AfterValidator, Field, model_validator

from engine.config import Color3, ConfigModel, CrossFieldError, Vec3

__all__ = [
    "SmokeSourceConfig",
    "SourceState",
    "ToonSmokeState",
    "ToonSmokeVolumeConfig",
    "build_toon_smoke",
]

OpenSide = Literal["-x", "+x", "-y", "+y", "-z", "+z"]
SIDES: tuple[str, ...] = ("-x", "+x", "-y", "+y", "-z", "+z")


def _int_tuple(v: list[int]) -> tuple[int, ...]:
    return tuple(int(x) for x in v)


GridSize = Annotated[list[Annotated[int, Field(ge=8, le=128, multiple_of=8)]], Field(min_length=3, max_length=3),
                     AfterValidator(_int_tuple)]
DisplaySize = Annotated[list[Annotated[int, Field(ge=8, le=256)]], Field(min_length=3, max_length=3),
                        AfterValidator(_int_tuple)]
MAX_BLOB_CELLS = 8.0  # longest blob semi-axis, in display cells (bounds the splat stencil)
MAX_SOLVER_WORK = 64 ** 3 * 128  # simulation cells × (diffusion + pressure iterations) a tick: 32³ × 48 in the paper
MAX_DISPLAY_CELLS = 128 * 128 * 256  # display (isosurface) cells: 64³ in the paper
COARSEST_CELLS = 64  # the pressure solver's multigrid halves the grid until it has at most this many cells ...
MAX_COARSEST_CELLS = 512  # ... or a side is odd or below 4; a dense inverse solves that level (512²: 2 MB, ~0.1 s)


def coarsest_shape(shape: tuple[int, ...]) -> tuple[int, ...]:
    """The multigrid's coarsest level for a simulation grid of ``shape`` (systems.toon_smoke.poisson): halved
    while it has more than :data:`COARSEST_CELLS` cells and every side is even and at least 4."""
    shape = tuple(int(n) for n in shape)
    while math.prod(shape) > COARSEST_CELLS and all(n % 2 == 0 and n >= 4 for n in shape):
        shape = tuple(n // 2 for n in shape)
    return shape


class SmokeSourceConfig(ConfigModel):
    """A spherical emitter of smoke: density, heat and velocity injected every step while it is on."""

    name: str = Field("source", min_length=1, max_length=64,
                      description="Name scripts use with the 'toon_smoke.set_source' command.")
    position: Vec3 = Field((0.0, -1.5, 0.0), description="Centre in the volume's local frame, metres.")
    radius: float = Field(0.4, ge=0.01, le=1000.0, description="Radius of the emitting sphere, metres.")
    density_rate: float = Field(8.0, ge=0.0, le=1000.0,
                                description="Density ρ added per second inside the sphere (the source term s of "
                                            "Stam's ∂ρ/∂t = … + s).")
    temperature_rate: float = Field(6.0, ge=0.0, le=1000.0,
                                    description="Temperature T added per second inside the sphere (drives buoyancy).")
    velocity: Vec3 = Field((0.0, 2.0, 0.0), description="Velocity u imposed inside the sphere, m/s (local frame).")
    velocity_jitter: float = Field(0.0, ge=0.0, le=100.0,
                                   description="Random velocity (uniform in ±this per axis, m/s) added to the imposed "
                                               "velocity each step, from the entity's seeded stream: breaks symmetry "
                                               "so plumes curl.")
    radial_speed: float = Field(0.0, ge=-100.0, le=100.0,
                                description="Outward speed at the sphere's surface, m/s (an explosion's blast): a "
                                            "divergence source ∇·u = 3·speed/radius inside the sphere (Feldman et al. "
                                            "2003); it pushes smoke out through the open sides.")
    start_time: float = Field(0.0, ge=0.0, le=1e6, description="Seconds after start when the source switches on.")
    duration: float = Field(0.0, ge=0.0, le=1e6, description="Seconds the source stays on (0 = for ever).")
    enabled: bool = Field(True, description="Whether the source emits (scripts toggle it).")


class ToonSmokeVolumeConfig(ConfigModel):
    """A box of cel-shaded smoke: stable fluids on a coarse grid, particles adding density blobs on a finer display
    grid, Perlin noise, a marching-cubes isosurface shaded from a 1D toon ramp, and an outline.  The defaults are the
    paper's setup (configs/effects/toon_smoke/paper.toml) without its sphere obstacle."""

    # --- grids (§3.1, §3.2)
    simulation_resolution: GridSize = Field(
        (32, 32, 32), description="Simulation (fluid) grid cells per axis; paper: 32³. Multiples of 8, 8..128.")
    display_resolution: DisplaySize = Field(
        (64, 64, 64), description="Display (isosurface) grid cells per axis; paper: 64³. Must be the simulation "
                                  "resolution times one integer factor 1..4 on every axis.")
    extent: Vec3 = Field((4.0, 4.0, 4.0),
                         description="Size of the volume in metres (x, y, z); cells must come out cubic.")
    time_step: float | None = Field(None, gt=0.0, le=0.25,
                                    description="Δt of the fluid step taken once per engine tick, seconds (default: the "
                                                "engine's fixed step; another value plays the smoke faster or slower).")
    # --- fluid (§3.1)
    viscosity: float = Field(0.0, ge=0.0, le=10.0, description="Kinematic viscosity ν of the Navier–Stokes "
                                                               "diffusion term ν∇²u, m²/s (0 = inviscid).")
    diffusion: float = Field(0.0, ge=0.0, le=10.0, description="Diffusion κ of density and temperature, m²/s.")
    diffusion_iterations: int = Field(8, ge=1, le=100,
                                      description="Red–black Gauss–Seidel sweeps of the implicit diffusion solve.")
    pressure_iterations: int = Field(40, ge=1, le=500,
                                     description="Maximum conjugate-gradient iterations of the pressure solve.")
    pressure_tolerance: float = Field(1e-4, ge=1e-7, le=0.1,
                                      description="Pressure solve stops when max|residual| ≤ this × max|∇·u| before "
                                                  "projection (relative divergence left after projection).")
    open_sides: list[OpenSide] = Field(["+y"], max_length=6,
                                       description="Sides of the box that are open (pressure 0 outside, smoke leaves); "
                                                   "the others are walls where the normal velocity is 0.")
    buoyancy: float = Field(2.0, ge=0.0, le=100.0,
                            description="β: upward acceleration per unit temperature, m/s² (hot smoke rises).")
    smoke_weight: float = Field(0.05, ge=0.0, le=100.0,
                                description="α: downward acceleration per unit density, m/s² (dense smoke sinks).")
    vorticity_confinement: float = Field(0.0, ge=0.0, le=20.0,
                                         description="ε of vorticity confinement (Fedkiw et al. 2001); 0 = off.")
    density_dissipation: float = Field(0.0, ge=0.0, le=100.0,
                                       description="Density fades as ρ ← ρ / (1 + rate·Δt); rate per second.")
    temperature_cooling: float = Field(0.15, ge=0.0, le=100.0,
                                       description="Temperature fades as T ← T / (1 + rate·Δt); rate per second.")
    density_limit: float = Field(4.0, gt=0.0, le=1000.0,
                                 description="Upper bound of the density ρ on both grids (sources saturate there).")
    temperature_limit: float = Field(10.0, gt=0.0, le=1000.0,
                                     description="Upper bound of the temperature T (sources saturate there).")
    sources: list[SmokeSourceConfig] = Field(default_factory=lambda: [SmokeSourceConfig()], max_length=16,
                                             description="Smoke emitters.")
    # --- obstacles (§4: the red sphere in the middle)
    obstacle_radius: float = Field(0.0, ge=0.0, le=1000.0,
                                   description="Radius of the volume's own sphere obstacle, metres (0 = none).")
    obstacle_center: Vec3 = Field((0.0, 0.0, 0.0), description="Centre of the sphere obstacle, local metres.")
    obstacle_color: Color3 = Field((0.85, 0.12, 0.1), description="Colour the sphere obstacle is drawn with (as shown on screen).")
    collide_with_colliders: bool = Field(True, description="Other entities' Colliders inside the volume are solid "
                                                           "(a height field: below its surface over its footprint).")
    # --- particles and density blobs (§3.3, figure 2)
    particle_count: int = Field(1000, ge=0, le=100_000, description="Number of particles; paper: 1000.")
    particle_spawn: Literal["volume", "sources"] = Field(
        "volume", description="Where particles are (re)born: anywhere in the volume (paper) or inside the sources.")
    particle_lifetime: float = Field(0.0, ge=0.0, le=1e4,
                                     description="Seconds before a particle is reborn (0 = only when it leaves).")
    particle_density_threshold: float = Field(0.25, ge=0.0, le=1000.0,
                                              description="D_p: a particle adds a blob only where density > D_p.")
    blob_density: float = Field(0.8, ge=0.0, le=1000.0, description="Density added at a blob's centre.")
    blob_radius: float = Field(0.2, gt=0.0, le=100.0, description="Blob radius R at density D_p, metres.")
    blob_radius_per_density: float = Field(0.1, ge=0.0, le=100.0,
                                           description="dR/dρ: radius growth per unit of density above D_p, metres.")
    blob_radius_max: float = Field(0.3, gt=0.0, le=100.0, description="Cap on the blob radius R, metres.")
    blob_stretch: float = Field(0.4, ge=0.0, le=100.0,
                                description="Stretch s = 1 + this·|u| along the velocity (figure 2), per m/s.")
    blob_stretch_max: float = Field(1.6, ge=1.0, le=8.0,
                                    description="Cap on s; the blob is an ellipsoid R·s along u and R/√s across.")
    # --- noise (§3.4)
    noise_scale: float = Field(0.5, gt=0.0, le=1000.0, description="Wavelength of the Perlin noise, metres.")
    noise_strength: float = Field(0.35, ge=0.0, le=1.0,
                                  description="Display density is multiplied by max(0, 1 + strength·noise).")
    noise_octaves: int = Field(2, ge=1, le=6, description="Octaves of the fractal sum of Perlin noise.")
    # --- isosurface and toon shading (§3.5, figure 3)
    iso_density: float = Field(0.3, gt=0.0, le=1000.0, description="D_iso: density of the isosurface.")
    ramp_colors: list[Color3] = Field(
        [(1.0, 1.0, 1.0), (0.72, 0.75, 0.86), (0.45, 0.48, 0.62)], min_length=1, max_length=16,
        description="Toon ramp colours as shown on screen (0..1), one per band, from c = 0 upwards.")
    ramp_positions: list[Annotated[float, Field(ge=0.0, le=1.0)]] = Field(
        [0.0, 0.18, 0.36], min_length=1, max_length=16,
        description="Where each band starts on the ramp coordinate c = (−v·g + 1)/2 (ascending, first 0). "
                    "c = 0 faces the viewer, 0.5 at the silhouette.")
    outline_width: float = Field(1.5, ge=0.0, le=16.0, description=(
        "Outline width in window pixels (0 = no outline); a view rendered at a lower scale draws as many fewer "
        "of its pixels, at least one."))
    outline_color: Color3 = Field((0.08, 0.08, 0.12), description="Outline colour (as shown on screen, 0..1).")
    outline_depth_threshold: float = Field(0.04, gt=0.0, le=10.0,
                                           description="Relative depth jump that draws an inner contour line.")

    def scene_budgets(self, fixed_dt: float) -> list[tuple[str, float, float]]:
        """(what, cost, limit) that every entity of a scene shares (engine.scene: the sum of each is capped)."""
        return [("smoke solver work (simulation cells * (diffusion_iterations + pressure_iterations))",
                 self._solver_work(), MAX_SOLVER_WORK),
                ("smoke display cells", math.prod(self.display_resolution), MAX_DISPLAY_CELLS)]

    def _solver_work(self) -> int:
        return math.prod(self.simulation_resolution) * (self.diffusion_iterations + self.pressure_iterations)

    @model_validator(mode="after")
    def _check_consistency(self) -> ToonSmokeVolumeConfig:
        sim, disp = self.simulation_resolution, self.display_resolution
        factors = [d / s for d, s in zip(disp, sim)]
        if any(f != int(f) for f in factors) or len(set(factors)) != 1 or not 1 <= factors[0] <= 4:
            raise CrossFieldError(("display_resolution", "simulation_resolution"),
                                 f"display_resolution {list(disp)} must be simulation_resolution {list(sim)} times one "
                             f"integer factor 1..4 on every axis (e.g. {[2 * s for s in sim]})")
        cells = [e / n for e, n in zip(self.extent, sim)]
        if min(self.extent) <= 0.0 or max(cells) - min(cells) > 1e-6 * max(cells):
            cube = cells[0]
            raise CrossFieldError(("extent", "simulation_resolution"),
                                 f"extent {list(self.extent)} / simulation_resolution {list(sim)} gives cells of "
                             f"{[round(c, 6) for c in cells]} m: cells must be cubic (e.g. extent "
                             f"{[round(cube * n, 6) for n in sim]})")
        if len(self.ramp_positions) != len(self.ramp_colors):
            raise CrossFieldError(("ramp_positions", "ramp_colors"),
                                 f"ramp_positions has {len(self.ramp_positions)} entries but ramp_colors has "
                             f"{len(self.ramp_colors)}: give one start position per colour")
        if self.ramp_positions[0] != 0.0 or any(b <= a for a, b in zip(self.ramp_positions, self.ramp_positions[1:])):
            raise CrossFieldError("ramp_positions",
                                 f"ramp_positions {list(self.ramp_positions)} must start at 0 and increase strictly")
        coarsest = coarsest_shape(sim)
        if math.prod(coarsest) > MAX_COARSEST_CELLS:
            raise CrossFieldError("simulation_resolution",
                                 f"simulation_resolution {list(sim)} halves only down to {list(coarsest)} = "
                             f"{math.prod(coarsest)} cells for the pressure solver's coarsest level (every side must "
                             f"stay even and at least 4), more than {MAX_COARSEST_CELLS}: keep the sides within a "
                             f"factor of 8 of each other (e.g. {[max(n, max(sim) // 8) for n in sim]})")
        if self.iso_density >= self.density_limit:
            raise CrossFieldError(("iso_density", "density_limit"),
                                 f"iso_density {self.iso_density:g} must be below density_limit "
                                 f"{self.density_limit:g}: "
                             "the display density never exceeds the limit, so no surface would be drawn")
        if self.particle_density_threshold >= self.density_limit:
            raise CrossFieldError(("particle_density_threshold", "density_limit"),
                                 f"particle_density_threshold {self.particle_density_threshold:g} must be below "
                             f"density_limit {self.density_limit:g}: the density never exceeds the limit, so no "
                             "particle would add a blob")
        work, display_cells = self._solver_work(), math.prod(disp)
        if work > MAX_SOLVER_WORK:
            raise CrossFieldError(("simulation_resolution", "diffusion_iterations", "pressure_iterations"),
                                 f"simulation_resolution {list(sim)} × (diffusion_iterations + pressure_iterations) = "
                             f"{work} cell sweeps a tick exceeds {MAX_SOLVER_WORK}; lower the resolution or the "
                             "iterations")
        if display_cells > MAX_DISPLAY_CELLS:
            raise CrossFieldError("display_resolution",
                                 f"display_resolution {list(disp)} has {display_cells} cells, more than "
                             f"{MAX_DISPLAY_CELLS} (128 × 128 × 256); lower it")
        h_display = cells[0] / factors[0]
        longest = self.blob_radius_max * self.blob_stretch_max / h_display
        if longest > MAX_BLOB_CELLS:
            raise CrossFieldError(("blob_radius_max", "blob_stretch_max", "display_resolution", "extent"),
                                 f"blob_radius_max × blob_stretch_max = "
                                 f"{self.blob_radius_max * self.blob_stretch_max:g} m "
                             f"is {longest:.1f} display cells; keep it ≤ {MAX_BLOB_CELLS:g} cells "
                             f"({MAX_BLOB_CELLS * h_display:g} m)")
        names = [s.name for s in self.sources]
        if len(set(names)) != len(names):
            raise CrossFieldError("sources", f"source names must be unique, got {names}")
        if len(set(self.open_sides)) != len(self.open_sides):
            raise CrossFieldError("open_sides", f"open_sides lists a side twice: {list(self.open_sides)}")
        return self

    # -- derived sizes
    @property
    def cell_size(self) -> float:
        """h: edge of a simulation cell, metres."""
        return self.extent[0] / self.simulation_resolution[0]

    @property
    def display_factor(self) -> int:
        return self.display_resolution[0] // self.simulation_resolution[0]

    @property
    def open_flags(self) -> tuple[bool, ...]:
        return tuple(side in self.open_sides for side in SIDES)


@dataclass
class SourceState:
    """A source as the simulation and scripts see it (scripts change it through commands)."""

    name: str
    position: np.ndarray  # (3,) local metres
    radius: float
    density_rate: float
    temperature_rate: float
    velocity: np.ndarray  # (3,) m/s
    velocity_jitter: float
    radial_speed: float
    start_time: float
    duration: float
    enabled: bool

    @classmethod
    def from_config(cls, cfg: SmokeSourceConfig) -> SourceState:
        return cls(cfg.name, np.array(cfg.position, float), cfg.radius, cfg.density_rate, cfg.temperature_rate,
                   np.array(cfg.velocity, float), cfg.velocity_jitter, cfg.radial_speed, cfg.start_time, cfg.duration,
                   cfg.enabled)

    def active(self, time: float) -> bool:
        if not self.enabled or time < self.start_time:
            return False
        return self.duration == 0.0 or time < self.start_time + self.duration


def _derived() -> Any:
    """A field derived from the state each step (skipped by the state hash)."""
    return field(default=None, metadata={"hash": False})


@dataclass
class ToonSmokeState:
    """Runtime state of one volume.

    Hashed: the MAC velocity (u on x-faces, v on y-faces, w on z-faces, m/s), density ρ and temperature T at cell
    centres, the scaled pressure φ (warm start), the particles, the sources and the clock.  Not hashed: everything
    re-derived from those each step (display grid, mesh, solver hierarchy, diagnostics).
    """

    u: np.ndarray
    v: np.ndarray
    w: np.ndarray
    density: np.ndarray
    temperature: np.ndarray
    pressure: np.ndarray
    expansion: np.ndarray  # (nx, ny, nz) target ∇·u (1/s) of the next projection (puffs), reset after use
    particles: np.ndarray  # (P, 3) float64 local metres
    particle_age: np.ndarray  # (P,) seconds
    sources: list[SourceState]
    noise_seed: int
    time: float = 0.0
    steps: int = 0
    geometry: Any = _derived()  # coordinate grids and masks of this config (systems.toon_smoke.grid.Geometry)
    solid: np.ndarray | None = _derived()  # (nx, ny, nz) bool, simulation grid
    display_solid: np.ndarray | None = _derived()
    solid_key: Any = _derived()
    hierarchy: Any = _derived()
    noise_base: np.ndarray | None = _derived()  # max(0, 1 + strength·noise) per display cell
    noise_factor: np.ndarray | None = _derived()  # noise_base, zero in solid display cells
    noise_key: Any = _derived()
    display_density: np.ndarray | None = _derived()
    particle_velocity: np.ndarray | None = _derived()
    blob_count: int = field(default=0, metadata={"hash": False})
    mesh_vertices: np.ndarray | None = _derived()  # (V, 3) float32 local metres
    mesh_normals: np.ndarray | None = _derived()  # (V, 3) float32, outward = −∇ρ/|∇ρ|
    mesh_faces: np.ndarray | None = _derived()  # (F, 3) uint32
    mesh_version: int = field(default=0, metadata={"hash": False})
    # the value of ``steps`` the display grid and mesh were derived at (-1: never, or to be re-derived)
    display_step: int = field(default=-1, metadata={"hash": False})
    divergence_before: float = field(default=0.0, metadata={"hash": False})  # max |∇·u| (1/s) before projection
    divergence_after: float = field(default=0.0, metadata={"hash": False})  # … and after
    pressure_iterations_used: int = field(default=0, metadata={"hash": False})


def build_toon_smoke(cfg: ToonSmokeVolumeConfig, ctx) -> list:
    """Component factory: ``[config, state]``; particles are drawn from the entity's ``toon_smoke`` stream."""
    from systems.toon_smoke.simulate import new_state

    rng = ctx.rng("toon_smoke")
    return [cfg, new_state(cfg, rng)]
