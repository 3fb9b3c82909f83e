"""Eq. 1 and table 2 (level selection), the level-4 turn / swap rules and the level-5 band metric."""

from __future__ import annotations

import numpy as np
import pytest

from systems.grass_field.lod import (CameraInput, ImpostorOrientation, band_distance, level_from_pixels,
                                     pseudo_pixels, select_levels, switch_distances, view_angles,
                                     visible_band_sides)
from tests.systems.grass_field.helpers import level_camera

TABLE2 = (4.0, 1.5, 1.0, 0.75)


def test_eq1_pseudo_pixels():
    # P = W L / (2 D tan θ): 640 px wide, 2θ = 60°, L = 0.5 at D = 100
    p = pseudo_pixels(100.0, 640, 0.5, np.tan(np.radians(30.0)))
    assert p == pytest.approx(640 * 0.5 / (2 * 100.0 * np.tan(np.radians(30.0))))
    assert p == pytest.approx(2.7713, abs=1e-4)
    # inversely proportional to D, proportional to W and L
    assert pseudo_pixels(200.0, 640, 0.5, 0.577) == pytest.approx(pseudo_pixels(100.0, 640, 0.5, 0.577) / 2)
    assert pseudo_pixels(100.0, 1280, 0.5, 0.577) == pytest.approx(2 * pseudo_pixels(100.0, 640, 0.5, 0.577))


def test_table2_thresholds_without_hysteresis():
    p = np.array([10.0, 4.0, 3.999, 1.5, 1.499, 1.0, 0.999, 0.75, 0.749, 0.01])
    assert level_from_pixels(p, TABLE2).tolist() == [0, 0, 1, 1, 2, 2, 3, 3, 4, 4]
    # hysteresis-free: sweeping P down then up gives the same level for the same P
    sweep = np.linspace(6.0, 0.2, 400)
    down = level_from_pixels(sweep, TABLE2)
    up = level_from_pixels(sweep[::-1], TABLE2)[::-1]
    assert np.array_equal(down, up)
    assert np.all(np.diff(down) >= 0)  # never back to a finer level while P falls


def test_switch_distances_solve_eq1():
    tan = np.tan(np.radians(30.0))
    d = switch_distances(640, 0.5, tan, TABLE2)
    assert np.allclose(pseudo_pixels(d, 640, 0.5, tan), TABLE2)
    assert np.allclose(d, [69.28, 184.75, 277.13, 369.50], atol=0.01)


def test_levels_along_a_line_of_cells():
    cam = level_camera((0.0, 0.0, 0.0), 0.0, width=640, fov_x_deg=60.0)
    d = switch_distances(640, 0.5, cam.tan_half_fov, TABLE2)
    distances = np.array([10.0, d[0] - 1, d[0] + 1, d[1] - 1, d[1] + 1, d[2] - 1, d[2] + 1, d[3] - 1, d[3] + 1,
                          600.0, 900.0, 1500.0])
    centres = np.column_stack([distances, np.zeros_like(distances), np.zeros_like(distances)])
    levels = select_levels(centres, cam, length=0.5, thresholds=TABLE2, max_level=5, merge_distance=800.0,
                           viewer_cell_centre=np.zeros(3))
    assert levels.tolist() == [0, 0, 1, 1, 2, 2, 3, 3, 4, 4, 5, 5]
    # the paper's methods: method 1 stops at level 3, method 2 at level 4
    m1 = select_levels(centres, cam, length=0.5, thresholds=TABLE2, max_level=3, merge_distance=800.0,
                       viewer_cell_centre=np.zeros(3))
    m2 = select_levels(centres, cam, length=0.5, thresholds=TABLE2, max_level=4, merge_distance=800.0,
                       viewer_cell_centre=np.zeros(3))
    assert m1.tolist() == [0, 0, 1, 1, 2, 2, 3, 3, 3, 3, 3, 3]
    assert m2.tolist() == [0, 0, 1, 1, 2, 2, 3, 3, 4, 4, 4, 4]


