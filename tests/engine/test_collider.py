"""Tests for engine.collider: signed distances, penetration queries and ray casts per shape."""

import numpy as np
import pytest

from engine.collider import Collider
from engine.heightfield import HeightField
from engine.spatial import Transform, quat_from_axis_angle, quat_from_euler

SQRT2 = np.sqrt(2.0)


def _tilted_field(slope_x=0.5, slope_z=0.25, base=1.0):
    """Height field sampling the plane h = base + slope_x·x + slope_z·z on [-4, 4]²."""
    xs = np.linspace(-4.0, 4.0, 17)
    heights = base + slope_x * xs[None, :] + slope_z * xs[:, None]
    return HeightField(heights=heights, spacing=0.5, origin=np.array([-4.0, -4.0]))


def test_box_signed_distance_and_normals_axis_aligned():
    box = Collider(shape="box", half_extents=[1.0, 2.0, 3.0])
    t = Transform(position=[10.0, 0.0, 0.0])
    points = np.array([
        [12.0, 0.0, 0.0],   # 1 outside +x face
        [10.0, -2.5, 0.0],  # 0.5 outside -y face
        [10.5, 0.0, 0.0],   # inside, nearest +x face at 0.5
        [10.0, 0.0, -2.9],  # inside, nearest -z face at 0.1
        [12.0, 3.0, 0.0],   # outside the +x+y edge: distance sqrt(2)
        [10.0, 0.0, 0.0],   # centre: nearest face x at 1
    ])
    d = box.signed_distance(points, t)
    np.testing.assert_allclose(d, [1.0, 0.5, -0.5, -0.1, SQRT2, -1.0], atol=1e-12)
    depth, normal = box.query(points, t)
    np.testing.assert_allclose(depth, [0.0, 0.0, 0.5, 0.1, 0.0, 1.0], atol=1e-12)
    expected = [[1, 0, 0], [0, -1, 0], [1, 0, 0], [0, 0, -1], [1 / SQRT2, 1 / SQRT2, 0], [1, 0, 0]]
    np.testing.assert_allclose(normal, expected, atol=1e-12)


def test_rotated_and_scaled_box():
    box = Collider(shape="box", half_extents=[1.0, 1.0, 1.0])
    t = Transform(position=[0.0, 1.0, 0.0], rotation=quat_from_axis_angle([0, 1, 0], np.pi / 4))
    points = np.array([[1.5, 1.0, 0.0], [0.0, 1.0, 1.6], [0.3, 1.0, 0.3]])
    d = box.signed_distance(points, t)
    # The vertical edges of the rotated unit cube lie at distance sqrt(2) on the x and z axes.
    np.testing.assert_allclose(d[:2], [1.5 - SQRT2, 1.6 - SQRT2], atol=1e-12)
    # (0.3, 0.3) is along a face normal of the rotated cube, 0.3·sqrt(2) from the centre.
    np.testing.assert_allclose(d[2], 0.3 * SQRT2 - 1.0, atol=1e-12)
    depth, normal = box.query(points, t)
    np.testing.assert_allclose(normal, [[1, 0, 0], [0, 0, 1], [1 / SQRT2, 0, 1 / SQRT2]], atol=1e-12)
    np.testing.assert_allclose(depth, [0.0, 0.0, 1.0 - 0.3 * SQRT2], atol=1e-12)
    stretched = Transform(scale=[2.0, 1.0, -1.0])  # per-axis, sign ignored
    np.testing.assert_allclose(box.signed_distance([[2.5, 0, 0], [0, 0, 1.5], [0, 1.5, 0]], stretched),
                               [0.5, 0.5, 0.5], atol=1e-12)


def test_sphere_distance_normal_and_max_scale():
    sphere = Collider(shape="sphere", radius=1.0)
    t = Transform(position=[0.0, 1.0, 0.0], scale=[1.0, 3.0, 2.0])  # radius × 3
    points = np.array([[0.0, 5.0, 0.0], [1.0, 1.0, 0.0], [0.0, 1.0, -4.0], [0.0, 1.0, 0.0]])
    np.testing.assert_allclose(sphere.signed_distance(points, t), [1.0, -2.0, 1.0, -3.0], atol=1e-12)
    depth, normal = sphere.query(points, t)
    np.testing.assert_allclose(depth, [0.0, 2.0, 0.0, 3.0], atol=1e-12)
    np.testing.assert_allclose(normal, [[0, 1, 0], [1, 0, 0], [0, 0, -1], [0, 1, 0]], atol=1e-12)


def test_plane_default_up_rotated_and_offset():
    plane = Collider(shape="plane")
    depth, normal = plane.query(np.array([[3.0, -0.25, 7.0], [0.0, 2.0, 0.0]]), Transform(position=[0, 0, 0]))
    np.testing.assert_allclose(depth, [0.25, 0.0])
    np.testing.assert_allclose(normal, [[0, 1, 0], [0, 1, 0]])
    # A plane tilted 90° about z faces -x; offset shifts it along its own normal.
    tilted = Collider(shape="plane", normal=[0.0, 2.0, 0.0], offset=0.5)
    t = Transform(position=[1.0, 0.0, 0.0], rotation=quat_from_axis_angle([0, 0, 1], np.pi / 2))
    d = tilted.signed_distance(np.array([[-2.0, 5.0, 1.0], [1.0, 0.0, 0.0]]), t)
    np.testing.assert_allclose(d, [2.5, -0.5], atol=1e-12)
    np.testing.assert_allclose(tilted.query(np.array([[0.0, 0.0, 0.0]]), t)[1], [[-1, 0, 0]], atol=1e-12)


