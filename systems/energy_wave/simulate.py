"""Per-step simulation of energy-wave emitters (seeds/000): numpy, with compiled loops in :mod:`.kernels`; no GL.

One fixed step of one emitter:

1. age every particle; irregular particles steer so they reach their control point E exactly when their lifetime τ
   runs out (eq. 3.5: v = (E − H)/τ while E stays put); circular particles keep the velocity A·(1 frame) that the
   collision gave them (eq. 3.4);
2. beam particles sweep their segment x → x + v·dt against every collider (boxes, spheres, planes, height fields,
   via ``Collider.ray_cast``); the first hit stops the particle at the surface point H and decides its pattern
   (eqs. 3.1, 3.6, N and t) and its motion (eq. 3.2–3.4 or 3.5); particles that miss fly on and can hit another
   collider later (fig. 4.7);
3. emission: new beam particles spread evenly over the step along the beam;
4. dead particles (age > lifetime) are removed by swapping the tail into their slots (O(dead));
5. one ``Impact`` and one ``EnergyWaveHit`` event per (emitter, collider) hit this step.

The emitters of a world step together, phase by phase: one ray cast and one depth query per collider for all
beams, one neighbour search for all emitters' hits (each emitter's particles repel only its own), and per emitter,
in entity order, its random draws and events. Each emitter only touches its own state and random stream, so the
result is the one of stepping them one after the other (tested).

Sign conventions (the printed eqs. 3.2 and 3.3 point the damper and the "repulsion" inwards):
D = k z n − h (w·n) n (the damper opposes the normal velocity, so a particle entering the surface is pushed out);
R = r Σ (P − Q_i)/|P − Q_i|² (away from the neighbours), with the part of R that points into the surface removed
(the surface holds it). A = c (D + R)/|D + R| is the acceleration "at the collision": it acts during the collision
frame (1/60 s), so the particle leaves H with velocity A·frame, of speed c (c in m/s per frame), and keeps it.
The incoming beam velocity is absorbed by the hit.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from components.energy_wave import (BEAM, FRAME, PATTERNS, ROUND_THRESHOLD, EnergyWaveEmitter, EnergyWaveHit,
                                    EnergyWaveState, ParticleBuffer)
from engine import exact
from engine.collider import Collider
from engine.exact import length, matvec
from engine.impacts import Impact
from engine.noise import PerlinNoise
from engine.spatial import Transform, quat_is_identity, quat_rotate, quat_to_matrix
from engine.world import World

from .kernels import advance_particles, dead_moves, gather_in_box, move_rows
from .neighbours import grouped_repulsion

F64 = NDArray[np.float64]

NEIGHBOUR_SAMPLE_LIMIT = 16  # per hashed cell: crowded cells are sampled (unbiased) so cost stays bounded
_EPS = 1e-12
_SIGN_AND_LOW = np.int8(-127)  # 0b10000001: the sign bit and the lowest bit of an int8 pattern code
_ROW = np.dtype((np.void, 24))  # one (x, y, z) float64 row as a 24-byte record
_QUAT_ROW = np.dtype((np.void, 32))  # one (w, x, y, z) float64 row as a 32-byte record


def _rows(array: F64) -> NDArray[np.void]:
    """A C-contiguous (n, 3) float64 array seen as n 24-byte records, or an (n, 4) one as 32-byte records (raises
    on any other layout)."""
    return array.view(_ROW if array.shape[1] == 3 else _QUAT_ROW)[:, 0]


def _take_rows(array: F64, rows: NDArray[np.int64]) -> F64:
    """``array[rows]`` of an (n, 3) array: numpy's fancy row indexing is several times slower than np.take."""
    return array.take(rows, axis=0)


def _put_rows(array: F64, rows: NDArray[np.int64], values: F64) -> None:
    """``array[rows] = values`` for a C-contiguous (n, 3) float64 array: one np.put of 24-byte records (the same
    bytes, several times faster than fancy row assignment)."""
    _rows(array).put(rows, _rows(np.ascontiguousarray(values, dtype=np.float64)))


@dataclass
class ColliderEntry:
    """A collider the beam can hit, with its transform and a world-space bounding box (None: unbounded)."""

    entity: int
    collider: Collider
    transform: Transform
    lo: F64 | None
    hi: F64 | None


# ----------------------------------------------------------------------------------------------------- colliders
def collider_bounds(collider: Collider, transform: Transform) -> tuple[F64 | None, F64 | None]:
    """World axis-aligned bounds of a collider's solid (None, None when unbounded: planes, rotated terrain)."""
    if collider.shape == "box":
        h = collider.half_extents * np.abs(transform.scale)
        extent = matvec(np.abs(quat_to_matrix(transform.rotation)), h)
        return transform.position - extent, transform.position + extent
    if collider.shape == "sphere":
        r = collider.radius * float(np.max(np.abs(transform.scale)))
        return transform.position - r, transform.position + r
    if collider.shape == "heightfield" and quat_is_identity(transform.rotation):
        # Solid in the column below the surface over the footprint (engine.heightfield.HeightField.solid_distance;
        # height fields ignore scale): bounded but for its bottom.
        field = collider.heightfield
        (x_lo, x_hi), (z_lo, z_hi) = field.bounds()
        top = float(field.heights.max()) + transform.position[1]  # height_range[1], without its min
        low = np.array([x_lo + transform.position[0], -np.inf, z_lo + transform.position[2]])
        high = np.array([x_hi + transform.position[0], top, z_hi + transform.position[2]])
        pad = 1e-9 * (1.0 + np.maximum(np.abs(low), np.abs(high)))  # the collider subtracts the position instead:
        pad[1] = 0.0  # a point on the footprint's edge must stay a candidate whatever the rounding
        return low - pad, high + pad
    return None, None


