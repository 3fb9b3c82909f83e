"""Tables 3 and 4 (primitive counts of methods 1-3) and the level-5 band on the paper's configurations."""

from __future__ import annotations

import numpy as np
import pytest

from systems.grass_field.frame import plan_frame
from systems.grass_field.lod import ImpostorOrientation, band_distance
from tests.systems.grass_field.helpers import level_camera, make_field, paper_config, walkthrough


def _mean_primitives(cfg, data, max_level: int) -> float:
    orientation = ImpostorOrientation(data.cell_count)
    totals = [plan_frame(cfg, data, level_camera(pos, yaw), orientation, max_level=max_level).total_primitives
              for pos, yaw in walkthrough(12)]
    return float(np.mean(totals))


@pytest.mark.parametrize("grid, plants", [(10, 10), (20, 20), (40, 40)])
def test_primitives_fall_from_method_1_to_2_to_3(grid, plants):
    cfg = paper_config(grid_x=grid, grid_z=grid, plants_per_cell=plants)
    _, data = make_field(cfg)
    m1, m2, m3 = (_mean_primitives(cfg, data, level) for level in (3, 4, 5))
    assert m1 > m2 >= m3
    if grid >= 20:
        assert m2 > m3
    if grid == 40:
        assert m1 / m3 > 4.0  # paper, table 4: 611308 / 111039 = 5.5


def test_band_appears_beyond_the_merge_distance():
    cfg = paper_config(grid_x=24, grid_z=24)
    _, data = make_field(cfg)
    cam = level_camera((20.0, 30.0, 10.0), 30.0)
    plan = plan_frame(cfg, data, cam, ImpostorOrientation(data.cell_count))
    viewer = plan.viewer_cell
    dist = band_distance(data.placed.cell_centre[:, [0, 2]], data.placed.cell_centre[viewer, [0, 2]])
    kept = plan.levels >= 0
    assert np.all(plan.levels[kept & (dist >= 800.0)] == 5)
    assert np.all(plan.levels[kept & (dist < 800.0)] <= 4)
    assert plan.band_cell == viewer and 1 <= plan.band_sides.sum() <= 5
    assert plan.primitives[5] == 2 * plan.band_sides.sum()
    # without level 5 (method 2) the same cells are level-4 rectangles
    m2 = plan_frame(cfg, data, cam, ImpostorOrientation(data.cell_count), max_level=4)
    assert m2.band_cell is None and np.all(m2.levels[plan.levels == 5] == 4)


def test_no_band_when_nothing_is_far():
    cfg = paper_config(grid_x=6, grid_z=6)
    _, data = make_field(cfg)
    plan = plan_frame(cfg, data, level_camera((0.0, 30.0, 0.0), 0.0), ImpostorOrientation(data.cell_count))
    assert plan.band_cell is None and plan.primitives[5] == 0 and not (plan.levels == 5).any()


def test_level4_rectangles_follow_the_rules_over_a_walk():
    cfg = paper_config(grid_x=20, grid_z=20)
    _, data = make_field(cfg)
    orientation = ImpostorOrientation(data.cell_count)
    previous = None
    for pos, yaw in walkthrough(20):
        cam = level_camera(pos, yaw)
        plan = plan_frame(cfg, data, cam, orientation, max_level=4)
        rel = data.placed.cell_centre[plan.impostor_cells][:, [0, 2]] - np.asarray(pos)[[0, 2]]
        to_eye = np.arctan2(-rel[:, 1], -rel[:, 0])
        off = np.degrees(np.abs((to_eye - plan.impostor_face + np.pi) % (2 * np.pi) - np.pi))
        assert np.all(off < 15.0 + 1e-9)  # a rectangle never lags the viewer by 15° or more
        image = np.degrees(orientation.image[plan.impostor_cells])
        assert np.allclose(np.mod(image, 30.0) * (np.mod(image, 30.0) < 29.0), 0.0, atol=1e-6)
        err = np.degrees(np.abs((to_eye - np.radians(image) + np.pi) % (2 * np.pi) - np.pi))
        assert np.all(err < 30.0 + 1e-9)
        assert plan.impostor_views.min() >= 0 and plan.impostor_views.max() < 12
        previous = plan
    assert previous is not None and len(previous.impostor_cells) > 10


def _assert_same_plans(a, b) -> None:
    assert np.array_equal(a.levels, b.levels) and a.viewer_cell == b.viewer_cell
    for x, y in zip(a.cells, b.cells, strict=True):
        assert np.array_equal(x, y)
    for x, y in zip(a.plants, b.plants, strict=True):
        assert np.array_equal(x, y)
    assert np.array_equal(a.impostor_cells, b.impostor_cells)
    assert np.array_equal(a.impostor_face, b.impostor_face) and np.array_equal(a.impostor_views, b.impostor_views)
    assert np.array_equal(a.impostor_blend, b.impostor_blend)
    assert a.band_cell == b.band_cell and np.array_equal(a.band_sides, b.band_sides)
    assert a.primitives == b.primitives


@pytest.mark.parametrize("max_level, blend", [(3, False), (4, False), (5, False), (5, True)])
def test_compiled_plan_equals_the_numpy_plan(max_level, blend):
    """The kernels (systems/grass_field/kernels.py) against the numpy functions they replace, over a walk that
    turns and swaps level-4 rectangles, looks up and down, and crosses the field's edge."""
    cfg = paper_config(grid_x=24, grid_z=20, plants_per_cell=12, blend_views=blend)
    _, data = make_field(cfg, height=lambda x, z: 3.0 * np.sin(0.01 * x) * np.cos(0.013 * z))
    compiled, reference = (ImpostorOrientation(data.cell_count) for _ in range(2))
    rng = np.random.default_rng(3)
    for step in range(60):
        pos = (-900.0 + 40.0 * step, 25.0 + 15.0 * np.sin(step), 200.0 * np.sin(0.1 * step))
        cam = level_camera(pos, 7.0 * step + rng.uniform(-20.0, 20.0), pitch_deg=rng.uniform(-30.0, 20.0),
                           fov_x_deg=rng.uniform(40.0, 90.0))
        b = plan_frame(cfg, data, cam, reference, max_level=max_level, compiled=False)
        a = plan_frame(cfg, data, cam, compiled, max_level=max_level)
        assert a.plant_list is not None and b.plant_list is None
        assert np.array_equal(a.plant_list, np.concatenate(b.plants))
        _assert_same_plans(a, b)
        assert np.array_equal(compiled.face, reference.face, equal_nan=True)
        assert np.array_equal(compiled.image, reference.image, equal_nan=True)
    assert (compiled.turns, compiled.swaps) == (reference.turns, reference.swaps)
    if max_level >= 4:
        assert compiled.turns > 0 and compiled.swaps > 0
