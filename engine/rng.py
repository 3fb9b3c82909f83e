"""Seeded random streams: one numpy Generator per (system, entity), derived with SeedSequence.

Keys are hashed with BLAKE2b (never Python's per-process salted ``hash()``), so the stream of one
entity does not depend on which other entities exist or in which order streams were first asked for.
"""

from __future__ import annotations

import hashlib

import numpy as np


def stable_key(text: str) -> int:
    """A 64-bit integer digest of ``text`` that is the same in every process."""
    return int.from_bytes(hashlib.blake2b(text.encode("utf-8"), digest_size=8).digest(), "little")


def derive_generator(seed: int, system: str, entity: int = 0) -> np.random.Generator:
    """A fresh generator for ``(system, entity)`` of the root ``seed``: the one :meth:`RandomStreams.stream` holds.

    Use it directly for randomness that must be reproducible but is not simulation state (a render pass's sample
    table, say): such a generator is not registered anywhere, so it leaves the state hash alone."""
    seq = np.random.SeedSequence(entropy=int(seed), spawn_key=(stable_key(system), int(entity)))
    return np.random.Generator(np.random.PCG64(seq))


class RandomStreams:
    """The random streams of one run, all derived from one root seed."""

    def __init__(self, seed: int) -> None:
        self.seed = int(seed)
        self._streams: dict[tuple[str, int], np.random.Generator] = {}

    def stream(self, system: str, entity: int = 0) -> np.random.Generator:
        """The generator for ``(system, entity)``; created on first use, then persistent."""
        key = (system, int(entity))
        gen = self._streams.get(key)
        if gen is None:
            gen = derive_generator(self.seed, system, entity)
            self._streams[key] = gen
        return gen

    def states(self) -> list[tuple[str, int, dict]]:
        """Every stream's bit-generator state, sorted by key (for hashing)."""
        return [(s, e, self._streams[(s, e)].bit_generator.state) for s, e in sorted(self._streams)]

    def drop(self, entity: int) -> None:
        """Forget the streams of a despawned entity."""
        for key in [k for k in self._streams if k[1] == entity]:
            del self._streams[key]