class ColliderBoundsCache:
    """The bounds of box and sphere colliders, per entity, kept while their shape and transform stay the same
    (most colliders do not move, and every tick's sweep needs them).  Height fields are not cached: a water
    surface's heights change in place every tick."""

    def __init__(self) -> None:
        self.entries: dict[int, tuple[tuple, F64 | None, F64 | None]] = {}

    def bounds(self, entity: int, collider: Collider, transform: Transform) -> tuple[F64 | None, F64 | None]:
        if collider.shape not in ("box", "sphere"):
            return collider_bounds(collider, transform)
        key = (id(collider), collider.shape, collider.half_extents.tobytes(), collider.radius,
               transform.position.tobytes(), transform.rotation.tobytes(), transform.scale.tobytes())
        cached = self.entries.get(entity)
        if cached is None or cached[0] != key:
            cached = (key, *collider_bounds(collider, transform))
            self.entries[entity] = cached
        return cached[1], cached[2]


def gather_colliders(world: World) -> list[ColliderEntry]:
    """Every entity with Transform + Collider, ascending by entity id (see :func:`hittable` for one emitter's)."""
    cache = world.try_resource(ColliderBoundsCache)
    if cache is None:
        cache = ColliderBoundsCache()
        world.insert_resource(cache)
    out = []
    for entity, (transform, collider) in world.query(Transform, Collider):
        lo, hi = cache.bounds(entity, collider, transform)
        out.append(ColliderEntry(entity, collider, transform, lo, hi))
    if len(cache.entries) > 2 * len(out) + 16:  # forget despawned entities now and then
        live = {entry.entity for entry in out}
        cache.entries = {e: v for e, v in cache.entries.items() if e in live}
    return out


def hittable(colliders: list[ColliderEntry], emitter: int, layers: list[str]) -> NDArray[np.bool_]:
    """Which ``colliders`` the beam of ``emitter`` can hit: all but the emitter itself, only ``layers`` if given."""
    return np.array([entry.entity != emitter and (not layers or entry.collider.layer in layers)
                     for entry in colliders], dtype=bool)


@dataclass
class SweepResult:
    """First solid hit of each swept segment (collider index -1: none) and trigger entries."""

    t: F64
    collider: NDArray[np.int64]
    normal: F64
    triggers: list[tuple[int, NDArray[np.int64], F64]]  # (collider index, segment rows, entry points)


def sweep(p0: F64, p1: F64, colliders: list[ColliderEntry],
          allowed: NDArray[np.bool_] | None = None) -> SweepResult:
    """Ray-cast the segments p0 → p1 against every collider; keep the first solid hit per segment.

    ``allowed`` (segments, colliders) says which segment may hit which collider (None: every one), so the
    segments of several emitters are cast together: one ray cast per collider that some segment can reach
    (:func:`sweep_candidates`), in collider order.
    """
    n = len(p0)
    best_t = np.full(n, np.inf)
    best_c = np.full(n, -1, dtype=np.int64)
    best_n = np.zeros((n, 3))
    trigger_hits = []
    candidates = sweep_candidates(p0, p1, colliders, allowed)
    for index in np.flatnonzero(candidates.any(axis=1)).tolist():  # loop over reachable colliders, ascending
        entry = colliders[index]
        rows = np.flatnonzero(candidates[index])
        origin = _take_rows(p0, rows)
        hit, t, normal = entry.collider.ray_cast(origin, _take_rows(p1, rows) - origin, entry.transform, max_t=1.0)
        if entry.collider.is_trigger:
            enter = hit & (t > 0.0)
            trigger_hits.append((index, rows[enter], t[enter]))
            continue
        better = hit & (t < best_t[rows])
        rows = rows[better]
        best_t[rows], best_c[rows] = t[better], index
        _put_rows(best_n, rows, _take_rows(normal, np.flatnonzero(better)))
    triggers = []
    for index, rows, t in trigger_hits:  # a trigger behind a solid hit in the same step is not reached
        keep = t <= best_t[rows]
        rows, t = rows[keep], t[keep]
        if rows.size:
            triggers.append((index, rows, p0[rows] + t[:, None] * (p1[rows] - p0[rows])))
    return SweepResult(best_t, best_c, best_n, triggers)