def test_heightfield_depth_and_normal_on_tilted_plane():
    collider = Collider(shape="heightfield", heightfield=_tilted_field())
    t = Transform(position=[0.0, -1.0, 0.0])
    rng = np.random.default_rng(3)
    xz = rng.uniform(-3.5, 3.5, size=(40, 2))
    surface_y = 1.0 + 0.5 * xz[:, 0] + 0.25 * xz[:, 1] - 1.0
    y = surface_y + rng.uniform(-1.0, 1.0, size=40)
    points = np.column_stack([xz[:, 0], y, xz[:, 1]])
    np.testing.assert_allclose(collider.signed_distance(points, t), y - surface_y, atol=1e-12)
    depth, normal = collider.query(points, t)
    np.testing.assert_allclose(depth, np.maximum(0.0, surface_y - y), atol=1e-12)
    expected = np.array([-0.5, 1.0, -0.25]) / np.linalg.norm([-0.5, 1.0, -0.25])
    np.testing.assert_allclose(normal, np.broadcast_to(expected, (40, 3)), atol=1e-12)


def test_box_ray_cast():
    box = Collider(shape="box", half_extents=[1.0, 1.0, 1.0])
    t = Transform(position=[0.0, 0.0, 0.0], rotation=quat_from_axis_angle([0, 1, 0], np.pi / 4))
    origins = np.array([[-5.0, 0.0, 0.0], [-5.0, 3.0, 0.0], [0.0, 5.0, 0.0], [0.2, 0.0, 0.0], [-5.0, 0.0, 0.0]])
    dirs = np.array([[1.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, -2.0, 0.0], [1.0, 0.0, 0.0], [-1.0, 0.0, 0.0]])
    hit, dist, normal = box.ray_cast(origins, dirs, t, max_t=100.0)
    np.testing.assert_array_equal(hit, [True, False, True, True, False])
    np.testing.assert_allclose(dist[hit], [5.0 - SQRT2, 2.0, 0.0], atol=1e-12)  # t in units of dirs
    assert np.all(np.isinf(dist[~hit])) and np.all(normal[~hit] == 0.0)
    assert normal[0] @ np.array([-1.0, 0.0, 0.0]) > 0.0 and abs(np.linalg.norm(normal[0]) - 1.0) < 1e-12
    np.testing.assert_allclose(normal[2], [0, 1, 0], atol=1e-12)
    np.testing.assert_allclose(normal[3], [1 / SQRT2, 0, 1 / SQRT2], atol=1e-12)  # inside: nearest face
    short = box.ray_cast(origins[:1], dirs[:1], t, max_t=3.0)
    assert not short[0][0]
    axis_aligned = box.ray_cast(np.array([[0.5, 0.5, 9.0]]), np.array([[0.0, 0.0, -1.0]]), Transform())
    np.testing.assert_allclose(axis_aligned[1], [8.0])
    np.testing.assert_allclose(axis_aligned[2], [[0, 0, 1]])


def test_sphere_and_plane_ray_cast():
    sphere = Collider(shape="sphere", radius=1.0)
    t = Transform(position=[0.0, 0.0, 2.0])
    hit, dist, normal = sphere.ray_cast(
        np.array([[0.0, 0.0, -3.0], [0.0, 1.5, -3.0], [0.0, 0.0, 7.0]]),
        np.array([[0.0, 0.0, 1.0], [0.0, 0.0, 1.0], [0.0, 0.0, 1.0]]),
        t,
    )
    np.testing.assert_array_equal(hit, [True, False, False])
    np.testing.assert_allclose(dist[0], 4.0)
    np.testing.assert_allclose(normal[0], [0, 0, -1])

    plane = Collider(shape="plane", offset=1.0)
    origins = np.array([[0.0, 5.0, 0.0], [0.0, 5.0, 0.0], [0.0, 5.0, 0.0], [2.0, 5.0, 0.0]])
    dirs = np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [1.0, -1.0, 0.0]])
    hit, dist, normal = plane.ray_cast(origins, dirs, Transform(), max_t=10.0)
    np.testing.assert_array_equal(hit, [True, False, False, True])
    np.testing.assert_allclose(dist[hit], [4.0, 4.0])
    np.testing.assert_allclose(normal[hit], [[0, 1, 0], [0, 1, 0]])


def test_ray_hits_lie_on_the_surface():
    rng = np.random.default_rng(5)
    origins = rng.uniform(-6.0, 6.0, size=(300, 3))
    dirs = -origins + rng.normal(scale=0.5, size=(300, 3))
    t = Transform(position=[0.1, -0.2, 0.3], rotation=quat_from_euler(0.4, 0.9, -0.3), scale=[1.0, 2.0, 1.5])
    for collider in (Collider(shape="box", half_extents=[1.0, 0.5, 2.0]), Collider(shape="sphere", radius=1.2)):
        hit, dist, normal = collider.ray_cast(origins, dirs, t)
        outside = collider.signed_distance(origins, t) > 0.0
        hits = hit & outside
        assert hits.sum() > 50
        points = origins[hits] + dist[hits, None] * dirs[hits]
        np.testing.assert_allclose(collider.signed_distance(points, t), 0.0, atol=1e-9)
        _, surface_normal = collider.query(points, t)
        np.testing.assert_allclose(np.sum(normal[hits] * surface_normal, axis=1), 1.0, atol=1e-6)


