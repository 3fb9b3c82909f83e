"""Placement is deterministic: same seed → same state hash; another seed → another field."""

from __future__ import annotations

import numpy as np

from components.grass_field import GrassFieldState
from engine.app import App
from tests.systems.grass_field.helpers import scene_text, write_scene

GRASS = 'preset = "grass_field/paper"\ngrid_x = 4\ngrid_z = 3\nplants_per_cell = 6'


def _app(tmp_path, seed=None):
    return App(write_scene(tmp_path, scene_text(GRASS)), seed=seed)


def test_same_seed_same_hash_and_placement(tmp_path):
    a, b = _app(tmp_path), _app(tmp_path)
    a.step(5)
    b.step(5)
    assert a.state_hash() == b.state_hash()
    sa, sb = (app.world.single(GrassFieldState) for app in (a, b))
    assert np.array_equal(sa.placed.placed.plant_position, sb.placed.placed.plant_position)


def test_different_seed_different_field(tmp_path):
    a, b = _app(tmp_path, seed=1), _app(tmp_path, seed=2)
    a.step(1)
    b.step(1)
    assert a.state_hash() != b.state_hash()
    sa, sb = (app.world.single(GrassFieldState) for app in (a, b))
    assert not np.array_equal(sa.layout_offset, sb.layout_offset)


def test_plants_stand_on_the_terrain_inside_their_cells(tmp_path):
    from engine.builtin import Terrain

    app = _app(tmp_path)
    app.step(1)
    state = app.world.single(GrassFieldState)
    placed = state.placed.placed
    terrain = app.world.single(Terrain)
    pos = placed.plant_position
    assert np.allclose(pos[:, 1], terrain.field.height_at(pos[:, 0], pos[:, 2]))
    cells = np.repeat(np.arange(placed.cell_count), placed.plants_per_cell)
    assert np.array_equal(placed.cell_of(pos[:, [0, 2]]), cells)
    # neighbouring cells are not clones: layouts differ or are turned
    key = state.cell_variant * 4 + state.cell_turn
    assert len(np.unique(key)) > 1


def test_commands_switch_method_and_debug_view(tmp_path):
    app = _app(tmp_path)
    entity = app.world.query(GrassFieldState)[0][0]
    before = app.state_hash()
    app.registry.command("grass_field.set_max_level")(app.world, entity, max_level=3)
    app.registry.command("grass_field.set_debug_levels")(app.world, entity, enabled=True)
    state = app.world.get(entity, GrassFieldState)
    assert state.max_level == 3 and state.debug_levels
    assert app.state_hash() != before