def sweep_candidates(p0: F64, p1: F64, colliders: list[ColliderEntry],
                     allowed: NDArray[np.bool_] | None = None) -> NDArray[np.bool_]:
    """Which segments p0 → p1 each collider must be ray-cast against: (colliders, segments), C-contiguous.

    A segment is a candidate of a collider it is ``allowed`` to hit (None: every one) when the collider is
    unbounded, or when the segment's bounding box meets the collider's on every axis: some end ≥ lo and some
    end ≤ hi. All bounded colliders are tested in one broadcast comparison; ``np.fmax``/``np.fmin`` of the ends
    keep the per-end test's answer when one end is NaN (the other end decides; two NaN ends meet no box).
    """
    n, m = len(p0), len(colliders)
    if allowed is None:
        candidates = np.ones((m, n), dtype=bool)
    else:
        candidates = np.array(allowed.T, dtype=bool, order="C")
    bounded = [index for index, entry in enumerate(colliders) if entry.lo is not None]
    if not bounded or n == 0:
        return candidates
    lo = np.array([colliders[index].lo for index in bounded]).T[:, :, None]  # (axis, collider, 1)
    hi = np.array([colliders[index].hi for index in bounded]).T[:, :, None]
    # (axis, collider, segment), segments contiguous: numpy's broadcast is several times slower over (segment, axis)
    reach_up = np.fmax(p0.T, p1.T, order="C")[:, None, :] >= lo
    reach_down = np.fmin(p0.T, p1.T, order="C")[:, None, :] <= hi
    overlap = reach_up[0] & reach_up[1] & reach_up[2] & reach_down[0] & reach_down[1] & reach_down[2]
    if len(bounded) == m:
        candidates &= overlap
    else:
        candidates[bounded] &= overlap
    return candidates


# ------------------------------------------------------------------------------------------------- the equations
def penalty_drag(depth: F64, normal: F64, velocity: F64, spring: float, damper: float) -> F64:
    """Drag D of the object (eq. 3.2, penalty method): D = k z n − h (w·n) n.

    The thesis prints + h (w·n) n; for a particle entering the surface (w·n < 0) that points inwards, so the
    damper here opposes the normal velocity as a penalty damper does: both terms push out of the object.
    """
    wn = np.einsum("ij,ij->i", velocity, normal)
    return (spring * depth - damper * wn)[:, None] * normal


def collision_acceleration(drag: F64, repulsion: F64, normal: F64, magnitude: F64) -> F64:
    """A = c (D + R)/|D + R| (eq. 3.4): same magnitude c for every particle, direction from D + R.

    The inward normal part of R is dropped first (the surface holds the particle against neighbours that splashed
    off before it); when D + R ≈ 0 the direction falls back to the surface normal n.
    """
    inward = np.minimum(np.einsum("ij,ij->i", repulsion, normal), 0.0)
    total = drag + repulsion - inward[:, None] * normal
    length = np.sqrt(np.einsum("ij,ij->i", total, total))
    safe = length > 1e-9
    direction = np.where(safe[:, None], total / np.where(safe, length, 1.0)[:, None], normal)
    return magnitude[:, None] * direction


def assign_patterns(u_circular: F64, u_continuous: F64, alpha: float, beta: float, samples: int,
                    roundness: float) -> NDArray[np.int8]:
    """Pattern code 0..7 (= A..H) of hit particles from two uniform draws each (section 3.2).

    Circular with probability α (eq. 3.1), continuous with probability β (eq. 3.6); separated particles are grains
    when N = 1, bars when N > 1; bars are round when t >= 0.5, sharp below (the tip shape itself follows t
    continuously through eq. 3.9 when drawn).
    """
    return _patterns(u_circular, u_continuous, alpha, beta, _separated_kind(samples, roundness))


def _separated_kind(samples: int, roundness: float) -> int:
    """Drawing kind of separated particles: 1 grain (N = 1), 2 round bar (t >= 0.5), 3 sharp bar."""
    if samples <= 1:
        return 1
    return 2 if roundness >= ROUND_THRESHOLD else 3


def _patterns(u_circular: F64, u_continuous: F64, alpha: F64 | float, beta: F64 | float,
              separated_kind: NDArray[np.int8] | int) -> NDArray[np.int8]:
    """:func:`assign_patterns` with α, β and the separated kind per particle (or shared)."""
    irregular = (u_circular >= alpha).astype(np.int8)
    kind = np.where(u_continuous < beta, 0, separated_kind).astype(np.int8)
    return (2 * kind + irregular).astype(np.int8)


def is_circular(pattern: NDArray[np.int8]) -> NDArray[np.bool_]:
    return (pattern & _SIGN_AND_LOW) == 0  # a bit test (int8 % is slow): not negative (BEAM), even


def is_irregular(pattern: NDArray[np.int8]) -> NDArray[np.bool_]:
    return (pattern & _SIGN_AND_LOW) == 1  # not negative, odd


def bar_offsets(samples: int, spacing: float) -> F64:
    """Offsets of a bar's sprites along d (eq. 3.8): U_j = Q + (−1)^j u (j − 1) d, j = 1..N (units of u·S)."""
    j = np.arange(1, samples + 1)
    return np.where(j % 2 == 0, 1.0, -1.0) * spacing * (j - 1)


def bar_sizes(samples: int, roundness: float) -> F64:
    """Relative sprite sizes of a bar (eq. 3.9): S_j / S = (N − (j − 1)(1 − t)) / N, j = 1..N."""
    j = np.arange(1, samples + 1)
    return (samples - (j - 1) * (1.0 - roundness)) / samples


def trail_fractions(textures: int) -> F64:
    """Positions of a continuous trail's sprites (eq. 3.7): T_i = P0 + (P1 − P0)(i − 1)/M, i = 1..M."""
    return np.arange(textures) / textures


