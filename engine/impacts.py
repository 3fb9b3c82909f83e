"""Generic physical events shared by effects (the engine names no effect)."""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class Impact:
    """Something hit entity ``target`` at ``point`` with momentum ``impulse`` (N·s, world space).

    Sent by effects that strike things (energy-wave particles); consumed by anything that reacts
    (rigid bodies take the impulse, targets take damage, water makes a wave).
    """

    target: int
    point: tuple[float, float, float]
    impulse: tuple[float, float, float]
    source: int = 0
    kind: str = "generic"
    normal: tuple[float, float, float] = (0.0, 0.0, 0.0)  # surface normal at the hit (unit), when known
    energy: float = 0.0  # kinetic energy delivered (J), when known
    count: int = 1  # how many hits this event aggregates
