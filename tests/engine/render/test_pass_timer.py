"""PassTimer's modes: a finish after every pass (CPU time), and ``waits`` (no finish; the time the main thread
spends blocked in each pass)."""

from __future__ import annotations

import time

from engine.render.renderer import PassTimer


class _Ctx:
    def __init__(self) -> None:
        self.finishes = 0

    def finish(self) -> None:
        self.finishes += 1


def test_waits_mode_records_blocked_time_per_pass_without_finishing():
    ctx = _Ctx()
    timer = PassTimer(ctx)
    timer.enabled, timer.gpu, timer.waits = True, False, True
    blocked = timer.wrap("blocked", lambda pc: time.sleep(0.02))  # asleep: blocked, like a wait in the driver
    busy = timer.wrap("busy", lambda pc: sum(range(20000)))
    for _ in range(2):
        blocked(None)
        busy(None)
        timer.frames += 1
    assert ctx.finishes == 0  # no finish between passes: that would hide the waits
    assert timer.wait_totals["blocked"] >= 2 * 15.0
    assert timer.wait_totals["blocked"] <= timer.totals["blocked"]
    assert timer.wait_totals["busy"] < timer.wait_totals["blocked"]
    report = timer.report_waits(top=1).splitlines()
    assert report[1].split()[0] == "blocked" and len(report) == 3  # the longest wait first, then the sums
    assert report[-1].split()[:2] == ["every", "pass"]


def test_cpu_mode_finishes_after_every_pass():
    ctx = _Ctx()
    timer = PassTimer(ctx)
    timer.enabled, timer.gpu = True, False
    timer.wrap("a", lambda pc: None)(None)
    timer.wrap("b", lambda pc: None)(None)
    assert ctx.finishes == 2 and set(timer.totals) == {"a", "b"} and not timer.wait_totals


class _Query:
    elapsed = 1_000_000

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        return False


class _QueryCtx(_Ctx):
    def __init__(self) -> None:
        super().__init__()
        self.queries = 0

    def query(self, time: bool = False):
        self.queries += 1
        return _Query()


def test_gpu_mode_reuses_one_timer_query_per_pass():
    """moderngl cannot release a query: one made per pass and frame grew memory by megabytes a minute with the
    profiler on."""
    ctx = _QueryCtx()
    timer = PassTimer(ctx)
    timer.enabled, timer.gpu = True, True
    passes = [timer.wrap(name, lambda pc: None) for name in ("terrain", "sky")]
    for _ in range(5):
        for execute in passes:
            execute(None)
    assert ctx.queries == 2 and timer.totals == {"terrain": 5.0, "sky": 5.0}