def trail_sizes(textures: int, end_scale: float) -> F64:
    """Relative sizes along a trail: 1 at P0 shrinking linearly to ``end_scale`` at the last sprite."""
    if textures == 1:
        return np.ones(1)
    return 1.0 - (1.0 - end_scale) * np.arange(textures) / (textures - 1)


# ------------------------------------------------------------------------------------------------ control points
def control_point_offsets(cfg: EnergyWaveEmitter, time: float, noise: PerlinNoise) -> F64:
    """Control points E_k (K, 3) in the wave frame at ``time``: keyframes (linear, optional loop) plus Perlin jitter."""
    out = np.zeros((len(cfg.control_points), 3))
    for k, cp in enumerate(cfg.control_points):  # loop over control points (at most 16)
        if cp.keyframes:
            times = np.array([key.time for key in cp.keyframes])
            positions = np.array([key.position for key in cp.keyframes])
            t = time % times[-1] if cp.loop else time
            out[k] = [np.interp(t, times, positions[:, a]) for a in range(3)]
        else:
            out[k] = cp.position
        if cp.noise_amplitude > 0.0:
            jitter = noise.noise3(np.full(3, cp.noise_frequency * time), np.full(3, 7.31 * k + 0.5),
                                  np.array([0.25, 3.75, 7.25]))
            out[k] += cp.noise_amplitude * jitter
    return out


def _noise(state: EnergyWaveState) -> PerlinNoise:
    if state.noise_cache is None or state.noise_cache.seed != state.noise_seed:
        state.noise_cache = PerlinNoise(state.noise_seed)
    return state.noise_cache


# ------------------------------------------------------------------------------------------------------ the step
@dataclass
class _Emitter:
    """One emitter during a step: its components and random stream, and the segments its beam flies."""

    entity: int
    transform: Transform
    cfg: EnergyWaveEmitter
    state: EnergyWaveState
    rng: np.random.Generator
    beam: NDArray[np.int64] | None = None  # slots of the particles flying as beam at the start of the step
    start: F64 | None = None  # their positions before the move


class _Scratch:
    """Work arrays reused from step to step for temporaries as large as a particle buffer.

    Allocating and freeing such arrays every step costs a page fault per 4 KiB on small VMs (the allocator hands
    the memory back each time; on the 2-core VM such faults took a third of the step). Never state: every use
    writes the array before reading it.
    """

    def __init__(self) -> None:
        self._arrays: dict[str, np.ndarray] = {}

    def get(self, name: str, shape: tuple[int, ...]) -> F64:
        size = math.prod(shape)
        array = self._arrays.get(name)
        if array is None or array.size < size:
            array = self._arrays[name] = np.empty(max(size, 1024))
        return array[:size].reshape(shape)


_SCRATCH = _Scratch()


def _remove_dead(buf: ParticleBuffer) -> int:
    """Remove the particles whose life is over (age > lifetime) by moving live tail particles into their slots
    (:func:`.kernels.dead_moves`); returns how many died."""
    dead, holes, movers = dead_moves(buf.age, buf.lifetime, buf.count)
    if holes.size:  # as many live particles above the new count move down into them
        for array in buf.arrays():  # loop over the particle arrays; (n, 3) and (n, 4) ones moved as records
            flat = _rows(array) if array.ndim == 2 else array
            flat.put(holes, flat.take(movers))
    buf.count -= dead
    return int(dead)


def _emission_count(cfg: EnergyWaveEmitter, state: EnergyWaveState, dt: float) -> int:
    """How many beam particles this step spawns (the rate's fractional carry kept; the excess over the buffer's
    room counted as dropped); advances the burst clock."""
    rate = (cfg.emission_rate if state.emitting else 0.0)
    burst = min(state.burst_time_left, dt)
    wanted = state.emit_carry + rate * dt + state.burst_rate * burst
    state.burst_time_left = max(0.0, state.burst_time_left - dt)
    if state.burst_time_left == 0.0:
        state.burst_rate = 0.0
    count = int(np.floor(wanted))
    state.emit_carry = wanted - count
    buf = state.particles
    room = buf.capacity - buf.count
    if count > room:
        state.dropped += count - room
        count = room
    return max(count, 0)


