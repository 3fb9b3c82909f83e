"""Render graph: validation, ordering, culling, lifetimes, pooling, compile cache, Graphviz output.

No GL: the pool's factory makes stand-in objects, and imported resources are plain objects.
"""

from __future__ import annotations

import dataclasses
import re
from collections.abc import Callable

import pytest

from engine.render.graph import (
    BufferDesc,
    GraphError,
    PassBuilder,
    PassContext,
    RenderGraph,
    ResourceHandle,
    ResourcePool,
    TextureDesc,
)

COLOR = TextureDesc(64, 64, "rgba16f")
SMALL = TextureDesc(32, 32, "rgba16f")


class FakeResource:
    """Stands in for a GL texture or buffer."""

    def __init__(self, desc: object, serial: int = 0) -> None:
        self.desc = desc
        self.id = serial

    def __repr__(self) -> str:
        return f"FakeResource#{self.id}({self.desc})"


class LoggingPool(ResourcePool):
    """A pool that records acquire/release events in a shared log."""

    def __init__(self, log: list[str]) -> None:
        super().__init__(self._make, destroy=lambda obj: log.append(f"destroy {obj.id}"))
        self.log = log

    def _make(self, desc: object) -> FakeResource:
        return FakeResource(desc, serial=self.allocations + 1)  # numbered 1, 2, ... per pool

    def acquire(self, desc: object) -> object:
        obj = super().acquire(desc)
        self.log.append(f"acquire {obj.id}")
        return obj

    def release(self, desc: object, obj: object) -> None:
        self.log.append(f"release {obj.id}")
        super().release(desc, obj)


def noop(ctx: PassContext) -> None:
    pass


def producer(graph: RenderGraph, name: str, output: str, desc: object = COLOR,
             inputs: tuple[str, ...] = (), side_effect: bool = False, log: list[str] | None = None) -> None:
    """A pass that reads ``inputs`` by name and creates and writes ``output``."""

    def setup(builder: PassBuilder) -> None:
        for source in inputs:
            builder.read(source)
        builder.write(builder.create(output, desc))

    graph.add_pass(name, setup, _logger(name, log), side_effect=side_effect)


def consumer(graph: RenderGraph, name: str, inputs: tuple[str, ...], log: list[str] | None = None) -> None:
    """A side-effect pass that only reads (a screenshot, a readback)."""
    graph.add_pass(name, lambda b: [b.read(source) for source in inputs], _logger(name, log), side_effect=True)


def _logger(name: str, log: list[str] | None) -> Callable[[PassContext], None]:
    def execute(ctx: PassContext) -> None:
        if log is not None:
            log.append(f"run {name}")

    return execute


def present_pass(graph: RenderGraph, name: str, inputs: tuple[str, ...], screen: object = None,
                 log: list[str] | None = None) -> None:
    """Reads ``inputs`` and writes an imported screen: never culled."""
    target = graph.import_resource("screen", screen or object(), TextureDesc(640, 480))

    def setup(builder: PassBuilder) -> None:
        for source in inputs:
            builder.read(source)
        builder.write(target)

    graph.add_pass(name, setup, _logger(name, log))


# -- culling ---------------------------------------------------------------------------------


def test_unused_pass_is_culled_and_never_runs_or_allocates() -> None:
    log: list[str] = []
    pool = ResourcePool(FakeResource)
    graph = RenderGraph(pool)
    producer(graph, "shadow", "shadow_map", log=log)          # nobody reads it
    producer(graph, "blur_input", "blur_src", log=log)        # read only by an unused pass:
    producer(graph, "blur", "blurred", inputs=("blur_src",), log=log)  # culled in turn
    producer(graph, "scene", "hdr", log=log)
    present_pass(graph, "present", ("hdr",), log=log)

    compiled = graph.compile()
    assert compiled.culled == ["shadow", "blur_input", "blur"]
    assert compiled.order == ["scene", "present"]
    graph.execute()
    assert log == ["run scene", "run present"]
    assert pool.allocations == 1
    assert "shadow_map" not in compiled.lifetimes and "blur_src" not in compiled.lifetimes