def test_heightfield_ray_cast_march_and_bisection():
    collider = Collider(shape="heightfield", heightfield=_tilted_field())
    t = Transform(position=[0.0, 0.0, 0.0])
    origins = np.array([
        [1.0, 10.0, 2.0],   # straight down
        [-3.0, 8.0, -3.0],  # oblique
        [1.0, 10.0, 2.0],   # straight up: miss
        [20.0, 10.0, 0.0],  # outside the footprint: miss
        [0.0, -5.0, 0.0],   # starts below the surface: t = 0
    ])
    dirs = np.array([[0.0, -1.0, 0.0], [1.0, -1.0, 0.5], [0.0, 1.0, 0.0], [0.0, -1.0, 0.0], [0.0, 1.0, 0.0]])
    hit, dist, normal = collider.ray_cast(origins, dirs, t, max_t=50.0)
    np.testing.assert_array_equal(hit, [True, True, False, False, True])
    np.testing.assert_allclose(dist[0], 10.0 - (1.0 + 0.5 + 0.5), atol=1e-9)
    # Oblique ray: 8 - s = 1 + 0.5(-3 + s) + 0.25(-3 + 0.5 s)  ->  s = 9.25 / 1.625
    np.testing.assert_allclose(dist[1], 9.25 / 1.625, atol=1e-9)
    np.testing.assert_allclose(dist[4], 0.0)
    expected = np.array([-0.5, 1.0, -0.25]) / np.linalg.norm([-0.5, 1.0, -0.25])
    np.testing.assert_allclose(normal[[0, 1, 4]], np.broadcast_to(expected, (3, 3)), atol=1e-12)
    assert not collider.ray_cast(origins[:1], dirs[:1], t, max_t=7.0)[0][0]


def test_flat_heightfield_ray_cast_and_rotation():
    flat = HeightField(heights=np.full((3, 3), 2.0), spacing=1.0, origin=[-1.0, -1.0])
    collider = Collider(shape="heightfield", heightfield=flat)
    # Rotated 90° about x: the field's up (+y) becomes world +z.
    t = Transform(position=[0.0, 0.0, 1.0], rotation=quat_from_axis_angle([1, 0, 0], np.pi / 2))
    hit, dist, normal = collider.ray_cast(np.array([[0.5, 0.5, 10.0]]), np.array([[0.0, 0.0, -1.0]]), t)
    assert hit[0]
    np.testing.assert_allclose(dist, [7.0], atol=1e-9)
    np.testing.assert_allclose(normal, [[0, 0, 1]], atol=1e-12)


def _pond():
    """A flat field at y = 0 over [-3.75, 3.75]² (16 × 16 samples), as a water surface makes."""
    return HeightField(heights=np.zeros((16, 16)), spacing=0.5, origin=np.array([-3.75, -3.75]))


def test_heightfield_is_solid_only_over_its_footprint():
    # A point below the surface's level was inside however far beside the footprint (height_at clamps to the
    # border), so a ray starting there hit at t = 0: a water surface 8 m away swallowed an energy wave as it left
    # its emitter. The solid is the column below the surface over the footprint, as Bullet's and PhysX's.
    collider = Collider(shape="heightfield", heightfield=_pond())
    hit, t, normal = collider.ray_cast([[-8.0, -0.67, 6.0]], [[0.0, 0.0, -0.33]], Transform(), max_t=1.0)
    assert not hit[0] and np.isinf(t[0]) and (normal == 0.0).all()
    points = np.array([[-8.0, -0.67, 6.0],  # beside a corner, below the level: √(4.25² + 2.25²)
                       [-3.76, -5.0, 0.0],  # just beside the x = -3.75 wall: 0.01
                       [0.0, -5.0, 3.85],  # beside the z = 3.75 wall
                       [5.75, 2.0, 0.0],  # beside and above the border's height: √(2² + 2²)
                       [-3.75, -5.0, 3.75],  # on the corner's edge, below: inside (edges included)
                       [1.0, -0.5, -2.0]])  # over the footprint, below: inside, vertical gap
    want = [np.sqrt(4.25 ** 2 + 2.25 ** 2), 0.01, 0.1, np.sqrt(8.0), -5.0, -0.5]
    for transform in (Transform(), Transform(position=[2.0, 1.0, -3.0], rotation=quat_from_euler(0.3, 0.7, -0.2))):
        world = _placed(transform, points)
        np.testing.assert_allclose(collider.signed_distance(world, transform), want, atol=1e-12)
        depth, normal = collider.query(world, transform)
        np.testing.assert_allclose(depth, [0.0, 0.0, 0.0, 0.0, 5.0, 0.5], atol=1e-12)
        local_normal = [[-4.25, 0.0, 2.25], [-1.0, 0.0, 0.0], [0.0, 0.0, 1.0], [1.0, 1.0, 0.0], [0.0, 1.0, 0.0],
                        [0.0, 1.0, 0.0]]  # beside: from the column's nearest point straight across; over: the surface
        local_normal = np.array(local_normal) / np.linalg.norm(local_normal, axis=1, keepdims=True)
        np.testing.assert_allclose(normal, _placed(Transform(rotation=transform.rotation), local_normal),
                                   atol=1e-12)
        up = _placed(Transform(rotation=transform.rotation), np.tile([0.0, 1.0, 0.0], (6, 1)))
        inside = collider.ray_cast(world, up, transform, max_t=0.5)  # straight up the field's frame
        np.testing.assert_array_equal(inside[0], [False, False, False, False, True, True])


