"""Per-cell frustum culling with the paper's rule (section 3)."""

from __future__ import annotations

import numpy as np

from systems.grass_field.culling import cull_cells, frustum_planes
from systems.grass_field.frame import plan_frame
from systems.grass_field.lod import CameraInput, ImpostorOrientation, select_levels
from tests.systems.grass_field.helpers import level_camera, make_field, paper_config


def _cells(angles_deg, distance):
    a = np.radians(np.asarray(angles_deg, float))
    return np.column_stack([distance * np.cos(a), np.zeros_like(a), distance * np.sin(a)])


def test_cells_behind_are_dropped_and_ahead_kept():
    cam = level_camera((0.0, 10.0, 0.0), 0.0, fov_x_deg=60.0)
    centres = _cells([0, 20, 29, 90, 135, 180, 225, 270], 1000.0)
    keep = cull_cells(centres, cam, cell_radius=1.0, near_distance=150.0)
    assert keep.tolist() == [True, True, True, False, False, False, False, False]


def test_near_cells_kept_up_to_twice_the_view_angle():
    cam = level_camera((0.0, 10.0, 0.0), 0.0, fov_x_deg=60.0)  # θ = 30°
    angles = [45, 59, 61, -45, -59]
    near = cull_cells(_cells(angles, 100.0), cam, cell_radius=1.0, near_distance=150.0)
    far = cull_cells(_cells(angles, 1000.0), cam, cell_radius=1.0, near_distance=150.0)
    assert near.tolist() == [True, True, False, True, True]
    assert not far.any()


def test_viewer_cell_is_never_culled():
    cam = level_camera((0.0, 10.0, 0.0), 0.0)
    centres = _cells([180.0], 40.0)  # the cell's centre is behind the viewer
    assert not cull_cells(centres, cam, cell_radius=1.0, near_distance=0.0)[0]
    assert cull_cells(centres, cam, cell_radius=1.0, near_distance=0.0, viewer_cell=0)[0]


def test_cell_straddling_the_frustum_edge_is_kept():
    cam = level_camera((0.0, 10.0, 0.0), 0.0, fov_x_deg=60.0)
    centres = _cells([34.0], 1000.0)  # centre 4° outside; the cell's angular radius is 5.7°
    assert cull_cells(centres, cam, cell_radius=100.0, near_distance=150.0)[0]
    assert not cull_cells(centres, cam, cell_radius=10.0, near_distance=150.0)[0]


def test_grid_culling_on_the_papers_field():
    cfg = paper_config(grid_x=40, grid_z=40)
    _, data = make_field(cfg)
    cam = level_camera((30.0, 30.0, -20.0), 45.0, fov_x_deg=60.0)
    plan = plan_frame(cfg, data, cam, ImpostorOrientation(data.cell_count))
    viewer = data.placed.cell_of(np.array([30.0, -20.0]))
    assert plan.levels[viewer] >= 0
    rel = data.placed.cell_centre[:, [0, 2]] - [30.0, -20.0]
    ang = np.degrees(np.arctan2(rel[:, 1], rel[:, 0]))
    behind = (np.abs((ang - 45.0 + 180.0) % 360.0 - 180.0) > 120.0) & (np.linalg.norm(rel, axis=1) > 300)
    assert behind.sum() > 100 and (plan.levels[behind] == -1).all()
    assert 0.1 < (plan.levels >= 0).mean() < 0.4


def _plant_vertices(data, plant: int, level: int) -> np.ndarray:
    """World positions of one plant's level mesh (as shaders/plant.vert places them)."""
    placed = data.placed
    local = data.meshes[level].vertices[placed.plant_variant[plant], :, :3].astype(np.float64)
    local = local * placed.plant_scale[plant]
    c, s = np.cos(placed.plant_yaw[plant]), np.sin(placed.plant_yaw[plant])
    x, z = local[:, 0] * c - local[:, 2] * s, local[:, 0] * s + local[:, 2] * c
    return np.column_stack([x, local[:, 1], z]) + placed.plant_position[plant]


def test_plants_wholly_outside_the_frustum_are_not_drawn():
    cfg = paper_config(grid_x=12, grid_z=12, plants_per_cell=20)
    _, data = make_field(cfg)
    cam = level_camera((30.0, 30.0, -20.0), 45.0, fov_x_deg=60.0, pitch_deg=-8.0)
    plan = plan_frame(cfg, data, cam, ImpostorOrientation(data.cell_count), max_level=3)
    planes = frustum_planes(cam)
    n = cfg.plants_per_cell
    dropped_near = 0
    for level in range(4):
        listed = (plan.cells[level][:, None] * n + np.arange(n)).reshape(-1)
        drawn = plan.plants[level]
        assert len(np.unique(drawn)) == len(drawn) and np.isin(drawn, listed).all()
        for plant in np.setdiff1d(listed, drawn):  # each dropped plant lies wholly behind one frustum side
            distance = _plant_vertices(data, plant, level) @ planes[:, :3].T + planes[:, 3]
            assert (distance < 0.0).all(axis=0).any()
        if level <= 1:
            dropped_near += len(listed) - len(drawn)
    assert dropped_near > 0  # the near cells kept up to twice the view angle are partly off screen
    assert plan.primitives[3] == int(data.meshes[3].real_primitives[data.placed.plant_variant[plan.plants[3]]].sum())