def test_pass_writing_nothing_observable_is_culled_without_side_effect() -> None:
    graph = RenderGraph()
    producer(graph, "scene", "hdr")
    graph.add_pass("inspect", lambda b: b.read("hdr"), noop)  # reads, writes nothing, no side effect
    assert graph.compile().culled == ["scene", "inspect"]
    assert graph.compile().order == []


def test_side_effect_pass_survives_and_its_inputs_live_until_it_runs() -> None:
    log: list[str] = []
    graph = RenderGraph(LoggingPool(log))
    producer(graph, "scene", "hdr", log=log)
    producer(graph, "tonemap", "ldr", inputs=("hdr",), log=log)  # output unread: culled
    consumer(graph, "capture", ("hdr",), log=log)                 # side effect: kept

    compiled = graph.compile()
    assert compiled.order == ["scene", "capture"]
    assert compiled.culled == ["tonemap"]
    assert compiled.lifetimes["hdr"] == (0, 1)
    graph.execute()
    hdr = log[0].split()[1]
    assert log == [f"acquire {hdr}", "run scene", "run capture", f"release {hdr}"]
    assert graph.pool.live_count == 0 and graph.pool.free_count == 1


def test_writing_an_imported_resource_keeps_the_pass() -> None:
    graph = RenderGraph()
    atlas = graph.import_resource("impostor_atlas", object(), TextureDesc(1024, 1024))
    graph.add_pass("bake_impostors", lambda b: b.write(atlas), noop)
    assert graph.compile().order == ["bake_impostors"]


# -- handles and validation -------------------------------------------------------------------


def test_handle_from_previous_frame_is_stale() -> None:
    graph = RenderGraph()
    old = graph.import_resource("height_field", object(), TextureDesc(8, 8, "r32f"))
    graph.reset()
    graph.import_resource("height_field", object(), TextureDesc(8, 8, "r32f"))
    with pytest.raises(GraphError, match=r"pass 'water' reads a stale handle to 'height_field'.*earlier frame"):
        graph.add_pass("water", lambda b: b.read(old), noop)


def test_handle_from_another_graph_is_stale() -> None:
    other = RenderGraph().import_resource("atlas", object())
    graph = RenderGraph()
    graph.import_resource("atlas", object())
    with pytest.raises(GraphError, match=r"pass 'grass' writes a stale handle to 'atlas'"):
        graph.add_pass("grass", lambda b: b.write(other), noop)


def test_old_version_read_after_a_later_write_is_stale() -> None:
    graph = RenderGraph()
    handles: dict[str, ResourceHandle] = {}

    def first(builder: PassBuilder) -> None:
        handles["v1"] = builder.write(builder.create("gbuffer", COLOR))

    graph.add_pass("geometry", first, noop)
    graph.add_pass("decals", lambda b: b.write(handles["v1"]), noop)
    assert handles["v1"].version == 1
    with pytest.raises(GraphError, match=r"pass 'lighting' reads a stale handle to 'gbuffer' \(version 1\): "
                                         r"pass 'decals' has since written it \(now version 2\)"):
        graph.add_pass("lighting", lambda b: b.read(handles["v1"]), noop)


def test_unknown_resource_is_rejected_with_suggestion() -> None:
    graph = RenderGraph()
    screen = graph.import_resource("screen", object())
    forged = dataclasses.replace(screen, index=42, name="shadows")
    with pytest.raises(GraphError, match=r"pass 'a' reads unknown resource 'shadows'"):
        graph.add_pass("a", lambda b: b.read(forged), noop)

    producer(graph, "scene", "gbuffer")
    graph.add_pass("lighting", lambda b: (b.read("gbufer"), b.write(screen)), noop)
    with pytest.raises(GraphError, match=r"pass 'lighting' reads unknown resource 'gbufer', did you mean 'gbuffer'\?"):
        graph.compile()