def _placed(transform: Transform, points) -> np.ndarray:
    """Points given in a collider's frame, in the world (the transform's rotation, then its position)."""
    from engine.spatial import quat_rotate

    return quat_rotate(transform.rotation, np.asarray(points, float)) + transform.position


def test_heightfield_side_walls_stop_rays_that_enter_below_the_surface():
    """A ray entering the footprint from beside it below the surface hits the side wall where it enters, with the
    wall's outward normal; one entering above it flies on to the surface (or through); a ray that never enters
    the footprint misses, however low. Rotated too, and the kernel and the numpy reference agree."""
    collider = Collider(shape="heightfield", heightfield=_tilted_field())  # h = 1 + 0.5x + 0.25z on [-4, 4]²
    origins = np.array([[-6.0, -1.5, 0.0],  # → +x below the wall's top (h(-4, 0) = -1): hits x = -4 at t = 2
                        [0.0, 0.0, 7.0],  # → -z, h(0, 4) = 2 above: hits z = 4 at t = 3
                        [-7.0, 0.0, -7.0],  # diagonally at the corner (-4, -4), h = -2 there: enters above
                        [-6.0, -3.5, -1.0],  # → +x, h(-4, -1) = -1.25 > -3.5 at the wall: t = 2
                        [-6.0, 9.0, 0.0],  # → +x high above: misses
                        [-6.0, -20.0, 0.0],  # → +z beside the footprint, far below: misses
                        [6.0, -20.0, 6.0],  # → up beside a corner: misses
                        [-6.0, -1.5, 0.0]])  # → +x but max_t stops it short of the wall
    dirs = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [1.0, 0.0, 1.0], [1.0, 0.0, 0.0], [1.0, 0.0, 0.0],
                     [0.0, 0.0, 1.0], [0.0, 1.0, 0.0], [1.0, 0.0, 0.0]])
    max_t = np.array([50.0, 50.0, 50.0, 50.0, 50.0, 50.0, 50.0, 1.9])
    for transform in (Transform(), Transform(position=[0.5, -2.0, 1.0], rotation=quat_from_euler(0.9, 0.2, 0.1))):
        world_o = _placed(transform, origins)
        world_d = _placed(Transform(rotation=transform.rotation), dirs)
        rows = [collider.ray_cast(world_o[i:i + 1], world_d[i:i + 1], transform, max_t[i]) for i in range(8)]
        hit = np.array([r[0][0] for r in rows])
        t = np.array([r[1][0] for r in rows])
        normal = np.array([r[2][0] for r in rows])
        np.testing.assert_array_equal(hit, [True, True, True, True, False, False, False, False])
        np.testing.assert_allclose(t[[0, 1, 3]], [2.0, 3.0, 2.0], atol=1e-12)
        local = [[-1.0, 0.0, 0.0], [0.0, 0.0, 1.0], [-1.0, 0.0, 0.0]]
        np.testing.assert_allclose(normal[[0, 1, 3]], _placed(Transform(rotation=transform.rotation),
                                                                         local), atol=1e-12)
        # the diagonal ray passes the corner above the surface and meets it inside: 0 = 1 + 0.75 (s - 7)
        assert 3.0 < t[2] < 7.0 and normal[2] @ _placed(Transform(rotation=transform.rotation),
                                                                  [[0.0, 1.0, 0.0]])[0] > 0.5
        np.testing.assert_allclose(t[2], 7.0 - 1.0 / 0.75, atol=1e-9)
        for a, b in zip(collider.ray_cast(world_o, world_d, transform, 50.0),
                        collider._ray_cast_numpy(world_o, world_d, transform, 50.0)):
            _same_bits(a, b)


def test_constructor_validation():
    with pytest.raises(ValueError, match="unknown collider shape 'cube'"):
        Collider(shape="cube")
    with pytest.raises(ValueError, match="HeightField"):
        Collider(shape="heightfield")
    with pytest.raises(ValueError, match="normal"):
        Collider(shape="plane", normal=[0.0, 0.0, 0.0])
    c = Collider(shape="sphere", layer="debris", is_trigger=True)
    assert c.layer == "debris" and c.is_trigger
    np.testing.assert_array_equal(Collider().normal, [0, 1, 0])


