"""The compiled particle step and emission (systems/dust_devil/kernels.py) give the numpy step's bits
(seeds/004)."""

import numpy as np
import pytest

from engine.app import App
from engine.spatial import quat_from_euler
from systems.dust_devil import simulate
from tests.systems.dust_devil.helpers import devil, scene_text

CASES = {
    "paper (nearest, midpoint)": dict(),
    "trilinear": dict(lookup="trilinear"),
    "euler, 3 substeps": dict(integrator="euler", substeps=3),
    "no terrain": dict(terrain=False),
    "terrain interaction off": dict(terrain_interaction=False),
    "odd grid, strong wind": dict(grid_resolution=[12, 20, 9], wind_scale=2.5, emission_radius=3.0),
    "emission clamped into the box": dict(emission_radius=20.0, emission_height=40.0, particle_lifetime=0.5),
}


def _run(tmp_path, use_kernels: bool, monkeypatch, steps: int = 90, drag_at: int = 40, ground_offset=None,
         **options):
    monkeypatch.setattr(simulate, "USE_KERNELS", use_kernels)
    options = dict(dict(particle_count=700, prewarm_time=0.5, grid_resolution=[16, 16, 16], amplitude=8.0),
                   **options)
    text = scene_text(**options)
    if ground_offset is not None:  # the terrain entity placed off the origin (a Ground with a translation)
        text = text.replace("position = [0.0, 0.0, 0.0]", f"position = {list(ground_offset)}", 1)
    path = tmp_path / f"scene_{int(use_kernels)}.toml"
    path.write_text(text, encoding="utf-8")
    app = App(path, strict=True)
    app.step(drag_at)
    entity, t, _, state = devil(app)
    app.registry.command("dust_devil.drag")(app.world, entity, delta=[2.5, 0.0, -1.75])  # field box moves
    app.step(steps - drag_at)
    return state, app.state_hash()


@pytest.mark.parametrize("case", list(CASES))
def test_kernel_step_equals_numpy_step_bit_for_bit(tmp_path, monkeypatch, case):
    ref, ref_hash = _run(tmp_path, False, monkeypatch, **CASES[case])
    out, out_hash = _run(tmp_path, True, monkeypatch, **CASES[case])
    assert np.array_equal(out.positions, ref.positions)
    assert np.array_equal(out.ages, ref.ages) and np.array_equal(out.lifetimes, ref.lifetimes)
    assert out.wind.evaluated == ref.wind.evaluated  # the same lazy grid points
    assert np.array_equal(out.wind._known, ref.wind._known)
    known = ref.wind._known
    assert np.array_equal(out.wind._flat[known], ref.wind._flat[known])
    assert out_hash == ref_hash


def test_kernel_step_with_a_translated_terrain(tmp_path, monkeypatch):
    ref, _ = _run(tmp_path, False, monkeypatch, ground_offset=(3.0, -1.5, 2.0))
    out, _ = _run(tmp_path, True, monkeypatch, ground_offset=(3.0, -1.5, 2.0))
    assert np.array_equal(out.positions, ref.positions)


def test_kernel_case_only_for_unrotated_unscaled_boxes(tmp_path, monkeypatch):
    from engine.spatial import Transform

    assert simulate._kernel_case(Transform(), None)
    assert not simulate._kernel_case(Transform(rotation=quat_from_euler(0.5, 0.0, 0.0)), None)
    assert not simulate._kernel_case(Transform(scale=np.array([1.0, 2.0, 1.0])), None)
    calls = []
    from systems.dust_devil import kernels

    original = kernels.advance_particles
    monkeypatch.setattr(kernels, "advance_particles", lambda *a: calls.append(1) or original(*a))
    state, _ = _run(tmp_path, True, monkeypatch, steps=3, drag_at=1, particle_count=50, prewarm_time=0.0)
    assert len(calls) == 3  # the bench's and the presets' case takes the kernel


def test_emission_takes_the_kernel_and_reuses_the_wind_grid(tmp_path, monkeypatch):
    """Re-emission runs kernels.emit_particles (two passes per emission: feet, then places), and the wind field
    object and its arrays are kept from step to step (reset, not reallocated)."""
    from systems.dust_devil import kernels

    calls = []
    original = kernels.emit_particles
    monkeypatch.setattr(kernels, "emit_particles", lambda *a: calls.append(a[13]) or original(*a))
    path = tmp_path / "scene.toml"
    path.write_text(scene_text(particle_count=50, prewarm_time=0.0, particle_lifetime=0.05), encoding="utf-8")
    app = App(path, strict=True)
    app.step(1)
    _, _, _, state = devil(app)
    wind, flat = state.wind, state.wind._flat
    first = len(calls)
    assert first >= 2 and calls[:2] == [False, True]  # the first emission (and re-emissions within the step)
    app.step(3)
    assert len(calls) > first and calls == [False, True] * (len(calls) // 2)  # re-emissions: pairs of passes
    assert state.wind is wind and state.wind._flat is flat and state.wind._known.any()
    assert state.wind.evaluated == state.wind._known.sum()  # counted from zero at this step's reset
