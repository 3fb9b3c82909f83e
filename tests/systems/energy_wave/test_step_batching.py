"""The step sweeps all emitters' beams together and reuses work arrays: neither may change any result."""

import subprocess
import sys
from pathlib import Path

import numpy as np

from components.energy_wave import EnergyWaveEmitter, EnergyWaveHit, EnergyWaveState
from engine.impacts import Impact
from engine.spatial import Transform
from systems.energy_wave.simulate import simulate_system, step_emitter

from .helpers import add_box, add_emitter, make_app

ROOT = Path(__file__).resolve().parents[3]


def _three_emitters(seed: int = 4):
    """Three emitters sharing a wall; one skips the glass layer; a trigger volume in front of the wall."""
    app = make_app(seed)
    add_box(app, (0.0, 0.0, -1.5), (3.0, 3.0, 0.2))
    add_box(app, (0.6, 0.0, -0.8), (0.3, 0.3, 0.05), layer="glass")
    add_box(app, (-0.6, 0.0, -0.9), (0.3, 0.3, 0.2), is_trigger=True)
    add_emitter(app, position=(-0.6, 0.0, 0.0), emission_rate=1500.0, circular_probability=0.5,
                continuity_probability=0.5)
    add_emitter(app, position=(0.6, 0.0, 0.0), emission_rate=1500.0, collision_layers=["default"])
    add_emitter(app, position=(0.0, 0.3, 0.0), yaw_pitch_roll=(0.3, 0.0, 0.0), emission_rate=900.0)
    return app


def _events(app, readers):
    return [[(type(e).__name__, repr(e)) for e in reader.read()] for reader in readers]


def test_emitters_stepped_together_equal_emitters_stepped_one_at_a_time():
    together, apart = _three_emitters(), _three_emitters()
    log = {}
    for app in (together, apart):
        readers = [app.world.events.reader(EnergyWaveHit), app.world.events.reader(Impact)]
        log[id(app)] = []
        for _ in range(50):
            if app is together:
                simulate_system(app.world, app.dt)
            else:
                for entity, (transform, cfg, state) in app.world.query(Transform, EnergyWaveEmitter,
                                                                        EnergyWaveState):
                    step_emitter(app.world, entity, transform, cfg, state, app.dt)
            log[id(app)].append(_events(app, readers))
            app.world.events.update()
    assert sum(s.particles.count for _, (s,) in together.world.query(EnergyWaveState)) > 1000
    assert any(tick[0] for tick in log[id(together)])  # hits were reported
    assert together.state_hash() == apart.state_hash()
    assert log[id(together)] == log[id(apart)]


def test_worlds_stepped_alternately_equal_worlds_stepped_alone():
    """Work arrays shared between steps and worlds never carry anything from one step to the next."""
    a, b = _three_emitters(1), make_app(2)
    add_box(b, (0.0, 0.0, -1.0), (2.0, 2.0, 0.2))
    add_emitter(b, emission_rate=4000.0)
    for _ in range(40):
        a.step(1)
        b.step(1)
    a_alone, b_alone = _three_emitters(1), make_app(2)
    add_box(b_alone, (0.0, 0.0, -1.0), (2.0, 2.0, 0.2))
    add_emitter(b_alone, emission_rate=4000.0)
    a_alone.step(40)
    b_alone.step(40)
    assert a.state_hash() == a_alone.state_hash()
    assert b.state_hash() == b_alone.state_hash()


def test_state_hash_is_the_same_in_a_fresh_process():
    code = ("from tests.systems.energy_wave.test_step_batching import _three_emitters\n"
            "app = _three_emitters(9)\napp.step(45)\nprint(app.state_hash())\n")
    here = _three_emitters(9)
    here.step(45)
    other = subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True, check=True)
    assert other.stdout.strip() == str(here.state_hash())


def test_many_particles_stay_finite_and_repelled():
    """A dense impact (thousands of settled neighbours, crowded cells sampled) gives finite, outward R."""
    app = make_app(3)
    add_box(app, (0.0, 0.0, -0.6), (2.0, 2.0, 0.1))
    entity, cfg, st = add_emitter(app, emission_rate=20000.0, beam_speed=10.0, circular_probability=1.0,
                                  max_particles=30000)
    app.step(45)
    buf = st.particles
    assert buf.count > 10000
    accel = buf.acceleration[: buf.count]
    assert np.isfinite(accel).all()
    assert (accel[buf.pattern[: buf.count] >= 0, 2] > 0.0).mean() > 0.9  # away from the wall (normal +z)


