"""Ticks overlapped with drawing: RenderGraph.execute(on_sync), Renderer.draw(overlap), App.render_frame(overlap).

The next ticks run while the GPU (here llvmpipe's threads) draws the frame; the pictures and the state must be
exactly those of ticking after each frame.
"""

from __future__ import annotations

import numpy as np

from engine.app import App
from engine.render.graph import PassBuilder, RenderGraph, ResourcePool, TextureDesc
from engine.render.passes import HudFeature
from tests.render_utils import make_renderer, render_app

COLOR = TextureDesc(16, 16, "rgba8")


def _graph_with(log: list[str], reads_earlier_output: bool) -> RenderGraph:
    """scene -> hdr, [sky: hdr again], present: hdr -> screen; or, with no reads, two passes that each write
    their own imported target."""
    graph = RenderGraph(ResourcePool(lambda desc: object()))
    screen = graph.import_resource("screen", object(), COLOR)
    out = {}
    if reads_earlier_output:
        def scene(b: PassBuilder) -> None:
            out["hdr"] = b.write(b.create("hdr", COLOR))

        def sky(b: PassBuilder) -> None:  # writes the same target again: not a read of an earlier output
            out["hdr"] = b.write(out["hdr"])

        def present(b: PassBuilder) -> None:
            b.read(out["hdr"])
            b.write(screen)

        graph.add_pass("scene", scene, lambda pc: log.append("scene"))
        graph.add_pass("sky", sky, lambda pc: log.append("sky"))
    else:
        other = graph.import_resource("other", object(), COLOR)
        graph.add_pass("scene", lambda b: b.write(other), lambda pc: log.append("scene"))

        def present(b: PassBuilder) -> None:
            b.write(screen)

    graph.add_pass("present", present, lambda pc: log.append("present"))
    return graph


def test_on_sync_runs_once_just_before_the_first_pass_that_reads_an_earlier_output():
    log: list[str] = []
    graph = _graph_with(log, reads_earlier_output=True)
    graph.execute(on_sync=lambda: log.append("SYNC"))
    assert log == ["scene", "sky", "SYNC", "present"]
    assert graph.compile().sync_pass == "present"


def test_on_sync_runs_after_the_last_pass_when_nothing_reads_an_earlier_output():
    log: list[str] = []
    graph = _graph_with(log, reads_earlier_output=False)
    graph.execute(on_sync=lambda: log.append("SYNC"))
    assert log == ["scene", "present", "SYNC"]
    assert graph.compile().sync_pass is None


def test_a_read_that_need_not_wait_does_not_move_the_sync_point():
    """A shadow map: a small pass writes it, the opaque passes sample it on the GPU; the CPU need not wait there,
    so the ticks still overlap the whole opaque work (PassBuilder.read(wait=False))."""
    for wait, expected in ((True, "scene"), (False, "present")):
        log: list[str] = []
        graph = RenderGraph(ResourcePool(lambda desc: object()))
        shadow = graph.import_resource("shadow_map", object(), COLOR)
        screen = graph.import_resource("screen", object(), COLOR)
        out = {}

        def draw_shadow(b: PassBuilder) -> None:
            out["shadow"] = b.write(shadow)

        def scene(b: PassBuilder) -> None:
            b.read(out["shadow"], wait=wait)
            out["hdr"] = b.write(b.create("hdr", COLOR))

        def present(b: PassBuilder) -> None:
            b.read(out["hdr"])
            b.write(screen)

        graph.add_pass("shadow", draw_shadow, lambda pc: log.append("shadow"))
        graph.add_pass("scene", scene, lambda pc: log.append("scene"))
        graph.add_pass("present", present, lambda pc: log.append("present"))
        graph.execute(on_sync=lambda: log.append("SYNC"))
        assert graph.compile().sync_pass == expected
        assert log.index("SYNC") == log.index(expected) - 1


def test_render_frame_without_a_renderer_still_runs_the_overlapped_ticks():
    app = App("configs/scenes/sandbox.toml", seed=3)
    app.render_frame(overlap=lambda: app.step(2))
    assert app.world.tick == 2


def test_overlapped_ticks_draw_the_same_pictures_and_reach_the_same_state(monkeypatch):
    """The demo (every effect, two views, scripts, an autopilot firing): frame N shows tick N either way, to
    the byte, and the state hash after the run is the same."""
    from game_demo.autoplay import AutoPilot

    monkeypatch.setattr(HudFeature, "_fps_line", lambda self: "FPS  60.0")  # the measured rate is not state
    runs = {}
    for overlapped in (False, True):
        app = App("configs/scenes/demo.toml")
        app.pre_tick.append(AutoPilot(window=(160, 96)))
        renderer = make_renderer(app, 160, 96)
        order: list[str] = []
        wrap = renderer.timer.wrap
        renderer.timer.wrap = lambda name, execute: wrap(name, lambda pc: (order.append(name), execute(pc)))
        app.step(40)  # into the action: beams flying, the dust devil moving
        pictures = []
        try:
            if overlapped:
                app.step(1)
            app.pre_tick.append(lambda app: order.append("tick"))
            for frame in range(6):
                if overlapped:
                    app.render_frame(overlap=(lambda: app.step(1)) if frame < 5 else None)
                else:
                    app.step(1)
                    app.render_frame()
                pictures.append(np.asarray(renderer.read_image()))
        finally:
            renderer.release()
            app.renderer = None
        runs[overlapped] = (pictures, app.state_hash(), app.world.tick)
        if overlapped:  # the ticks ran inside the frames, before the pass that first waits for the GPU
            sync = renderer.graph.compile().sync_pass
            frames = " ".join(order).split(" hud")[:-1]  # the HUD is each frame's last pass
            assert sync is not None and len(frames) == 6
            for frame in frames[:5]:
                assert f"tick {sync}" in frame, frame
    (plain, plain_hash, plain_tick), (over, over_hash, over_tick) = runs[False], runs[True]
    assert plain_tick == over_tick == 46 and plain_hash == over_hash
    for a, b in zip(plain, over):
        assert np.array_equal(a, b)
    assert not np.array_equal(plain[0], plain[-1])  # the frames did change: the comparison means something


def _picture_at(tick: int, scene: str) -> np.ndarray:
    return np.asarray(render_app(App(scene), 96, 64, frames=1, steps_per_frame=tick))


def test_advance_overlapped_shows_the_state_before_its_ticks_and_plain_advance_the_state_after():
    scene = "configs/scenes/energy_wave_showcase.toml"  # beams in flight: every tick changes the picture
    before, after = _picture_at(30, scene), _picture_at(32, scene)
    assert not np.array_equal(before, after)
    for overlap_ticks, expected in ((True, before), (False, after)):
        app = App(scene)
        app.config.render.overlap_ticks = overlap_ticks
        renderer = make_renderer(app, 96, 64)
        try:
            app.step(30)
            assert app.advance(2.5 * app.dt) == 2
            assert app.world.tick == 32
            assert np.array_equal(np.asarray(renderer.read_image()), expected)
        finally:
            renderer.release()
            app.renderer = None
