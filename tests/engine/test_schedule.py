import pytest

from engine.schedule import FixedClock, Schedule, ScheduleError, Stage


def noop(world, dt):
    pass


def names(schedule, stage=Stage.SIMULATION):
    return [s.name for s in schedule.stage(stage)]


def test_ties_broken_by_registration_order():
    s = Schedule()
    for n in ("c", "a", "b"):
        s.add(noop, Stage.SIMULATION, name=n)
    assert names(s) == ["c", "a", "b"]


def test_before_and_after_constraints():
    s = Schedule()
    s.add(noop, Stage.SIMULATION, name="render_prep", after=("physics",))
    s.add(noop, Stage.SIMULATION, name="physics")
    s.add(noop, Stage.SIMULATION, name="input_map", before=("physics",))
    assert names(s) == ["input_map", "physics", "render_prep"]


def test_cycle_names_the_systems():
    s = Schedule()
    s.add(noop, Stage.SIMULATION, name="a", after=("c",))
    s.add(noop, Stage.SIMULATION, name="b", after=("a",))
    s.add(noop, Stage.SIMULATION, name="c", after=("b",))
    s.add(noop, Stage.SIMULATION, name="free")
    with pytest.raises(ScheduleError) as err:
        s.stage(Stage.SIMULATION)
    msg = str(err.value)
    assert "cycle" in msg and all(n in msg for n in ("a", "b", "c")) and "free" not in msg


def test_stages_in_fixed_order_and_duplicate_names():
    s = Schedule()
    s.add(noop, Stage.RENDER, name="draw")
    s.add(noop, Stage.STARTUP, name="boot")
    order = s.order()
    assert [st for st, _ in order] == list(Stage)
    with pytest.raises(ScheduleError, match="already registered"):
        s.add(noop, Stage.INPUT, name="draw")


def test_fixed_clock_accumulates_and_caps_catch_up():
    clock = FixedClock(dt=0.01, max_steps=3)
    assert clock.advance(0.025) == 2
    assert clock.alpha == pytest.approx(0.5)  # half a step left over: how far the frame is into the next tick
    assert clock.advance(0.004) == 0
    assert clock.advance(0.001) == 1  # 0.005 + 0.004 + 0.001 reaches one step
    assert clock.advance(1.0) == 3  # a long stall runs at most 3 steps
    assert clock.dropped_time > 0.9
    assert 0.0 <= clock.alpha < 1.0