def test_first_max_is_argmax_over_three_columns_ties_included():
    from engine.collider import _first_max

    rng = np.random.default_rng(2)
    q = np.round(rng.normal(size=(5000, 3)) * 2) / 2  # many equal values
    q[:10] = [[1, 1, 1], [0, 1, 1], [1, 0, 1], [1, 1, 0], [-np.inf, -np.inf, -np.inf], [np.inf, 0, np.inf],
              [-1, -np.inf, -1], [0, 0, 1], [2, 2, 1], [-0.0, 0.0, -0.0]]
    assert np.array_equal(_first_max(q[:, 0], q[:, 1], q[:, 2]), np.argmax(q, axis=-1))


# ----------------------------------------------------------------------------- box kernels == numpy reference
def _same_bits(a, b):
    a, b = np.asarray(a), np.asarray(b)
    assert a.shape == b.shape and a.dtype == b.dtype
    if a.dtype == np.bool_:
        np.testing.assert_array_equal(a, b)
    else:  # bit patterns: tells -0.0 from 0.0 and compares NaNs
        np.testing.assert_array_equal(a.view(np.int64), b.view(np.int64))


def _box_cases():
    """Random boxes and transforms (rotated, scaled incl. a flat and a negative axis) with the edge cases."""
    rng = np.random.default_rng(7)
    cases = [
        (Collider(shape="box", half_extents=[1.0, 2.0, 3.0]), Transform()),
        (Collider(shape="box", half_extents=[1.0, 2.0, 3.0]), Transform(position=[10.0, -1.0, 0.5])),
        (Collider(shape="box", half_extents=[0.5, 0.0, 0.25]),
         Transform(position=[0.2, 0.3, -0.4], rotation=quat_from_euler(0.3, -1.1, 2.0), scale=[2.0, 1.0, -3.0])),
        (Collider(shape="box", half_extents=[1.0, 1.0, 1.0]),
         Transform(rotation=quat_from_axis_angle([0, 1, 0], np.pi / 4))),
    ]
    for _ in range(3):
        q = rng.standard_normal(4)
        cases.append((Collider(shape="box", half_extents=rng.uniform(0.1, 3.0, 3)),
                      Transform(position=rng.uniform(-5, 5, 3), rotation=q / np.linalg.norm(q),
                                scale=rng.uniform(-2, 2, 3))))
    return cases


def _edge_points(box, transform, rng, n=4000):
    """World points: random, on faces/edges/corners, at the centre, on the axes with ±0 and far away."""
    h = box.half_extents * np.abs(transform.scale)
    local = rng.uniform(-2.0, 2.0, (n, 3)) * np.maximum(h, 0.5)
    signs = rng.choice([-1.0, 1.0], (n, 3))
    snap = rng.random((n, 3)) < 0.3  # about a third of the coordinates exactly on a face plane
    local = np.where(snap, signs * h, local)
    zero = rng.random((n, 3)) < 0.1
    local = np.where(zero, signs * 0.0, local)  # +0.0 and -0.0
    local[:8] = [[0, 0, 0], [-0.0, -0.0, -0.0], h, -h, [h[0], 0, 0], [0, -h[1], 0], [0, 0, h[2]], 3 * h + 1]
    world = transform.position + _rotate_np(transform.rotation, local)
    world[-4:] = [[0.0, 0.0, 0.0], [-0.0, 0.0, -0.0], [1e6, -1e6, 1e6], [1e-300, -1e-300, 0.0]]
    world = np.concatenate([world, local])  # also unrotated points, exactly on axis-aligned faces
    return world


def _rotate_np(q, v):
    from engine.spatial import quat_rotate

    return quat_rotate(q, v)


def test_box_query_kernel_matches_numpy_bit_for_bit():
    rng = np.random.default_rng(11)
    for box, transform in _box_cases():
        points = _edge_points(box, transform, rng)
        depth, normal = box.query(points, transform)
        ref_depth, ref_normal = box._query_numpy(points, transform)
        _same_bits(depth, ref_depth)
        _same_bits(normal, ref_normal)
        ref_distance = box._local_distance(box._to_local(points, transform), transform)[0]
        _same_bits(box.signed_distance(points, transform), ref_distance)
        assert np.all(np.isfinite(normal))
    box = Collider(shape="box")
    empty = box.query(np.zeros((0, 3)), Transform())
    assert empty[0].shape == (0,) and empty[1].shape == (0, 3)