def _emit(emitters: list[_Emitter], dt: float) -> None:
    """Spawn this step's beam particles of every emitter, spread evenly along the distance each beam covers in one
    step and uniformly over the beam's cross-section disc (float64 sin/cos for cross-machine determinism).

    Each emitter draws its stratification phases, then its disc radii and angles from its own stream (the order
    of one emitter alone); the positions are then computed once for all of them."""
    spawning, draws = [], []
    for e in emitters:  # loop over emitters: counts and random draws in each one's own stream
        count = _emission_count(e.cfg, e.state, dt)
        if count > 0:
            spawning.append((e, count))
            draws.append((e.rng.random(count), e.rng.random(count), e.rng.random(count)))
    if not spawning:
        return
    counts = np.array([count for _, count in spawning])
    firsts = np.cumsum(counts) - counts
    axes = quat_to_matrix(np.array([e.transform.rotation for e, _ in spawning]))  # columns: right, up, back (+z)
    right = np.repeat(axes[:, :, 0], counts, axis=0)
    up = np.repeat(axes[:, :, 1], counts, axis=0)
    forward = np.repeat(-axes[:, :, 2], counts, axis=0)
    u_phase, u_radius, u_angle = (np.concatenate(parts) for parts in zip(*draws))
    serial = (np.arange(len(u_phase)) - np.repeat(firsts, counts)).astype(np.float64)
    phase = (serial + u_phase) / np.repeat(counts.astype(np.float64), counts)  # stratified over the step
    r = _per_row([e.cfg.beam_radius for e, _ in spawning], counts) * np.sqrt(u_radius)
    theta = 2.0 * np.pi * u_angle
    disc = (r * exact.cos(theta))[:, None] * right + (r * exact.sin(theta))[:, None] * up
    speed = _per_row([e.cfg.beam_speed for e, _ in spawning], counts)
    position = (np.repeat(np.array([e.transform.position for e, _ in spawning], np.float64), counts, axis=0) + disc
                + (phase * speed * dt)[:, None] * forward)
    age = phase * dt
    for i, (e, count) in enumerate(spawning):  # loop over emitters: each one's own buffer
        buf, cfg = e.state.particles, e.cfg
        own = slice(int(firsts[i]), int(firsts[i] + count))
        s = slice(buf.count, buf.count + count)
        buf.position[s] = position[own]
        buf.velocity[s] = cfg.beam_speed * forward[own.start]
        buf.hit_point[s] = position[own]
        buf.acceleration[s] = 0.0
        buf.target_offset[s] = 0.0
        buf.age[s] = age[own]
        buf.lifetime[s] = cfg.beam_range / cfg.beam_speed
        buf.pattern[s] = BEAM
        buf.control[s] = 0
        buf.frame[s] = e.transform.rotation
        buf.count += count
        e.state.emitted += count


def emit(cfg: EnergyWaveEmitter, state: EnergyWaveState, transform: Transform, rng: np.random.Generator,
         dt: float) -> int:
    """Spawn one emitter's beam particles of this step (see :func:`_emit`); returns how many."""
    before = state.emitted
    _emit([_Emitter(-1, transform, cfg, state, rng)], dt)
    return state.emitted - before


def _ball(rng: np.random.Generator, count: int) -> F64:
    """Uniform points in the unit ball."""
    return _ball_points(rng.standard_normal((count, 3)), rng.random(count))


def _ball_points(normal: F64, uniform: F64) -> F64:
    """Uniform points in the unit ball from standard normal triples (directions) and uniforms (radii³)."""
    normal /= np.maximum(np.linalg.norm(normal, axis=1, keepdims=True), _EPS)
    return normal * exact.cbrt(uniform)[:, None]


@dataclass
class _Splashes:
    """Beam particles of every emitter that hit this step, between their random draws and their landing, emitter
    after emitter (``first[i]`` .. ``first[i + 1]`` belong to flying emitter i)."""

    first: NDArray[np.int64]
    rows: NDArray[np.int64]  # buffer slots, each in its emitter's buffer
    point: F64  # hit points H
    normal: F64  # surface normals n there
    pattern: NDArray[np.int8]
    lifetime: F64
    magnitude: F64  # c (m/s²)
    control: NDArray[np.int8]
    offset: F64  # random offsets of the control points
    circular: NDArray[np.int64]  # which of them move circularly (eqs. 3.2–3.4), ascending
    query: F64  # the hit points of the circular ones (the queries of eq. 3.3)
    drag: F64  # D (eq. 3.2) of the circular ones
    neighbours: list[F64]  # per emitter: positions that repel its circular ones (eq. 3.3)
    incoming: F64  # their beam velocities before the hit


def _per_row(values: list[float], counts: NDArray[np.int64]) -> F64:
    """Each emitter's value repeated for each of its ``counts`` particles."""
    return np.repeat(np.array(values, dtype=np.float64), counts)