def test_groups_computed_together_equal_groups_computed_alone():
    """Several emitters' repulsions in one pass give bit for bit what each gets alone (tables, samples, sums)."""
    from systems.energy_wave.neighbours import grouped_repulsion, in_reach

    rng = np.random.default_rng(8)
    groups = []
    for g, (spread, radius) in enumerate([(0.05, 0.1), (1.0, 0.3), (0.02, 0.25), (0.3, 0.05)]):
        pts = rng.normal(g, spread, (800 + 500 * g, 3))
        query = pts[rng.integers(0, len(pts), 40 + 30 * g)] + rng.normal(0.0, spread / 4, (40 + 30 * g, 3))
        groups.append((query, pts[in_reach(pts, query, radius)], radius, 1.0 + g))
    groups.insert(2, (np.zeros((0, 3)), np.zeros((0, 3)), 0.1, 1.0))  # an empty group keeps its place
    for limit in (0, 16):
        together = grouped_repulsion(groups, limit)
        for group, result in zip(groups, together):
            assert np.array_equal(result, grouped_repulsion([group], limit)[0])
    assert np.abs(together[0]).max() > 0.0


def test_row_helpers_and_dead_removal_match_fancy_indexing():
    """Rows gathered with take and written as 24-byte records, and dead particles replaced by the live ones above the
    new count (or just dropped when they all sit there), give what numpy's fancy indexing gives, slot by slot."""
    from components.energy_wave import ParticleBuffer
    from systems.energy_wave.simulate import _put_rows, _remove_dead, _take_rows

    rng = np.random.default_rng(3)
    array = rng.standard_normal((50, 3))
    rows = np.array([7, 3, 41, 0])
    assert np.array_equal(_take_rows(array, rows), array[rows])
    values = rng.standard_normal((4, 3))
    expected = array.copy()
    expected[rows] = values
    _put_rows(array, rows, values)
    assert np.array_equal(array, expected)
    for dead_at in (np.array([2, 5, 29, 38]), np.array([36, 37, 38, 39])):  # holes to fill; only the tail dies
        buf = ParticleBuffer(60)
        buf.count = 40
        for a in buf.arrays():
            a[...] = rng.integers(0, 100, a.shape).astype(a.dtype)
        dead = np.zeros(40, dtype=bool)
        dead[dead_at] = True
        buf.lifetime[:40] = 50.0
        buf.age[:40] = np.where(dead, 50.0 + 2e-9, 50.0 + 1e-9)  # dead: age > lifetime + 1e-9 (not merely >=)
        before = [a[:40].copy() for a in buf.arrays()]
        assert _remove_dead(buf) == 4
        assert buf.count == 36
        source = np.arange(36)  # each slot below the new count keeps its particle, or takes the next live mover
        kept = np.flatnonzero(~dead)
        source[dead_at[dead_at < 36]] = kept[kept >= 36]
        for old, new in zip(before, buf.arrays()):
            assert np.array_equal(new[:36], old[source])


def test_gather_in_box_equals_the_numpy_selection():
    """The neighbour gathering kernel keeps exactly the settled rows (pattern >= 0) in the box, then the extra rows
    in the box, in index order (borders inclusive, NaN outside)."""
    from systems.energy_wave.kernels import gather_in_box
    from systems.energy_wave.neighbours import in_box

    rng = np.random.default_rng(12)
    position = np.round(rng.uniform(-1.0, 1.0, (400, 3)), 1)  # many points exactly on the box's faces
    position[5] = np.nan
    pattern = rng.integers(-1, 8, 400).astype(np.int8)
    extra = np.round(rng.uniform(-1.0, 1.0, (30, 3)), 1)
    lo, hi = np.array([-0.5, -0.3, -0.8]), np.array([0.5, 0.7, 0.2])
    out = np.full((430, 3), -7.0)
    found = gather_in_box(position, pattern, 300, extra, lo, hi, out)  # the buffer's live range is [0, 300)
    expected = np.concatenate([position[in_box(position[:300], lo, hi, pattern[:300] >= 0)],
                               extra[in_box(extra, lo, hi)]])
    assert 0 < len(expected) < 330
    assert found == len(expected)
    assert np.array_equal(out[:found], expected)


def test_advance_kernel_equals_the_numpy_update():
    """age += dt, beam rows with their unmoved positions, x += v·dt for all but the held irregular particles."""
    from systems.energy_wave.kernels import advance_particles, move_rows

    rng = np.random.default_rng(21)
    position, velocity, age = rng.standard_normal((50, 3)), rng.standard_normal((50, 3)), rng.random(50)
    pattern = rng.integers(-1, 8, 50).astype(np.int8)
    for hold in (False, True):
        p, a = position.copy(), age.copy()
        beam, start, irregular = advance_particles(p, velocity, a, pattern, 40, 1.0 / 60.0, hold)
        assert np.array_equal(beam, np.flatnonzero(pattern[:40] < 0))
        assert np.array_equal(start, position[beam])
        expected_irregular = np.flatnonzero((pattern[:40] >= 0) & (pattern[:40] % 2 == 1)) if hold else []
        assert np.array_equal(irregular, expected_irregular)
        move_rows(p, velocity, irregular, 1.0 / 60.0)
        moved = position.copy()
        moved[:40] += velocity[:40] * (1.0 / 60.0)
        assert np.array_equal(p, moved)
        assert np.array_equal(a[:40], age[:40] + 1.0 / 60.0) and np.array_equal(a[40:], age[40:])