def test_orthographic_views_draw_every_plant_of_the_kept_cells():
    cfg = paper_config(grid_x=6, grid_z=6, plants_per_cell=5)
    _, data = make_field(cfg)
    cam = CameraInput(np.array([0.0, 500.0, 0.0]), np.array([0.0, -1.0, 0.0]), np.pi / 2, 256,
                      up=np.array([0.0, 0.0, 1.0]), ortho_pixels_per_unit=0.5)
    plan = plan_frame(cfg, data, cam, ImpostorOrientation(data.cell_count))
    assert frustum_planes(cam) is None
    for cells, plants in zip(plan.cells, plan.plants):
        assert len(plants) == len(cells) * cfg.plants_per_cell


def test_cells_over_a_bare_area_are_never_drawn():
    """``bare_areas`` (a pond, a road): every cell overlapping a rectangle is culled at every level, in the compiled
    and the numpy plan alike, the viewer's own cell included, and the band leaves those cells out."""
    from systems.grass_field.frame import band_sector_content

    area = (-120.0, -60.0, 90.0, 140.0)
    cfg = paper_config(grid_x=40, grid_z=40, bare_areas=[list(area)])
    _, data = make_field(cfg)
    x, z = data.placed.cell_centre[:, 0], data.placed.cell_centre[:, 2]
    half = 0.5 * cfg.cell_size
    overlap = (x + half > area[0]) & (x - half < area[2]) & (z + half > area[1]) & (z - half < area[3])
    assert np.array_equal(data.bare, overlap) and 4 <= overlap.sum() < 20
    plain = make_field(paper_config(grid_x=40, grid_z=40))[1]
    for position, yaw in [((0.0, 30.0, 40.0), 20.0), ((-900.0, 30.0, 0.0), 0.0), ((300.0, 40.0, -500.0), 120.0)]:
        cam = level_camera(position, yaw, pitch_deg=-10.0)
        for compiled in (True, False):
            plan = plan_frame(cfg, data, cam, ImpostorOrientation(data.cell_count), compiled=compiled)
            reference = plan_frame(cfg, plain, cam, ImpostorOrientation(plain.cell_count), compiled=compiled)
            assert (plan.levels[overlap] == -1).all()
            assert np.array_equal(plan.levels[~overlap], reference.levels[~overlap])
            assert (reference.levels[overlap] >= 0).any() or position[0] < -500.0  # the area was in view
            for cells in plan.cells:
                assert not overlap[cells].any()
            assert not overlap[plan.impostor_cells].any()
    far_from = int(data.placed.cell_of(np.array([-900.0, 0.0])))
    content, plain_content = (band_sector_content(d, far_from, cfg.merge_distance) for d in (data, plain))
    assert (content <= plain_content).all()


def test_bare_areas_must_be_ordered():
    import pytest
    from pydantic import ValidationError

    with pytest.raises(ValidationError, match=r"bare_areas\[1\].*x_min < x_max"):
        paper_config(bare_areas=[[0.0, 0.0, 1.0, 1.0], [5.0, 0.0, 2.0, 1.0]])


def test_the_band_replaces_only_cells_eq1_puts_at_level_4_in_wide_views():
    """Section 6: the merged band stands beyond the 3→4 distance.  At 640 px that distance (369) is well inside
    the paper's merge distance (800); at 1920 and 3840 px (1108, 2215) it is not, and the band moves out with it
    instead of swallowing cells that eq. 1 wants drawn as geometry (36 and 225 such cells before).  Compiled and
    numpy plans alike."""
    from systems.grass_field.frame import band_apothem

    cfg = paper_config(grid_x=40, grid_z=40)
    _, data = make_field(cfg)
    for width, expect_moved in [(640, False), (1920, True), (3840, True)]:
        for position, yaw in [((0.0, 30.0, 0.0), 20.0), ((-700.0, 30.0, -600.0), 45.0)]:
            cam = level_camera(position, yaw, width=width)
            apothem = band_apothem(cfg, data, cam)
            assert (apothem > cfg.merge_distance) == expect_moved
            for compiled in (True, False):
                plan = plan_frame(cfg, data, cam, ImpostorOrientation(data.cell_count), compiled=compiled)
                plain = plan_frame(cfg, data, cam, ImpostorOrientation(data.cell_count), max_level=4,
                                   compiled=compiled)
                banded = plan.levels == 5
                assert plan.band_apothem == apothem
                assert (plain.levels[banded] == 4).all()  # never a cell eq. 1 puts at levels 0-3
                assert np.array_equal(plan.levels[~banded], plain.levels[~banded])
                if width == 1920 and position[0] == -700.0:
                    assert banded.any() and (plan.levels == 4).any()  # both still in use