def _splash(emitters: list[_Emitter], first: NDArray[np.int64], rows: NDArray[np.int64], point: F64, normal: F64,
            depth: F64) -> _Splashes:
    """Draw the pattern, lifetime, c and control point of the beam particles that hit (sections 3.2–3.3) and the
    drag D of the circular ones (eq. 3.2), and gather their neighbours; :func:`_repulsions` then gives their
    repulsion R (eq. 3.3) and :func:`_land` their acceleration (eq. 3.4).

    Each emitter draws from its own stream, in the same order as when it steps alone (its uniforms, then its
    control-point offsets); the arithmetic then runs once over every emitter's particles, with the emitters'
    parameters repeated per particle (the same operations on the same values: the same bits).
    """
    counts = np.diff(first)
    u_parts, normals, uniforms = [], [], []
    for i, e in enumerate(emitters):  # loop over emitters: random draws in each one's own stream
        n = int(counts[i])
        u_parts.append(e.rng.random((n, 5)) if n else np.zeros((0, 5)))  # no hit, no draw
        if e.cfg.control_points and n:
            normals.append(e.rng.standard_normal((n, 3)))
            uniforms.append(e.rng.random(n))
    u = np.concatenate(u_parts)
    cfgs = [e.cfg for e in emitters]
    pattern = _patterns(u[:, 0], u[:, 1], _per_row([c.circular_probability for c in cfgs], counts),
                        _per_row([c.continuity_probability for c in cfgs], counts),
                        np.repeat(np.array([_separated_kind(c.splash_samples, c.splash_roundness) for c in cfgs],
                                           np.int8), counts))
    lifetime = np.maximum(_per_row([c.lifetime_frames for c in cfgs], counts)
                          + _per_row([c.lifetime_spread for c in cfgs], counts) * (2.0 * u[:, 2] - 1.0), 1.0) * FRAME
    continuous = pattern < 2
    c = np.where(continuous, _per_row([c.acceleration_continuous for c in cfgs], counts),
                 _per_row([c.acceleration_separated for c in cfgs], counts))
    spread = np.where(continuous, _per_row([c.acceleration_continuous_spread for c in cfgs], counts),
                      _per_row([c.acceleration_separated_spread for c in cfgs], counts))
    c = np.maximum(c + spread * (2.0 * u[:, 3] - 1.0), 0.0) / FRAME  # (m/s per frame) -> m/s²
    # Irregular: pick a control point by its probability, and a random offset within its spread.
    control = np.zeros(len(u), dtype=np.int8)
    offset = np.zeros((len(u), 3))
    if normals:
        with_points, radii = [], []
        for i, e in enumerate(emitters):  # loop over emitters with control points (at most 16 points each)
            if not e.cfg.control_points or not counts[i]:
                continue
            own = slice(int(first[i]), int(first[i + 1]))
            weights = np.array([cp.probability for cp in e.cfg.control_points])
            cumulative = weights.cumsum() / weights.sum()
            control[own] = np.minimum(cumulative.searchsorted(u[own, 4], side="right"), len(weights) - 1)
            with_points.append(own)
            radii.append(np.array([cp.spread for cp in e.cfg.control_points]).take(control[own]))
        ball = _ball_points(np.concatenate(normals), np.concatenate(uniforms))
        ball *= np.concatenate(radii)[:, None]
        if len(ball) == len(u):  # every emitter that was hit has control points: all rows, in order
            offset = ball
        else:
            _put_rows(offset, np.concatenate([np.arange(s.start, s.stop) for s in with_points]), ball)
    # Circular: the drag D (eq. 3.2) now, in the paper's units (lengths in `equation_unit`, velocities per frame).
    circ = ((pattern & 1) == 0).nonzero()[0]  # codes 0..7 here: even is circular (int8 % is slow)
    bounds = np.searchsorted(circ, first)
    circ_counts = np.diff(bounds)
    unit = _per_row([e.cfg.equation_unit for e in emitters], circ_counts)
    per_frame = _per_row([FRAME / e.cfg.equation_unit for e in emitters], circ_counts)
    w = np.concatenate([_take_rows(e.state.particles.velocity, e.beam[rows[first[i]: first[i + 1]]])
                        for i, e in enumerate(emitters)])
    drag = penalty_drag(depth.take(circ) / unit, _take_rows(normal, circ), _take_rows(w, circ) * per_frame[:, None],
                        _per_row([e.cfg.spring for e in emitters], circ_counts),
                        _per_row([e.cfg.damper for e in emitters], circ_counts))
    # Neighbours for R (eq. 3.3): every particle of the emitter already hit (its hits are still BEAM in the buffer)
    # and its hits this step, only those near the queries (the impact zone is small).
    neighbours = []
    gathered = _SCRATCH.get("neighbours", (sum(e.state.particles.count for e in emitters) + len(point), 3))
    used = 0
    query = _take_rows(point, circ)
    querying = np.flatnonzero(circ_counts)  # each emitter's queries' box (neighbours.in_reach), all at once
    lows = np.minimum.reduceat(query, bounds[querying]) if querying.size else query
    highs = np.maximum.reduceat(query, bounds[querying]) if querying.size else query
    k = 0
    for i, e in enumerate(emitters):  # loop over emitters: each one's particles repel only its own
        if bounds[i] == bounds[i + 1]:
            neighbours.append(np.zeros((0, 3)))
            continue
        buf = e.state.particles
        own = point[first[i]: first[i + 1]]
        lo = lows[k] - e.cfg.repulsion_radius  # the box grown by the radius
        hi = highs[k] + e.cfg.repulsion_radius
        k += 1
        found = gather_in_box(buf.position, buf.pattern, buf.count, own, lo, hi, gathered[used:])
        neighbours.append(gathered[used: used + found])
        used += found
    slots = np.concatenate([e.beam[rows[first[i]: first[i + 1]]] for i, e in enumerate(emitters)])
    return _Splashes(first, slots, point, normal, pattern, lifetime, c, control, offset, circ, query, drag, neighbours,
                     w)


def _repulsions(emitters: list[_Emitter], splash: _Splashes) -> F64:
    """R (eq. 3.3) of every circular particle from its own emitter's neighbours, all emitters at once, in the
    order of ``splash.circular``."""
    bounds = np.searchsorted(splash.circular, splash.first)
    groups = [(splash.query[bounds[i]: bounds[i + 1]], splash.neighbours[i], e.cfg.repulsion_radius,
               e.cfg.repulsion * e.cfg.equation_unit) for i, e in enumerate(emitters)]
    found = grouped_repulsion(groups, NEIGHBOUR_SAMPLE_LIMIT)
    return np.concatenate(found) if found else np.zeros((0, 3))


