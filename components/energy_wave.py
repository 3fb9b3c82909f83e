"""EnergyWaveEmitter: config model and runtime state (seeds/000, Nito 2013, "Energy-wave expression considering
collision in real-time 3DCG").

An energy wave is a beam of glowing particles. Every particle that hits a collider joins one of eight patterns
A–H (table in :data:`PATTERNS`), chosen by the circular-distribution probability α, the continuity probability β,
the splash sampling count N and the splash roundness t (section 3.2). The pattern picks the equation of motion
(circular: eqs. 3.2–3.4, irregular: eq. 3.5) and the rendering (continuous trail eq. 3.7, grain, bar eq. 3.8 with
tip sizes eq. 3.9).

Units: metres, seconds; τ in frames of 1/60 s as in the paper, c in m/s per frame (A acts during the collision
frame); the bar spacing u in sprite sizes S.
No GL here: the simulation lives in ``systems/energy_wave/simulate.py``.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Annotated

import numpy as np
from pydantic import Field, ValidationInfo, field_validator, model_validator

from engine.config import Color3, ConfigModel, CrossFieldError, Vec3

__all__ = [
    "BEAM",
    "ControlPoint",
    "EnergyWaveEmitter",
    "EnergyWaveHit",
    "EnergyWaveState",
    "FRAME",
    "Keyframe",
    "PATTERNS",
    "PATTERN_PARAMETERS",
    "ParticleBuffer",
    "ROUND_THRESHOLD",
    "build_energy_wave",
]

FRAME = 1.0 / 60.0  # the paper's frame: τ is counted in these
BEAM = -1  # pattern code of a particle still flying in the beam (before any hit)
ROUND_THRESHOLD = 0.5  # bars with t >= 0.5 are labelled round (E, F), below sharp (G, H)

# Pattern code = 2 * rendering kind + global shape; rendering kind 0 continuous, 1 grain, 2 round bar,
# 3 sharp bar; global shape 0 circular, 1 irregular.  (Figure 2.5 of the paper, read as in the spec.)
PATTERNS = ("A", "B", "C", "D", "E", "F", "G", "H")

# The four shape parameters that make a wave show one pattern only (command "energy_wave.set_pattern" and the
# presets pattern_a.toml ... pattern_h.toml).
PATTERN_PARAMETERS: dict[str, dict[str, float | int]] = {
    "A": {"circular_probability": 1.0, "continuity_probability": 1.0},
    "B": {"circular_probability": 0.0, "continuity_probability": 1.0},
    "C": {"circular_probability": 1.0, "continuity_probability": 0.0, "splash_samples": 1},
    "D": {"circular_probability": 0.0, "continuity_probability": 0.0, "splash_samples": 1},
    "E": {"circular_probability": 1.0, "continuity_probability": 0.0, "splash_samples": 12, "splash_roundness": 1.0},
    "F": {"circular_probability": 0.0, "continuity_probability": 0.0, "splash_samples": 12, "splash_roundness": 1.0},
    "G": {"circular_probability": 1.0, "continuity_probability": 0.0, "splash_samples": 12, "splash_roundness": 0.1},
    "H": {"circular_probability": 0.0, "continuity_probability": 0.0, "splash_samples": 12, "splash_roundness": 0.1},
}

MAX_PARTICLES = 1_000_000
MAX_SPRITES = 2_000_000  # max_particles · max(trail_textures, splash_samples): 20,000 · 16 by default
MAX_SUB_SPRITES = 64  # M and N: sub-sprites per particle, expanded on the GPU
MAX_CONTROL_POINTS = 16
MAX_KEYFRAMES = 64

Probability = Annotated[float, Field(ge=0.0, le=1.0)]


class Keyframe(ConfigModel):
    """A control-point position at a time; positions between keyframes are interpolated linearly."""

    time: float = Field(ge=0.0, le=1e6, description="Seconds since the emitter started (or since the loop began).")
    position: Vec3 = Field(description="Control point E at that time, in the wave frame (see ControlPoint).")


class ControlPoint(ConfigModel):
    """A control point E for irregular particles (eq. 3.5, section 3.3.2).

    Positions are relative to each particle's hit point H, in the wave frame: +x the emitter's right, +y its up,
    +z back towards the emitter (the emitter shoots along -z), so (0, 0, 1) lies 1 m in front of the hit
    surface on the shooter's side whatever the emitter's orientation.
    """

    position: Vec3 = Field((0.0, 0.0, 1.0), description="E relative to the hit point H in the wave frame, metres.")
    probability: float = Field(1.0, ge=0.0, le=1e6,
                               description="Relative weight of this point; a particle picks point i with "
                                           "probability weight_i / sum of weights.")
    spread: float = Field(0.0, ge=0.0, le=100.0,
                          description="Random spread: each particle aims at E plus a uniform offset within a "
                                      "ball of this radius (metres, fig. 4.8).")
    keyframes: list[Keyframe] = Field(default_factory=list, max_length=MAX_KEYFRAMES,
                                      description="Optional animation of E (keyframes, sorted by time); "
                                                  "overrides position when present.")
    loop: bool = Field(False, description="Repeat the keyframes with the period of the last keyframe's time.")
    noise_amplitude: float = Field(0.0, ge=0.0, le=100.0,
                                   description="Perlin-noise jitter of E per axis, metres (section 3.3.2).")
    noise_frequency: float = Field(1.0, gt=0.0, le=100.0, description="Perlin-noise jitter frequency, hertz.")

    @field_validator("keyframes")
    @classmethod
    def _sorted_keyframes(cls, keyframes: list[Keyframe]) -> list[Keyframe]:
        times = [k.time for k in keyframes]
        if times != sorted(times):
            raise ValueError(f"keyframes must be sorted by time, got times {times}")
        return keyframes

    @field_validator("loop")
    @classmethod
    def _loop_needs_period(cls, loop: bool, info: ValidationInfo) -> bool:
        keyframes = info.data.get("keyframes") or []
        if loop and (not keyframes or keyframes[-1].time <= 0.0):
            raise ValueError("loop needs keyframes whose last time is > 0 (the loop period)")
        return loop


def _default_control_points() -> list[ControlPoint]:
    """Four control points in an X around the hit (fig. 4.2 uses four for the irregular shape)."""
    return [ControlPoint(position=[x, y, 0.35]) for x, y in ((0.6, 0.6), (-0.6, 0.6), (0.6, -0.6), (-0.6, -0.6))]


class EnergyWaveEmitter(ConfigModel):
    """An energy-wave emitter (seeds/000): a particle beam that deforms into patterns A–H when it hits colliders."""

    # ---- the four shape parameters (table 4.2, upper block)
    circular_probability: Probability = Field(
        1.0, description="α: probability that a hit particle moves circularly (eqs. 3.2–3.4); else irregularly "
                         "towards a control point (eq. 3.5). Eq. 3.1.")
    continuity_probability: Probability = Field(
        0.3, description="β: probability that a hit particle renders continuous (trail, eq. 3.7); else separated "
                         "(grain or bar). Eq. 3.6.")
    splash_samples: int = Field(
        12, ge=1, le=MAX_SUB_SPRITES,
        description="N: splash sampling count; N = 1 separated particles are grains, N > 1 bars of N sprites "
                    "(eq. 3.8).")
    splash_roundness: float = Field(
        0.5, gt=0.0, le=1.0,
        description="t: splash roundness in (0, 1]; sprite j of a bar has size (N - (j-1)(1-t))/N · S (eq. 3.9): "
                    "t = 1 round tips, t -> 0 sharp tips (labelled round when t >= 0.5).")
    # ---- motion after the hit (table 4.2, lower block)
    lifetime_frames: float = Field(
        40.0, gt=0.0, le=100_000.0, description="τ: particle lifetime after the hit, in frames of 1/60 s.")
    lifetime_spread: float = Field(
        0.0, ge=0.0, le=100_000.0,
        description="Random spread of τ: each particle gets τ ± this many frames (uniform), at least one frame.")
    acceleration_continuous: float = Field(
        1.5, ge=0.0, le=10_000.0,
        description="c for circular-continuous particles (pattern A): |A| (eq. 3.4) in m/s per frame; A acts "
                    "during the collision frame, so the particle leaves the hit at c m/s.")
    acceleration_continuous_spread: float = Field(
        0.5, ge=0.0, le=10_000.0,
        description="Random spread of c (circular-continuous): c ± this, uniform, clamped at 0.")
    acceleration_separated: float = Field(
        2.5, ge=0.0, le=10_000.0,
        description="c for circular-separated particles (patterns C, E, G): |A| (eq. 3.4) in m/s per frame; "
                    "the particle leaves the hit at c m/s.")
    acceleration_separated_spread: float = Field(
        1.0, ge=0.0, le=10_000.0,
        description="Random spread of c (circular-separated): c ± this, uniform, clamped at 0.")
    repulsion: float = Field(
        4.0, ge=0.0, le=1e6, description="r: repulsion from a neighbour at distance 1 (in equation_unit) (eq. 3.3).")
    repulsion_radius: float = Field(
        0.25, gt=0.0, le=100.0,
        description="Effective radius of the neighbour repulsion R (eq. 3.3), metres; also the spatial-hash cell.")
    spring: float = Field(1.0, ge=0.0, le=1e6, description="k: penalty spring coefficient of the drag D (eq. 3.2).")
    damper: float = Field(0.8, ge=0.0, le=1e6, description="h: penalty damper coefficient of the drag D (eq. 3.2).")
    equation_unit: float = Field(
        0.025, gt=0.0, le=100.0,
        description="Length unit (metres) in which eqs. 3.2–3.3 are evaluated, with velocities per frame (1/60 s): "
                    "z, w and P, Q are expressed in it before D and R are summed, so it sets the balance of the "
                    "drag D (∝ 1/unit) against the repulsion R (∝ unit) for the paper's k, h, r: larger spreads the "
                    "circular splash flatter along the surface, smaller sends it back along the normal.")
    control_points: list[ControlPoint] = Field(
        default_factory=_default_control_points, max_length=MAX_CONTROL_POINTS,
        description="Control points E of irregular particles (eq. 3.5), relative to the hit in the wave frame.")
    # ---- rendering
    bar_spacing: float = Field(
        0.4, gt=0.0, le=100.0,
        description="u: spacing of the bar sprites along the travel direction (eq. 3.8), in sprite sizes S.")
    trail_textures: int = Field(
        16, ge=1, le=MAX_SUB_SPRITES,
        description="M: sprites of a continuous trail from the hit point P0 to the particle P1 (eq. 3.7).")
    trail_end_scale: float = Field(
        0.4, gt=0.0, le=1.0,
        description="Size factor of the last trail sprite (nearest the particle); the first, at P0, has size S.")
    particle_size: float = Field(
        0.09, gt=0.0, le=100.0, description="S: billboard radius at the particle, metres.")
    color: Color3 = Field((0.35, 0.65, 1.0), description="Glow colour (linear RGB) at the rim of each sprite.")
    core_color: Color3 = Field((1.0, 1.0, 1.0), description="Colour at the centre of each sprite (linear RGB).")
    intensity: float = Field(0.06, ge=0.0, le=1000.0, description="HDR brightness multiplier of every sprite.")
    glow: float = Field(0.5, ge=0.0, le=100.0, description="Strength of the bloom added around the wave (a frame uses the "
                                                                "largest among its emitters).")
    glow_radius: float = Field(2.0, ge=0.5, le=8.0, description="Bloom blur radius in glow-buffer pixels (largest among the "
                                                                "emitters).")
    # ---- emission
    emitting: bool = Field(True, description="Emit continuously from the start (scripts: energy_wave.set_emitting).")
    emission_rate: float = Field(1200.0, ge=0.0, le=1e7, description="Particles per second while emitting.")
    beam_speed: float = Field(6.0, gt=0.0, le=10_000.0, description="Speed of beam particles along the emitter's "
                                                                     "forward (-z) axis, m/s.")
    beam_radius: float = Field(0.12, ge=0.0, le=100.0, description="Radius of the beam's cross-section, metres.")
    beam_range: float = Field(12.0, gt=0.0, le=100_000.0,
                              description="Beam particles that hit nothing die after this distance, metres.")
    burst_duration: float = Field(0.5, gt=0.0, le=600.0,
                                  description="Seconds a burst (energy_wave.fire) lasts, at emission_rate.")
    max_particles: int = Field(20_000, ge=1, le=MAX_PARTICLES,
                               description="Capacity of the particle buffers; emission pauses when full.")
    particle_mass: float = Field(0.001, ge=0.0, le=1000.0,
                                 description="Mass per particle (kg) for the impulse sent in Impact events.")
    collision_layers: list[Annotated[str, Field(max_length=64)]] = Field(
        default_factory=list, max_length=32,
        description="Collider layers the beam hits; empty: every layer.")

    @field_validator("control_points")
    @classmethod
    def _irregular_needs_targets(cls, points: list[ControlPoint], info: ValidationInfo) -> list[ControlPoint]:
        alpha = info.data.get("circular_probability", 1.0)
        if alpha < 1.0 and not points:
            raise ValueError(f"circular_probability = {alpha} < 1 makes irregular particles (eq. 3.5), which need "
                             "at least one control point")
        if points and sum(c.probability for c in points) <= 0.0:
            raise ValueError("at least one control point needs a probability > 0")
        return points

    def scene_budgets(self, fixed_dt: float) -> list[tuple[str, float, float]]:
        """(what, cost, limit) that every entity of a scene shares (engine.scene: the sum of each is capped)."""
        return [("sprites (max_particles * max(trail_textures, splash_samples))", self._sprites(), MAX_SPRITES)]

    def _sprites(self) -> int:
        return self.max_particles * max(self.trail_textures, self.splash_samples)

    @model_validator(mode="after")
    def _sprite_budget(self) -> EnergyWaveEmitter:
        """Every particle may become a trail of M sprites or a bar of N: the sprite buffers hold max_particles ·
        max(M, N) billboards. Each bound alone is sane; together at their maxima they were 64 million sprites
        (gigabytes of index buffer, a minute a frame)."""
        sprites = self._sprites()
        if sprites > MAX_SPRITES:
            raise CrossFieldError(("max_particles", "trail_textures", "splash_samples"),
                                 f"max_particles * max(trail_textures, splash_samples) = {sprites} sprites exceeds "
                             f"{MAX_SPRITES}; lower max_particles, trail_textures or splash_samples")
        return self


@dataclass(frozen=True)
class EnergyWaveHit:
    """Sent once per tick per (emitter, collider) hit: where the wave struck, how hard, how many particles."""

    emitter: int
    target: int
    point: tuple[float, float, float]  # mean hit point
    normal: tuple[float, float, float]  # mean surface normal (unit)
    impulse: tuple[float, float, float]  # sum of particle_mass · incoming velocity (N·s)
    energy: float  # sum of ½ m |w|² (J)
    count: int  # particles that hit this tick
    trigger: bool = False  # the collider is a trigger (particles passed through)


_VEC_FIELDS = ("position", "velocity", "hit_point", "acceleration", "target_offset")
_SCALAR_FIELDS = ("age", "lifetime")
_CODE_FIELDS = ("pattern", "control")
_QUAT_FIELDS = ("frame",)
_FIELDS = (*_VEC_FIELDS, *_QUAT_FIELDS, *_SCALAR_FIELDS, *_CODE_FIELDS)


@dataclass
class ParticleBuffer:
    """Struct-of-arrays of one emitter's particles; slots [0, count) are alive (packed, order not meaningful).

    position, velocity (m, m/s); hit_point P0 = H (eq. 3.5, 3.7); acceleration A (eq. 3.4, circular only);
    target_offset (the random spread added to a control point); age (s since emission, reset at the hit);
    lifetime (s: beam range / speed before the hit, τ after); pattern (BEAM or 0..7 = A..H); control (index of the
    chosen control point, irregular only); frame (the emitter's rotation when the particle left it, a (w, x, y, z)
    quaternion: the wave's direction, which the control points are relative to, eq. 3.5).
    """

    capacity: int
    count: int = 0
    position: np.ndarray = field(default=None)  # type: ignore[assignment]
    velocity: np.ndarray = field(default=None)  # type: ignore[assignment]
    hit_point: np.ndarray = field(default=None)  # type: ignore[assignment]
    acceleration: np.ndarray = field(default=None)  # type: ignore[assignment]
    target_offset: np.ndarray = field(default=None)  # type: ignore[assignment]
    age: np.ndarray = field(default=None)  # type: ignore[assignment]
    lifetime: np.ndarray = field(default=None)  # type: ignore[assignment]
    pattern: np.ndarray = field(default=None)  # type: ignore[assignment]
    control: np.ndarray = field(default=None)  # type: ignore[assignment]
    frame: np.ndarray = field(default=None)  # type: ignore[assignment]

    def __post_init__(self) -> None:
        c = int(self.capacity)
        for name in _VEC_FIELDS:
            if getattr(self, name) is None:
                setattr(self, name, np.zeros((c, 3)))
        for name in _SCALAR_FIELDS:
            if getattr(self, name) is None:
                setattr(self, name, np.zeros(c))
        if self.pattern is None:
            self.pattern = np.full(c, BEAM, dtype=np.int8)
        if self.control is None:
            self.control = np.zeros(c, dtype=np.int8)
        if self.frame is None:
            self.frame = np.zeros((c, 4))
            self.frame[:, 0] = 1.0

    def __hash_state__(self) -> dict:
        """Only the live slots are state (dead slots keep stale values)."""
        n = self.count
        return {"count": n, **{k: getattr(self, k)[:n] for k in _FIELDS}}

    def arrays(self) -> list[np.ndarray]:
        return [getattr(self, k) for k in _FIELDS]

    def live(self, name: str) -> np.ndarray:
        """View of the live part of one array."""
        return getattr(self, name)[: self.count]

    def grow(self, capacity: int) -> None:
        """Reallocate to ``capacity`` slots, keeping the live particles (used when max_particles changes)."""
        capacity = int(capacity)
        keep = min(self.count, capacity)
        for name in _FIELDS:
            old = getattr(self, name)
            new = np.zeros((capacity,) + old.shape[1:], dtype=old.dtype)
            new[:keep] = old[:keep]
            setattr(self, name, new)
        self.capacity, self.count = capacity, keep


@dataclass
class EnergyWaveState:
    """Runtime state of one emitter: its particles, emission clock and counters."""

    particles: ParticleBuffer
    noise_seed: int
    time: float = 0.0  # seconds since the emitter started (control-point keyframes and noise run on it)
    emitting: bool = True
    emit_carry: float = 0.0  # fractional particle left over from the last tick's emission
    burst_time_left: float = 0.0  # seconds of burst emission still to go (energy_wave.fire)
    burst_rate: float = 0.0  # particles per second during the burst
    emitted: int = 0
    dropped: int = 0  # particles not emitted because the buffer was full
    hits_per_pattern: np.ndarray = field(default_factory=lambda: np.zeros(len(PATTERNS), dtype=np.int64))
    noise_cache: object = field(default=None, metadata={"hash": False})  # PerlinNoise built from noise_seed


def build_energy_wave(cfg: EnergyWaveEmitter, ctx) -> list:
    """Component factory: the validated config plus fresh runtime state (seeded from the entity's stream)."""
    rng = ctx.rng("energy_wave")
    noise_seed = int(rng.integers(0, 2**31 - 1))
    return [cfg, EnergyWaveState(ParticleBuffer(cfg.max_particles), noise_seed=noise_seed, emitting=cfg.emitting)]