def test_failed_setup_leaves_no_half_declared_pass() -> None:
    graph = RenderGraph()

    def broken(builder: PassBuilder) -> None:
        builder.create("scratch", COLOR)
        raise RuntimeError("setup bug")

    with pytest.raises(RuntimeError):
        graph.add_pass("broken", broken, noop)
    producer(graph, "fixed", "scratch")  # the name is free again
    assert graph.compile().culled == ["fixed"]


def test_missing_input_names_pass_and_resource() -> None:
    graph = RenderGraph()
    made: dict[str, ResourceHandle] = {}
    graph.add_pass("alloc", lambda b: made.setdefault("h", b.create("velocity", COLOR)), noop)
    graph.add_pass("motion_blur", lambda b: b.read(made["h"]), noop, side_effect=True)
    with pytest.raises(GraphError, match=r"pass 'motion_blur' reads 'velocity' \(version 0\), but no pass writes "
                                         r"it and it is not imported \(created by pass 'alloc'\)"):
        graph.compile()


def test_pass_reading_and_writing_one_version_is_rejected() -> None:
    graph = RenderGraph()
    made: dict[str, ResourceHandle] = {}
    graph.add_pass("scene", lambda b: made.setdefault("hdr", b.write(b.create("hdr", COLOR))), noop)

    def setup(builder: PassBuilder) -> None:
        builder.write(builder.read(made["hdr"]))  # blur in place: sample and render one texture

    graph.add_pass("bloom", setup, noop, side_effect=True)
    with pytest.raises(GraphError, match=r"pass 'bloom' reads and writes 'hdr' \(version 1\)"):
        graph.compile()


def test_two_writers_without_order_are_rejected() -> None:
    graph = RenderGraph()
    target = graph.import_resource("height_field", object(), TextureDesc(16, 16, "r32f"))
    graph.add_pass("rain", lambda b: b.write(target), noop)
    graph.add_pass("wake", lambda b: b.write(target), noop)
    with pytest.raises(GraphError, match=r"passes 'rain' and 'wake' all write 'height_field' version 0 "
                                         r"with no order between them"):
        graph.compile()


def test_cycle_is_listed_in_the_message() -> None:
    graph = RenderGraph()
    out: dict[str, ResourceHandle] = {}

    def a(builder: PassBuilder) -> None:
        builder.read("b_out")  # by name: resolves to b's output at compile time
        out["a"] = builder.write(builder.create("a_out", COLOR))

    def b(builder: PassBuilder) -> None:
        builder.read(out["a"])
        builder.write(builder.create("b_out", COLOR))

    graph.add_pass("a", a, noop, side_effect=True)
    graph.add_pass("b", b, noop, side_effect=True)
    with pytest.raises(GraphError, match=r"cycle: a -> b -> a \(b reads 'a_out'; a reads 'b_out'\)"):
        graph.compile()


def test_undeclared_resource_in_execute_is_rejected() -> None:
    graph = RenderGraph(ResourcePool(FakeResource))
    producer(graph, "scene", "hdr")
    producer(graph, "other", "unrelated")
    graph.add_pass("peek", lambda b: b.read("hdr"), lambda ctx: ctx.get("unrelated"), side_effect=True)
    with pytest.raises(GraphError, match=r"pass 'peek' uses 'unrelated' without declaring it"):
        graph.execute()
    assert graph.pool.live_count == 0  # released although the pass raised


# -- ordering and lifetimes -------------------------------------------------------------------


def test_order_is_deterministic_and_consumer_declared_first_runs_after_producer() -> None:
    def build() -> RenderGraph:
        graph = RenderGraph()
        present_pass(graph, "composite", ("hdr", "ui"))  # declared before both producers
        producer(graph, "ui", "ui")
        producer(graph, "sky", "sky")
        producer(graph, "scene", "hdr", inputs=("sky",))
        return graph

    first, second = build().compile(), build().compile()
    assert first.order == ["ui", "sky", "scene", "composite"]
    assert second.order == first.order
    assert first.lifetimes == {"screen": (3, 3), "ui": (0, 3), "sky": (1, 2), "hdr": (2, 3)}


