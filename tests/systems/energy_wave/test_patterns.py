"""Pattern assignment (section 3.2, eqs. 3.1 and 3.6) and the sprite layouts of eqs. 3.7–3.9."""

import numpy as np
import pytest

from components.energy_wave import PATTERN_PARAMETERS, PATTERNS, EnergyWaveEmitter
from systems.energy_wave import set_pattern
from systems.energy_wave.simulate import (assign_patterns, bar_offsets, bar_sizes, trail_fractions, trail_sizes)

from .helpers import add_box, add_emitter, make_app, state


def _hits(seed=3, ticks=40, **fields):
    """Cumulative hits per pattern of a dense beam fired at a wall 1 m away."""
    app = make_app(seed)
    add_box(app, (0.0, 0.0, -1.2), (2.0, 2.0, 0.2))
    entity, _, st = add_emitter(app, emission_rate=6000.0, max_particles=20_000, beam_speed=10.0, **fields)
    app.step(ticks)
    return st.hits_per_pattern.copy(), app, entity


def _within_binomial(successes, trials, p, sigmas=4.0):
    sd = np.sqrt(max(p * (1.0 - p), 1e-12) / trials)
    return abs(successes / trials - p) <= sigmas * sd + 1e-12


@pytest.mark.parametrize("alpha,beta", [(0.5, 0.3), (0.8, 0.6)])
def test_pattern_shares_match_alpha_and_beta(alpha, beta):
    hits, _, _ = _hits(circular_probability=alpha, continuity_probability=beta)
    total = hits.sum()
    assert total > 2000
    circular = hits[0::2].sum()  # A, C, E, G
    continuous = hits[0] + hits[1]  # A, B
    assert _within_binomial(circular, total, alpha), (circular / total, alpha)
    assert _within_binomial(continuous, total, beta), (continuous / total, beta)
    # Independence: the share of A is α·β.
    assert _within_binomial(hits[0], total, alpha * beta)


def test_assign_patterns_is_exactly_the_paper_table():
    u_circ = np.array([0.1, 0.9, 0.1, 0.9])
    u_cont = np.array([0.1, 0.1, 0.9, 0.9])
    # α = β = 0.5: circular+continuous, irregular+continuous, circular+separated, irregular+separated
    assert [PATTERNS[p] for p in assign_patterns(u_circ, u_cont, 0.5, 0.5, 1, 0.5)] == ["A", "B", "C", "D"]
    assert [PATTERNS[p] for p in assign_patterns(u_circ, u_cont, 0.5, 0.5, 12, 1.0)] == ["A", "B", "E", "F"]
    assert [PATTERNS[p] for p in assign_patterns(u_circ, u_cont, 0.5, 0.5, 12, 0.1)] == ["A", "B", "G", "H"]
    # α = 1 and β = 0 are certain; α = 0 never circular.
    assert set(assign_patterns(u_circ, u_cont, 1.0, 0.0, 1, 0.5)) == {2}
    assert set(assign_patterns(u_circ, u_cont, 0.0, 1.0, 1, 0.5)) == {1}


def test_n_equal_1_gives_grains_only():
    hits, _, _ = _hits(circular_probability=0.5, continuity_probability=0.3, splash_samples=1, ticks=25)
    assert hits[4:].sum() == 0  # no bars (E-H)
    assert hits[2] > 0 and hits[3] > 0  # grains of both global shapes (C, D)


@pytest.mark.parametrize("pattern", PATTERNS)
def test_set_pattern_makes_every_hit_that_pattern(pattern):
    app = make_app(5)
    add_box(app, (0.0, 0.0, -0.8), (2.0, 2.0, 0.2))
    entity, _, _ = add_emitter(app, emission_rate=3000.0, beam_speed=10.0)
    set_pattern(app.world, entity, pattern)
    app.step(12)
    hits = state(app, entity).hits_per_pattern
    assert hits.sum() > 100
    assert hits[PATTERNS.index(pattern)] == hits.sum()
    cfg = app.world.get(entity, EnergyWaveEmitter)
    for key, value in PATTERN_PARAMETERS[pattern].items():
        assert getattr(cfg, key) == value


def test_bar_tip_sizes_eq_3_9():
    # t = 1: every sprite of the bar has the size S (round tips)
    np.testing.assert_allclose(bar_sizes(12, 1.0), np.ones(12))
    # t -> 0: sizes shrink linearly to the tip, S_N/S = (N - (N-1)(1-t))/N
    for n, t in [(12, 0.1), (24, 0.01), (5, 0.5)]:
        sizes = bar_sizes(n, t)
        assert sizes[0] == 1.0
        assert np.all(np.diff(sizes) < 0)
        assert sizes[-1] == pytest.approx((n - (n - 1) * (1 - t)) / n)
    assert bar_sizes(24, 0.01)[-1] < 0.06  # sharp
    assert bar_sizes(1, 0.1).tolist() == [1.0]  # a grain


def test_bar_positions_eq_3_8():
    # U_j = Q + (-1)^j u (j-1) d: alternating sides, growing distance
    np.testing.assert_allclose(bar_offsets(5, 0.4), [0.0, 0.4, -0.8, 1.2, -1.6])
    assert bar_offsets(1, 0.4).tolist() == [0.0]


def test_trail_positions_eq_3_7():
    # T_i = P0 + (P1 - P0)(i - 1)/M
    np.testing.assert_allclose(trail_fractions(4), [0.0, 0.25, 0.5, 0.75])
    sizes = trail_sizes(5, 0.3)
    assert sizes[0] == 1.0 and sizes[-1] == pytest.approx(0.3) and np.all(np.diff(sizes) < 0)