def _accelerations(splash: _Splashes, repulsion: F64) -> F64:
    """A = c (D + R)/|D + R| (eq. 3.4) of the circular particles; 0 for the irregular ones (eq. 3.5 steers them)."""
    acceleration = np.zeros((len(splash.rows), 3))
    circ = splash.circular
    if circ.size:
        _put_rows(acceleration, circ, collision_acceleration(splash.drag, repulsion, _take_rows(splash.normal, circ),
                                                             splash.magnitude.take(circ)))
    return acceleration


def _land(cfg: EnergyWaveEmitter, state: EnergyWaveState, splash: _Splashes, acceleration: F64, own: slice) -> None:
    """Turn the beam particles ``own`` of ``splash`` into splash particles at their hit points: circular ones leave
    with A (eq. 3.4) acting for one frame, irregular ones with eq. 3.5's velocity (E − H) / τ towards their
    control point (at rest without control points), which the next steps keep steering."""
    buf = state.particles
    rows = splash.rows[own]
    point = splash.point[own]
    acceleration = acceleration[own]
    _put_rows(buf.position, rows, point)
    _put_rows(buf.hit_point, rows, point)
    _put_rows(buf.velocity, rows, acceleration * FRAME)  # A acts during the collision frame; irregular: at rest
    _put_rows(buf.acceleration, rows, acceleration)
    _put_rows(buf.target_offset, rows, splash.offset[own])
    buf.age[rows] = 0.0
    buf.lifetime[rows] = splash.lifetime[own]
    buf.pattern[rows] = splash.pattern[own]
    buf.control[rows] = splash.control[own]
    irregular = rows[is_irregular(splash.pattern[own])]
    if irregular.size and cfg.control_points:
        target = _irregular_targets(cfg, state, irregular)
        _put_rows(buf.velocity, irregular, (target - _take_rows(buf.hit_point, irregular))
                  / buf.lifetime[irregular][:, None])
    state.hits_per_pattern += np.bincount(splash.pattern[own], minlength=len(PATTERNS))


def _send_events(world: World, emitter: int, colliders: list[ColliderEntry], which: NDArray[np.int64],
                 point: F64, normal: F64, velocity: F64, mass: float, trigger: bool = False) -> None:
    """One Impact (solid colliders) and one EnergyWaveHit per collider hit this step: aggregated, not per particle."""
    if len(which) == 0:
        return
    single = not (which != which[0]).any()  # the usual case: one collider, every row (no selection copies)
    for index in which[:1] if single else np.unique(which):  # loop over the colliders that were hit
        if single:
            p, n, v = point, normal, velocity
        else:
            sel = which == index
            p, n, v = point[sel], normal[sel], velocity[sel]
        count = len(p)
        mean_point = np.add.reduce(p, axis=0) / count  # what p.mean(axis=0) computes, without its wrapper
        mean_normal = np.add.reduce(n, axis=0)
        mean_normal = mean_normal / max(float(length(mean_normal)), _EPS)
        impulse = mass * np.add.reduce(v, axis=0)
        energy = 0.5 * mass * float(np.einsum("ij,ij->", v, v))
        target = colliders[int(index)].entity
        at, i, nn = tuple(mean_point.tolist()), tuple(impulse.tolist()), tuple(mean_normal.tolist())
        if not trigger:
            world.events.send(Impact(target, at, i, source=emitter, kind="energy_wave"))
        world.events.send(EnergyWaveHit(emitter, target, at, nn, i, energy, count, trigger))


def _steer_irregular(cfg: EnergyWaveEmitter, state: EnergyWaveState, irregular: NDArray[np.int64], dt: float) -> None:
    """Irregular particles (slots ``irregular``) aim at their control point so that they arrive when τ runs out
    (eq. 3.5)."""
    buf = state.particles
    target = _irregular_targets(cfg, state, irregular)
    remaining = np.maximum(buf.lifetime[irregular] - buf.age[irregular] + dt, dt)  # age already advanced
    buf.velocity[irregular] = (target - buf.position[irregular]) / remaining[:, None]


def _irregular_targets(cfg: EnergyWaveEmitter, state: EnergyWaveState, rows: NDArray[np.int64]) -> F64:
    """Where the irregular particles ``rows`` fly to (eq. 3.5): E = H + the chosen control point at the emitter's
    current time, in the frame of the wave each particle came with (its emission rotation, so turning the
    emitter afterwards does not swing splashes already flying), plus its random spread."""
    buf = state.particles
    local = control_point_offsets(cfg, state.time, _noise(state))
    control = np.minimum(buf.control[rows], len(local) - 1)  # the config may have lost points since
    offsets = quat_rotate(buf.frame[rows], local[control])
    return buf.hit_point[rows] + offsets + buf.target_offset[rows]