def test_box_ray_cast_kernel_matches_numpy_bit_for_bit():
    rng = np.random.default_rng(12)
    for box, transform in _box_cases():
        origins = _edge_points(box, transform, rng)
        n = len(origins)
        # directions: random, towards the centre, axis-parallel (zeros in the box frame and in the world frame),
        # zero vectors (NaN-free), tiny and huge
        dirs = rng.standard_normal((n, 3))
        dirs[rng.random(n) < 0.25] *= 1e-3
        towards = rng.random(n) < 0.3
        dirs[towards] = transform.position - origins[towards]
        axis_rows = rng.random(n) < 0.3
        local_axis = np.zeros((n, 3))
        local_axis[np.arange(n), rng.integers(0, 3, n)] = rng.choice([-3.0, 3.0], n)
        dirs[axis_rows] = _rotate_np(transform.rotation, local_axis[axis_rows])
        dirs[rng.random(n) < 0.2] *= rng.choice([0.0, -0.0, 1.0], (1, 3))  # world-axis zeros
        dirs[:5] = [[0, 0, 0], [-0.0, -0.0, -0.0], [1e-310, 0, 0], [0, 1e300, 0], [1, 1, 1]]
        for max_t in (np.inf, 1.0, 0.0, 2.5):
            hit, t, normal = box.ray_cast(origins, dirs, transform, max_t=max_t)
            with np.errstate(over="ignore"):  # 1 / 1e-310 in the numpy reference
                ref = box._ray_cast_numpy(origins, dirs, transform, max_t=max_t)
            _same_bits(hit, ref[0])
            _same_bits(t, ref[1])
            _same_bits(normal, ref[2])
            assert not np.isnan(t).any() and not np.isnan(normal).any()
            assert hit.any() and (~hit).any()
        # a zero direction hits only from inside (t = 0)
        zero_hit, zero_t, _ = box.ray_cast(origins, np.zeros_like(origins), transform)
        inside = box.signed_distance(origins, transform) < 0.0
        np.testing.assert_array_equal(zero_hit, inside)
        assert np.all(zero_t[inside] == 0.0) and np.all(np.isinf(zero_t[~inside]))


def test_box_kernels_accept_non_contiguous_and_list_input():
    box = Collider(shape="box", half_extents=[1.0, 2.0, 0.5])
    transform = Transform(position=[0.5, 0.0, 0.0], rotation=quat_from_euler(0.2, 0.4, 0.1))
    rng = np.random.default_rng(3)
    block = rng.uniform(-3, 3, (50, 6))
    origins, dirs = block[:, :3], block[:, 3:]  # strided views
    assert not origins.flags.c_contiguous
    for got, ref in zip(box.ray_cast(origins, dirs, transform), box._ray_cast_numpy(origins, dirs, transform)):
        _same_bits(got, ref)
    for got, ref in zip(box.query(origins.tolist(), transform), box._query_numpy(origins, transform)):
        _same_bits(got, ref)