def test_overwriting_a_version_waits_for_its_readers() -> None:
    graph = RenderGraph()
    heights = graph.import_resource("height_field", object(), TextureDesc(16, 16, "r32f"))

    def draw_water(builder: PassBuilder) -> None:
        builder.read(heights)      # this frame's heights, before the step below overwrites them
        builder.read("reflection")  # produced by a pass declared later
        builder.write(graph.import_resource("screen", object()))

    graph.add_pass("draw_water", draw_water, noop)
    graph.add_pass("step_water", lambda b: b.write(heights), noop)  # ready first, yet must wait
    producer(graph, "reflect", "reflection")
    assert graph.compile().order == ["reflect", "draw_water", "step_water"]


def test_diamond_order_lifetimes_and_aliasing() -> None:
    log: list[str] = []
    graph = RenderGraph(LoggingPool(log))
    producer(graph, "A", "x", log=log)
    producer(graph, "C", "c", inputs=("x",), log=log)
    producer(graph, "B", "b", inputs=("x",), log=log)
    present_pass(graph, "D", ("b", "c"), log=log)
    producer(graph, "E", "e", log=log)
    consumer(graph, "F", ("e",), log=log)

    compiled = graph.compile()
    assert compiled.order == ["A", "C", "B", "D", "E", "F"]
    assert compiled.lifetimes == {"x": (0, 2), "c": (1, 3), "b": (2, 3), "screen": (3, 3), "e": (4, 5)}
    graph.execute()
    runs = [entry for entry in log if entry.startswith("run")]
    assert runs == ["run A", "run C", "run B", "run D", "run E", "run F"]
    # x is released after B (its last reader); e reuses a texture released after D
    assert log.index("release 1") == log.index("run B") + 1
    assert graph.pool.allocations == 3
    assert log[log.index("run E") - 1] in {"acquire 1", "acquire 2", "acquire 3"}


# -- pooling ----------------------------------------------------------------------------------


def _frame(graph: RenderGraph, descs: dict[str, TextureDesc], seen: dict[str, object], atlas: object) -> None:
    graph.reset()
    atlas_handle = graph.import_resource("atlas", atlas, TextureDesc(256, 256))
    for name, desc in descs.items():
        def setup(builder: PassBuilder, name: str = name, desc: TextureDesc = desc) -> None:
            builder.read(atlas_handle)
            builder.write(builder.create(name, desc))

        def execute(ctx: PassContext, name: str = name) -> None:
            seen[name] = ctx.get(name)
            seen["atlas"] = ctx.get(atlas_handle)

        graph.add_pass(f"draw_{name}", setup, execute)
    graph.add_pass("present", lambda b: [b.read(name) for name in descs], noop, side_effect=True)
    graph.execute()


def test_pool_reuses_only_matching_descriptors_across_frames_and_never_pools_imports() -> None:
    made: list[object] = []
    pool = ResourcePool(lambda desc: made.append(desc) or FakeResource(desc))
    graph = RenderGraph(pool)
    atlas = object()
    frame1: dict[str, object] = {}
    _frame(graph, {"color": COLOR, "bloom": SMALL}, frame1, atlas)
    assert pool.allocations == 2 and pool.free_count == 2 and pool.live_count == 0
    assert frame1["atlas"] is atlas

    frame2: dict[str, object] = {}
    _frame(graph, {"color": COLOR, "bloom": SMALL}, frame2, atlas)
    assert pool.allocations == 2
    assert frame2["color"] is frame1["color"] and frame2["bloom"] is frame1["bloom"]

    frame3: dict[str, object] = {}
    _frame(graph, {"color": COLOR, "bloom": TextureDesc(32, 32, "rgba8")}, frame3, atlas)
    assert pool.allocations == 3
    assert frame3["color"] is frame1["color"] and frame3["bloom"] is not frame1["bloom"]
    assert frame3["bloom"].desc == TextureDesc(32, 32, "rgba8")
    assert TextureDesc(256, 256) not in made  # the imported atlas never came from the pool
    assert pool.free_count == 3


