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


def test_the_kernels_run_as_plain_python_give_the_same_bits():
    """``NUMBA_DISABLE_JIT=1`` (for a debugger) runs every kernel as Python: the showcase's state hash must not
    move. It moved after 30 ticks while the outline's edge lengths used ``math.hypot`` (CPython's own algorithm;
    compiled, C's hypot)."""
    import os
    import subprocess
    import sys

    scene = CONFIGS / "scenes" / "water_surface_showcase.toml"
    cmd = [sys.executable, "-m", "engine", "run", str(scene), "--no-render", "--steps", "30", "--seed", "3", "--hash"]
    env = {**os.environ, "NUMBA_DISABLE_JIT": "1"}
    out = subprocess.run(cmd, capture_output=True, text=True, check=True, env=env, cwd=CONFIGS.parent)
    app = App(scene, seed=3)
    app.step(30)
    assert out.stdout.strip().splitlines()[-1] == app.state_hash()