def test_level_follows_the_viewport_width():
    centres = np.array([[100.0, 0.0, 0.0]])
    kw = dict(length=0.5, thresholds=TABLE2, max_level=4, merge_distance=800.0)
    narrow = level_camera((0.0, 0.0, 0.0), 0.0, width=640)  # P = 2.77
    wide = level_camera((0.0, 0.0, 0.0), 0.0, width=1280)  # P = 5.54
    assert select_levels(centres, narrow, **kw)[0] == 1
    assert select_levels(centres, wide, **kw)[0] == 0


def test_band_metric_is_the_12_gon():
    r = 800.0
    side = np.radians(np.arange(12) * 30.0)
    corner = side + np.radians(15.0)
    on_sides = np.column_stack([r * np.cos(side), r * np.sin(side)])
    on_corners = np.column_stack([r / np.cos(np.radians(15.0)) * np.cos(corner),
                                  r / np.cos(np.radians(15.0)) * np.sin(corner)])
    assert np.allclose(band_distance(on_sides, [0.0, 0.0]), r)
    assert np.allclose(band_distance(on_corners, [0.0, 0.0]), r)
    assert np.allclose(band_distance(on_sides + [5.0, 7.0], [5.0, 7.0]), r)


def test_band_sides_behind_the_camera_are_not_drawn():
    cam = level_camera((0.0, 20.0, 0.0), 0.0, fov_x_deg=60.0)  # looks along +x (side 0)
    sides = visible_band_sides(cam, np.zeros(2), 800.0)
    assert sides[0] and sides[1] and sides[11]
    assert not sides[[4, 5, 6, 7, 8]].any()
    assert 2 <= sides.sum() <= 5


def test_twelve_views_every_30_degrees():
    a = view_angles()
    assert len(a) == 12
    assert np.allclose(np.diff(np.degrees(a)), 30.0)


def test_rectangle_turns_after_15_and_image_switches_after_30_degrees():
    o = ImpostorOrientation(1)
    on = np.array([True])
    deg = np.radians
    o.update(np.array([deg(10.0)]), on, deg(15.0), deg(30.0))
    assert np.degrees(o.face[0]) == pytest.approx(10.0) and np.degrees(o.image[0]) == pytest.approx(0.0)
    o.update(np.array([deg(24.9)]), on, deg(15.0), deg(30.0))  # 14.9° from the face: no turn
    assert np.degrees(o.face[0]) == pytest.approx(10.0)
    o.update(np.array([deg(25.0)]), on, deg(15.0), deg(30.0))  # 15°: turns to face the viewer
    assert np.degrees(o.face[0]) == pytest.approx(25.0)
    assert np.degrees(o.image[0]) == pytest.approx(0.0)  # 25° from the image: kept
    o.update(np.array([deg(29.9)]), on, deg(15.0), deg(30.0))
    assert np.degrees(o.image[0]) == pytest.approx(0.0)
    o.update(np.array([deg(30.0)]), on, deg(15.0), deg(30.0))  # 30° from the image: nearest of the 12
    assert np.degrees(o.image[0]) == pytest.approx(30.0)
    o.update(np.array([deg(-20.0)]), on, deg(15.0), deg(30.0))  # wraps around 0°
    assert np.degrees(o.image[0]) == pytest.approx(330.0)
    assert o.turns >= 2 and o.swaps == 2
    o.update(np.array([deg(0.0)]), np.array([False]), deg(15.0), deg(30.0))  # leaves level 4: forgotten
    assert np.isnan(o.face[0])


def test_local_view_undoes_the_cells_quarter_turn():
    o = ImpostorOrientation(3)
    o.update(np.radians([90.0, 90.0, 0.0]), np.ones(3, bool), np.radians(15.0), np.radians(30.0))
    assert o.local_view(np.array([0, 1, 1])).tolist() == [3, 0, 9]


def test_orthographic_camera_has_one_level():
    cam = CameraInput(np.zeros(3), [0.0, -1.0, 0.0], np.pi / 2, 200, ortho_pixels_per_unit=4.0)
    centres = np.array([[0.0, 0.0, 0.0], [500.0, 0.0, 0.0]])
    levels = select_levels(centres, cam, length=0.5, thresholds=TABLE2, max_level=4, merge_distance=800.0)
    assert levels.tolist() == [1, 1]  # P = 0.5 * 4 = 2: level 1 at any distance
