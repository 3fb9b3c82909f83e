"""Render extraction for the energy wave: one 12-float record per particle, no GL (so it is benchmarked and tested
headless).

Each record is three RGBA texels: (position, alpha), (hit point P0, unused), (unit travel direction d, unused).
Records are grouped by how the GPU expands them (section 3.4): single sprites (beam particles and grains),
continuous trails of M sprites (eq. 3.7) and bars of N sprites (eqs. 3.8, 3.9). The vertex shader expands each
record into its sprites from ``gl_VertexID`` (no instancing), so the CPU work here is O(particles) whatever M and
N are.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from components.energy_wave import BEAM, EnergyWaveEmitter, EnergyWaveState
from engine.spatial import Transform
from engine.world import World

from .simulate import alpha

RECORD_FLOATS = 12
SINGLE, TRAIL, BAR = 0, 1, 2
_UP = np.array([0.0, 1.0, 0.0], np.float32)


@dataclass
class EmitterDraw:
    """One emitter's share of the frame: its records' place in the shared array and its drawing parameters."""

    first: int  # index of the emitter's first record in the frame's record array
    counts: tuple[int, int, int]  # records of the single, trail and bar groups, stored in that order
    config: EnergyWaveEmitter

    @property
    def total(self) -> int:
        return sum(self.counts)

    def sprites(self) -> int:
        """Sprites (textures) this emitter draws: singles + M per trail + N per bar."""
        single, trail, bar = self.counts
        return single + trail * self.config.trail_textures + bar * self.config.splash_samples


@dataclass
class FrameData:
    records: np.ndarray  # (n, RECORD_FLOATS) float32
    emitters: list[EmitterDraw]

    def sprites(self) -> int:
        return sum(e.sprites() for e in self.emitters)


def _directions(velocity: np.ndarray, acceleration: np.ndarray, offset: np.ndarray) -> np.ndarray:
    """Unit travel direction d: the velocity, else the acceleration (a circular particle at its hit), else the
    offset from the hit point, else +y."""
    d = velocity.copy()
    for fallback in (acceleration, offset):
        still = np.einsum("ij,ij->i", d, d) < 1e-20
        d[still] = fallback[still]
    length = np.sqrt(np.einsum("ij,ij->i", d, d))
    ok = length > 1e-10
    d[ok] /= length[ok, None]
    d[~ok] = _UP
    return d


def pack_emitter(cfg: EnergyWaveEmitter, state: EnergyWaveState) -> tuple[np.ndarray, tuple[int, int, int]]:
    """Records of one emitter's live particles, grouped single | trail | bar, and the group sizes."""
    buf = state.particles
    n = buf.count
    pattern = buf.pattern[:n]
    kind = pattern // 2  # rendering kind of hit particles: 0 continuous, 1 grain, 2 round bar, 3 sharp bar
    bar = SINGLE if cfg.splash_samples == 1 else BAR  # N = 1: bars degenerate to grains
    group = np.select([pattern == BEAM, kind == 0, kind == 1], [SINGLE, TRAIL, SINGLE], bar)
    members = [np.flatnonzero(group == g) for g in (SINGLE, TRAIL, BAR)]
    order = np.concatenate(members)
    counts = tuple(len(m) for m in members)
    rec = np.empty((n, RECORD_FLOATS), np.float32)
    position = buf.position[:n]
    rec[:, 0:3] = position
    rec[:, 3] = alpha(state)
    rec[:, 4:7] = buf.hit_point[:n]
    rec[:, 7] = 0.0
    rec[:, 8:11] = _directions(buf.velocity[:n], buf.acceleration[:n], position - buf.hit_point[:n])
    rec[:, 11] = 0.0
    return rec[order], counts  # type: ignore[return-value]


def extract_frame(world: World) -> FrameData:
    """All emitters' records in one array (ascending entity id) with each emitter's draw parameters."""
    parts, emitters, first = [], [], 0
    for _, (_, cfg, state) in world.query(Transform, EnergyWaveEmitter, EnergyWaveState):
        records, counts = pack_emitter(cfg, state)
        if len(records) == 0:
            continue
        parts.append(records)
        emitters.append(EmitterDraw(first, counts, cfg))
        first += len(records)
    records = np.concatenate(parts) if parts else np.zeros((0, RECORD_FLOATS), np.float32)
    return FrameData(records, emitters)