def test_heightfield_ray_cast_kernel_matches_numpy_bit_for_bit():
    """The compiled march + Illinois refinement against the numpy reference: rough fields (midpoint displacement,
    a flat one, a tiny 2 × 2 one), rays from above, below, inside and outside the footprint, grazing, vertical,
    horizontal and zero-length, from the footprint's borders and along them; several max_t. Rays from beside the
    footprint that enter it below the surface hit a side wall (normal horizontal) in both."""
    from engine.heightfield import midpoint_displacement
    from engine.spatial import quat_conjugate, quat_rotate

    rng = np.random.default_rng(11)
    fields = [HeightField(heights=midpoint_displacement(5, 0.6, 4.0, np.random.default_rng(3)), spacing=0.7,
                          origin=[-11.0, -9.0]),
              HeightField(heights=np.full((5, 4), 1.5), spacing=2.0, origin=[0.0, 0.0]),
              HeightField(heights=np.array([[0.0, 1.0], [2.0, -1.0]]), spacing=3.0, origin=[-1.5, -1.5])]
    hits = walls = 0
    for field in fields:
        collider = Collider(shape="heightfield", heightfield=field)
        transform = Transform(position=[0.3, -0.2, 0.1], rotation=quat_from_euler(0.2, 0.05, -0.1))
        n = 3000
        origins = rng.uniform(-14.0, 14.0, (n, 3))
        dirs = rng.normal(size=(n, 3))
        dirs[: n // 6, [0, 2]] = 0.0  # vertical
        dirs[n // 6: n // 3, 1] *= 1e-3  # grazing
        dirs[n // 3: n // 3 + 50, 1] = 0.0  # horizontal
        dirs[-20:] = 0.0  # no direction at all
        (x_lo, x_hi), (z_lo, z_hi) = field.bounds()
        border = slice(n // 3 + 50, n // 3 + 250)  # origins (in the field's frame) on the borders, some along them
        local = rng.uniform(-14.0, 14.0, (200, 3))
        local[:, 0] = np.where(np.arange(200) % 2 == 0, x_lo, x_hi)
        local[100:, [0, 2]] = local[100:, [2, 0]]
        local[100:, 2] = np.where(np.arange(100) % 2 == 0, z_lo, z_hi)
        origins[border] = quat_rotate(transform.rotation, local) + transform.position
        dirs[n // 3 + 50: n // 3 + 90] = quat_rotate(transform.rotation, np.array([0.0, 0.3, 1.0]))
        for max_t in (np.inf, 3.0, 0.0):
            inverse = quat_conjugate(transform.rotation)  # the shape functions work in the collider's frame
            o, d = quat_rotate(inverse, origins - transform.position), quat_rotate(inverse, dirs)
            beside = slice(n // 3 + 250, n // 3 + 270)  # from beside x_lo with a subnormal x direction: an entry
            o[beside, 0], d[beside] = x_lo - 1.0, [5e-324, -1.0, 0.0]  # at t = inf (along z: x never changes)
            with np.errstate(over="ignore"):  # 1 / 5e-324
                want = collider._ray_heightfield_numpy(o, d, transform, max_t)
            got = collider._ray_heightfield(o, d, transform, max_t)
            for a, b in zip(want, got):
                _same_bits(a, b)
            hits += int(want[0].sum())
            walls += int((want[0] & (want[2][:, 1] == 0.0)).sum())
            for a, b in zip(collider.ray_cast(origins, dirs, transform, max_t),
                            collider._ray_cast_numpy(origins, dirs, transform, max_t)):
                _same_bits(a, b)
    assert hits > 300 and walls > 100  # the cases do hit (1223, 838 of them side walls, with this seed)


def test_heightfield_interval_kernel_matches_numpy_bit_for_bit():
    """The compiled clipping of rays to a field's box against the numpy reference, -0.0 and NaN included: rays
    starting exactly on each face or corner (t = ±0 there), parallel inside and outside a slab, without
    direction, with a subnormal direction, with NaN origins (inactive); the march's step count from the longest
    horizontal travel; and both refuse a NaN or infinite direction alike (its travel is NaN)."""
    from engine.collider import _heightfield_interval_kernel

    rng = np.random.default_rng(17)
    collider = Collider(shape="heightfield", heightfield=HeightField(heights=rng.uniform(-1.0, 2.0, (6, 5)),
                                                                    spacing=0.8, origin=[-1.5, -2.0]))
    lo, hi = collider._heightfield_box()
    n = 4000
    o = rng.uniform(-4.0, 4.0, (n, 3))
    d = rng.normal(size=(n, 3)) * rng.choice([0.1, 1.0, 10.0], (n, 1))
    for axis in range(3):  # origins on the faces, going in and out
        on = slice(200 * axis, 200 * axis + 200)
        o[on, axis] = np.where(np.arange(200) % 2 == 0, lo[axis], hi[axis])
        d[on.start: on.start + 50, axis] = 0.0  # ... and along them
        d[on.start + 200 * 3: on.start + 200 * 3 + 60, axis] = 0.0  # parallel anywhere
    d[1500:1520] = 0.0
    d[1520:1540, 1] = 5e-324
    o[1560:1580, 1] = np.nan
    o[1580:1600] = np.abs(o[1580:1600]) * -0.0  # origin at -0.0
    o[1600:1800] = np.where(rng.random((200, 3)) < 0.5, lo, hi)  # on the box's corners: ±0 on several axes
    signed_zeros, actives = 0, []
    for max_t in (np.inf, 2.5, 0.0, -0.0):
        with np.errstate(invalid="ignore", over="ignore"):
            want = collider._heightfield_interval(o, d, max_t)
            t_start, t_end, active, longest = _heightfield_interval_kernel(o, d, lo, hi, max_t)
            horizontal = np.hypot(d[:, 0], d[:, 2]) * np.where(want[2], want[1] - want[0], 0.0)
        for got, ref in zip((t_start, t_end, active), want[:3]):
            _same_bits(got, ref)
        _same_bits(np.float64(longest), np.max(horizontal, initial=0.0))
        assert collider._heightfield_steps(longest) == want[3]
        live = want[2]
        signed_zeros += int(np.sum(np.signbit(t_end[live]) & (t_end[live] == 0.0)))
        actives.append(int(live.sum()))
    assert signed_zeros > 0  # -0.0 did occur where it is kept
    assert actives[0] > 500 and actives[2] > 0
    for bad in (np.nan, np.inf):
        d[7, 0] = bad
        with pytest.raises(ValueError, match="NaN"), np.errstate(invalid="ignore", over="ignore"):
            collider._heightfield_interval(o, d, 1.0)
        with pytest.raises(ValueError, match="NaN"):
            collider._heightfield_steps(_heightfield_interval_kernel(o, d, lo, hi, 1.0)[3])


def test_heightfield_distance_kernel_matches_solid_distance_bit_for_bit():
    """The signed distance (the ray casts' inside test) compiled against HeightField.solid_distance: points inside
    and outside the footprint, on grid nodes and borders, one float beside them, at ±0, ±inf and huge coordinates
    (an overflowing distance), a NaN height; over the footprint it is y − height_at, as it always was. NaN x or z
    and float32 heights take solid_distance itself (NaN still fails there as it did)."""
    from engine.heightfield import midpoint_displacement

    rng = np.random.default_rng(23)
    field = HeightField(heights=midpoint_displacement(4, 0.6, 3.0, np.random.default_rng(2)), spacing=0.6,
                        origin=[-0.0, -4.2])
    collider = Collider(shape="heightfield", heightfield=field)
    (x_lo, x_hi), (z_lo, z_hi) = field.bounds()
    n = 3000
    p = rng.uniform(-12.0, 12.0, (n, 3))
    p[:500, 0] = x_lo + field.spacing * rng.integers(-2, 20, 500)  # on grid lines and nodes
    p[:500, 2] = z_lo + field.spacing * rng.integers(-2, 20, 500)
    p[500:520, 0] = -0.0
    p[520:540, 0], p[540:560, 2] = x_hi, z_hi
    p[560:580, 0], p[580:600, 2] = np.inf, -np.inf
    p[600:620, [0, 2]] = [1e300, -1e300]
    p[620:640, 0] = np.nextafter(x_lo, -1.0)  # one float beside the footprint, far below the surface (x_lo is
    p[640:660, 2] = np.nextafter(z_hi, 99.0)  # -0.0: the gap 5e-324 squares to 0, so the distance is 0: not inside)
    p[620:640, 2], p[640:660, 0], p[620:660, 1] = z_lo + 1.0, x_lo + 1.0, -50.0
    p[660:680, 1] = np.nan
    p[680:700, 0], p[680:700, 1] = x_hi + 1e-160, 9.0  # a gap whose square underflows, above the border's surface
    with np.errstate(invalid="ignore"):
        want = field.solid_distance(p[:, 0], p[:, 1], p[:, 2])
        _same_bits(collider._heightfield_distance(p), want)
    finite = np.isfinite(p).all(axis=1)  # (the identity rotation of an infinite point gives NaN)
    _same_bits(collider.signed_distance(p[finite], Transform()), want[finite])
    over = (p[:, 0] >= x_lo) & (p[:, 0] <= x_hi) & (p[:, 2] >= z_lo) & (p[:, 2] <= z_hi)
    assert 500 < over.sum() < 2500
    _same_bits(want[over], p[over, 1] - field.height_at(p[over, 0], p[over, 2]))
    beside = ~over & ~np.isnan(p[:, 1])
    assert (want[beside] >= 0.0).all() and (want[620:640] == 0.0).all() and (want[640:660] > 0.0).all()
    single = Collider(shape="heightfield", heightfield=HeightField(heights=field.heights.astype(np.float32),
                                                                    spacing=0.6, origin=[-0.0, -4.2]))
    single.heightfield.heights = field.heights.astype(np.float32)  # float32 heights: solid_distance's arithmetic
    with np.errstate(invalid="ignore"):
        _same_bits(single._heightfield_distance(p), single.heightfield.solid_distance(p[:, 0], p[:, 1], p[:, 2]))
    p[1234, 2] = np.nan
    with pytest.raises(IndexError), np.errstate(invalid="ignore"):
        collider._heightfield_distance(p)


@pytest.mark.parametrize("rotated", [False, True])
@pytest.mark.parametrize("shape", ["box", "sphere", "plane", "heightfield"])
def test_rays_that_start_inside_hit_at_zero_with_the_query_normal(shape, rotated):
    """Inside starts (mixed with outside ones) hit at t = 0 with the normal ``query`` gives there; the ray cast
    computes those normals only for the inside rows, and skips the rotations of an unrotated collider."""
    from engine.heightfield import midpoint_displacement

    field = HeightField(heights=midpoint_displacement(4, 0.6, 2.0, np.random.default_rng(5)), spacing=0.5,
                        origin=[-4.0, -4.0])
    collider = Collider(shape=shape, heightfield=field if shape == "heightfield" else None, radius=1.5,
                        half_extents=np.array([1.0, 0.7, 1.2]))
    transform = Transform(position=[0.2, -0.1, 0.3],
                          rotation=quat_from_euler(0.3, 0.2, -0.1) if rotated else np.array([1.0, 0.0, 0.0, 0.0]))
    rng = np.random.default_rng(2)
    origins = rng.uniform(-1.6, 1.6, (400, 3))
    dirs = rng.normal(size=(400, 3))
    inside = collider.signed_distance(origins, transform) < 0.0
    assert 40 < inside.sum() < 360  # a mix of inside and outside starts
    hit, t, normal = collider.ray_cast(origins, dirs, transform, max_t=0.5)
    assert hit[inside].all() and (t[inside] == 0.0).all()
    np.testing.assert_array_equal(normal[inside], collider.query(origins[inside], transform)[1])
    np.testing.assert_array_equal(normal[~hit], 0.0)
    assert np.isinf(t[~hit]).all()
    for a, b in zip((hit, t, normal), collider._ray_cast_numpy(origins, dirs, transform, max_t=0.5)):
        np.testing.assert_array_equal(a, b)


def test_heightfield_rays_with_nan_or_infinite_coordinates_miss_and_leave_the_others_alone():
    # A NaN origin used to index the height grid out of range and a NaN or infinite direction to turn the march's
    # step count into int(nan): a script's bad ray crashed the cast of every ray with it. Box, sphere and plane
    # already answered such rays with a miss.
    collider = Collider(shape="heightfield", heightfield=_tilted_field())
    good_o, good_d = [[0.3, 5.0, -0.2], [1.0, 4.0, 1.0]], [[0.1, -1.0, 0.05], [0.0, -1.0, 0.0]]
    alone = collider.ray_cast(good_o, good_d, Transform())
    bad_o = [[np.nan, 5.0, 0.0], [0.0, 5.0, 0.0], [np.inf, 5.0, 0.0]]
    bad_d = [[0.0, -1.0, 0.0], [np.nan, -1.0, 0.0], [0.0, -1.0, 0.0]]
    hit, t, normal = collider.ray_cast(good_o[:1] + bad_o + good_o[1:], good_d[:1] + bad_d + good_d[1:], Transform())
    assert alone[0].all()
    assert hit.tolist() == [True, False, False, False, True]
    assert np.isinf(t[1:4]).all() and not normal[1:4].any()
    assert np.array_equal(t[[0, 4]], alone[1]) and np.array_equal(normal[[0, 4]], alone[2])
    hit, t, _ = collider.ray_cast([[0.0, 5.0, 0.0]], [[np.inf, -1.0, 0.0]], Transform())
    assert not hit[0] and np.isinf(t[0])