def _advance(e: _Emitter, dt: float) -> None:
    """Age every particle, steer the irregular ones (eq. 3.5) and move everything; remember the beam segments."""
    buf = e.state.particles
    if buf.capacity != e.cfg.max_particles:
        buf.grow(e.cfg.max_particles)
    e.state.time += dt
    steer = bool(e.cfg.control_points)  # without control points irregular particles keep their velocity
    e.beam, e.start, irregular = advance_particles(buf.position, buf.velocity, buf.age, buf.pattern, buf.count, dt,
                                                   steer)
    if irregular.size:
        _steer_irregular(e.cfg, e.state, irregular, dt)
        move_rows(buf.position, buf.velocity, irregular, dt)


def _penetration(end: F64, rows: NDArray[np.int64], which: NDArray[np.int64],
                 colliders: list[ColliderEntry]) -> F64:
    """Penetration depth z (eq. 3.2) of the segment ends ``end[rows]`` in the colliders ``which`` they hit."""
    depth = np.zeros(rows.size)
    for index in np.unique(which):  # loop over the colliders hit, vectorized over particles
        sel = which == index
        entry = colliders[int(index)]
        depth[sel] = entry.collider.query(end[rows[sel]], entry.transform)[0]
    return depth


def _collide(world: World, emitters: list[_Emitter]) -> None:
    """Stop the beam particles that hit a collider this step, report the hits and triggers (eqs. 3.1–3.6).

    The beams of all emitters are swept together (one ray cast and one depth query per collider), then each
    emitter in turn reports its triggers, draws its splashes, gets their repulsion and reports its hits.
    """
    flying = [e for e in emitters if e.beam.size]
    colliders = gather_colliders(world)
    if not flying or not colliders:
        return
    bounds = np.cumsum([0] + [e.beam.size for e in flying])
    start = np.concatenate([e.start for e in flying])
    end = np.concatenate([_take_rows(e.state.particles.position, e.beam) for e in flying])
    owner = np.repeat(np.arange(len(flying)), np.diff(bounds))
    allowed = np.array([hittable(colliders, e.entity, e.cfg.collision_layers) for e in flying])[owner]
    result = sweep(start, end, colliders, allowed)
    hit = np.flatnonzero(result.collider >= 0)
    depth = _penetration(end, hit, result.collider[hit], colliders)
    first = np.searchsorted(hit, bounds)  # flying emitter i's hits: hit[first[i]:first[i + 1]]
    splash = None
    if hit.size:
        start_hit = _take_rows(start, hit)
        point = start_hit + result.t[hit, None] * (_take_rows(end, hit) - start_hit)
        splash = _splash(flying, first, hit - bounds[owner[hit]], point, result.normal[hit], depth)
        acceleration = _accelerations(splash, _repulsions(flying, splash))
    for i, e in enumerate(flying):  # loop over emitters, in entity order: events in a fixed order
        for index, rows, points in result.triggers:
            mine = (rows >= bounds[i]) & (rows < bounds[i + 1])
            incoming = e.state.particles.velocity[e.beam[rows[mine] - bounds[i]]]
            _send_events(world, e.entity, colliders, np.full(len(incoming), index), points[mine],
                         -incoming / max(e.cfg.beam_speed, _EPS), incoming, e.cfg.particle_mass, trigger=True)
        own = slice(int(first[i]), int(first[i + 1]))
        if own.start == own.stop:
            continue
        _land(e.cfg, e.state, splash, acceleration, own)
        rows = hit[own]
        _send_events(world, e.entity, colliders, result.collider[rows], splash.point[own], splash.normal[own],
                     splash.incoming[own], e.cfg.particle_mass)


def _step(world: World, emitters: list[_Emitter], dt: float) -> None:
    """One fixed step of ``emitters``, phase by phase (see the module docstring)."""
    for e in emitters:  # loop over emitters
        _advance(e, dt)
    _collide(world, emitters)
    for e in emitters:  # loop over emitters
        _remove_dead(e.state.particles)
    _emit(emitters, dt)


def step_emitter(world: World, entity: int, transform: Transform, cfg: EnergyWaveEmitter, state: EnergyWaveState,
                 dt: float) -> None:
    """Advance one emitter by one fixed step."""
    _step(world, [_Emitter(entity, transform, cfg, state, world.random.stream("energy_wave", entity))], dt)


def simulate_system(world: World, dt: float) -> None:
    """Simulation stage: step every emitter (ascending entity id), their beams swept together."""
    emitters = [_Emitter(entity, transform, cfg, state, world.random.stream("energy_wave", entity))
                for entity, (transform, cfg, state) in world.query(Transform, EnergyWaveEmitter, EnergyWaveState)]
    _step(world, emitters, dt)


# ------------------------------------------------------------------------------------------------------- queries
def pattern_counts(state: EnergyWaveState) -> dict[str, int]:
    """Live particles per pattern (and 'beam' for those still flying)."""
    live = state.particles.live("pattern")
    counts = np.bincount(live[live >= 0], minlength=len(PATTERNS))
    return {"beam": int(np.sum(live == BEAM)), **{p: int(c) for p, c in zip(PATTERNS, counts)}}


def alpha(state: EnergyWaveState) -> F64:
    """Opacity of each live particle: 1 in the beam, remaining life fraction after the hit (section 3.4)."""
    buf = state.particles
    n = buf.count
    life = np.clip(1.0 - buf.age[:n] / buf.lifetime[:n], 0.0, 1.0)
    return np.where(buf.pattern[:n] == BEAM, 1.0, life)
