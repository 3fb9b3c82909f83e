"""Determinism: the same seed gives bit-identical state, another seed (random gusts) a different one, and a
restored snapshot continues exactly."""

from __future__ import annotations

from engine.app import App
from tests.systems.water_surface.helpers import CONFIGS, write_scene

WATER = 'preset = "water_surface/choppy_lake"\nresolution = [40, 40]'
BODIES = """
[[entities]]
name = "crate"
[entities.components.Transform]
position = [1.0, 0.6, -2.0]
rotation = [30.0, 10.0, 5.0]
scale = [1.0, 0.7, 1.2]
[entities.components.RigidBody]
mass = 300.0

[[entities]]
name = "barge"
scripts = [{ name = "water_surface.glide", params = { velocity = [1.0, 0.0, 0.5], distance = 4.0 } }]
[entities.components.Transform]
position = [-3.0, 0.0, 2.0]
scale = [1.5, 0.8, 0.9]
[entities.components.RigidBody]
kinematic = true
"""


def _run(tmp_path, seed: int, steps: int = 90) -> App:
    app = App(write_scene(tmp_path, WATER, BODIES, seed=seed), configs_root=CONFIGS)
    app.step(steps)
    return app


def test_same_seed_same_hash_other_seed_other_hash(tmp_path):
    a, b, c = _run(tmp_path, 5), _run(tmp_path, 5), _run(tmp_path, 6)
    assert a.state_hash() == b.state_hash()
    assert a.state_hash() != c.state_hash()


def test_a_restored_snapshot_continues_identically(tmp_path):
    app = _run(tmp_path, 5, steps=30)
    snap = app.snapshot()
    app.step(40)
    first = app.state_hash()
    app.restore(snap)
    app.step(40)
    assert app.state_hash() == first