def test_pool_trim_destroys_idle_objects_and_rejects_foreign_release() -> None:
    destroyed: list[object] = []
    pool = ResourcePool(FakeResource, destroy=destroyed.append)
    a, b = pool.acquire(COLOR), pool.acquire(BufferDesc(1024))
    pool.release(COLOR, a)
    pool.advance_frame()
    pool.release(BufferDesc(1024), b)
    pool.advance_frame()
    assert pool.trim(max_idle_frames=0) == 1 and destroyed == [a]
    assert pool.acquire(BufferDesc(1024)) is b
    with pytest.raises(GraphError, match="not in use from this pool"):
        pool.release(COLOR, a)


def test_graph_without_pool_explains_what_is_missing() -> None:
    graph = RenderGraph()
    producer(graph, "scene", "hdr")
    consumer(graph, "capture", ("hdr",))
    with pytest.raises(GraphError, match=r"pass 'scene' needs transient resource 'hdr'.*no pool"):
        graph.execute()


# -- compile cache ----------------------------------------------------------------------------


def _declare(graph: RenderGraph, with_bloom: bool, size: int = 64) -> None:
    graph.reset()
    producer(graph, "scene", "hdr", desc=TextureDesc(size, size, "rgba16f"))
    if with_bloom:
        producer(graph, "bloom", "bloom", inputs=("hdr",))
    present_pass(graph, "present", ("hdr", "bloom") if with_bloom else ("hdr",))


def test_recompiles_only_when_the_declared_structure_changes() -> None:
    graph = RenderGraph(ResourcePool(FakeResource))
    _declare(graph, with_bloom=False)
    first = graph.compile()
    assert graph.compile_count == 1
    for _ in range(3):  # same passes re-declared every frame (new imported screen object each time)
        _declare(graph, with_bloom=False)
        graph.execute()
        assert graph.compile() is first
    assert graph.compile_count == 1

    _declare(graph, with_bloom=True)
    assert graph.compile().order == ["scene", "bloom", "present"]
    assert graph.compile_count == 2
    _declare(graph, with_bloom=False)  # back to an earlier structure: cached
    assert graph.compile() is first and graph.compile_count == 2
    _declare(graph, with_bloom=False, size=128)  # a descriptor change is a structural change
    graph.compile()
    assert graph.compile_count == 3


# -- Graphviz ---------------------------------------------------------------------------------


def test_to_dot_draws_passes_as_boxes_resources_as_ellipses_and_culled_dashed() -> None:
    graph = RenderGraph()
    producer(graph, "shadow", "shadow_map")
    producer(graph, "scene", "hdr")
    present_pass(graph, "present", ("hdr",))
    dot = graph.to_dot()

    assert dot.startswith("digraph") and dot.rstrip().endswith("}")
    lines = dot.splitlines()
    node = {name: next(line for line in lines if line.strip().startswith(f'"pass:{name}" ['))
            for name in ("shadow", "scene", "present")}
    assert "shape=box" in node["shadow"] and "style=dashed" in node["shadow"]
    assert "style=dashed" not in node["scene"] and "style=dashed" not in node["present"]
    assert re.search(r'"res:hdr@1" \[shape=ellipse', dot)
    assert '"pass:scene" -> "res:hdr@1";' in dot
    assert '"res:hdr@1" -> "pass:present";' in dot
    assert '"pass:shadow" -> "res:shadow_map@1" [style=dashed];' in dot


# -- descriptors ------------------------------------------------------------------------------


def test_descriptors_validate_and_describe_themselves() -> None:
    assert TextureDesc(4, 4, "rgba16f").components == 4 and TextureDesc(4, 4, "rgba16f").dtype == "f2"
    assert TextureDesc(4, 4, "depth24").is_depth
    with pytest.raises(GraphError, match=r"unknown texture format 'rgba16'.*did you mean"):
        TextureDesc(4, 4, "rgba16")
    with pytest.raises(GraphError, match="positive"):
        TextureDesc(0, 4)
    with pytest.raises(GraphError, match="positive"):
        BufferDesc(-1)
