"""Each effect's simulated data is in the state hash, and its random draws follow the seed.

The determinism tests compare hashes; they can only fail if the hash sees the data.  Here one bit of one live value
of each effect's state is changed and the hash must change; and two seeds must simulate different data (not only
hash differently: the hash also covers the seed itself)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from components.dust_devil import DustDevilState
from components.energy_wave import EnergyWaveState
from components.toon_smoke import ToonSmokeState
from components.water_surface import RigidBodyState, WaterState
from engine.app import App

SCENES = Path(__file__).resolve().parents[2] / "configs" / "scenes"

CASES = {  # name: (scene, state type, live value, steps, seeded)
    "energy_wave particles": ("energy_wave_showcase", EnergyWaveState,
                              lambda s: s.particles.position[: s.particles.count], 20, True),
    "water heights": ("water_surface_showcase", WaterState, lambda s: s.heights, 10, False),
    "water previous heights": ("water_surface_showcase", WaterState, lambda s: s.previous, 10, False),
    "rigid body velocity": ("water_surface_showcase", RigidBodyState, lambda s: s.velocity, 10, False),
    "toon smoke density": ("toon_smoke_showcase", ToonSmokeState, lambda s: s.density, 10, False),
    "toon smoke particles": ("toon_smoke_showcase", ToonSmokeState, lambda s: s.particles, 10, True),
    "dust devil positions": ("dust_devil_showcase", DustDevilState, lambda s: s.positions, 5, True),
    "dust devil ages": ("dust_devil_showcase", DustDevilState, lambda s: s.ages, 5, False),
}


def _live(app: App, state_type, value) -> np.ndarray:
    (_, (state,)), *_ = app.world.query(state_type)
    return value(state)


@pytest.mark.parametrize("case", CASES, ids=list(CASES))
def test_one_bit_of_the_effects_state_changes_the_hash(case):
    scene, state_type, value, steps, _ = CASES[case]
    app = App(SCENES / f"{scene}.toml", seed=1)
    app.step(steps)
    live = _live(app, state_type, value)
    nonzero = np.flatnonzero(live)
    assert nonzero.size, f"{case}: nothing alive after {steps} steps to change"
    before = app.state_hash()
    flat = live.reshape(-1)  # a view: the state's own array
    flat[nonzero[-1]] = np.nextafter(flat[nonzero[-1]], np.inf)
    assert app.state_hash() != before


@pytest.mark.parametrize("case", [c for c in CASES if CASES[c][4]], ids=[c for c in CASES if CASES[c][4]])
def test_two_seeds_simulate_different_data(case):
    scene, state_type, value, steps, _ = CASES[case]
    runs = []
    for seed in (1, 2):
        app = App(SCENES / f"{scene}.toml", seed=seed)
        app.step(steps)
        runs.append(_live(app, state_type, value).copy())
    assert runs[0].shape != runs[1].shape or not np.array_equal(*runs)
