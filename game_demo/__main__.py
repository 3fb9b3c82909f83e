"""``python -m game_demo [--headless] [--autoplay] [--seed S]``: play the demo, or watch it play itself.

With a display it opens the window.  Without one (or with ``--headless``) it runs the autoplay headless,
writes screenshots to ``out/demo/`` and says so.  ``--autoplay`` exits 0 on the win screen (1 otherwise)
and prints the final state hash last.
"""

from __future__ import annotations

import argparse
import logging
import sys
from pathlib import Path

from engine.app import App
from engine.config import ConfigError

SCENE = Path(__file__).resolve().parents[1] / "configs" / "scenes" / "demo.toml"
log = logging.getLogger("game_demo")


def _positive(text: str) -> int:
    value = int(text)
    if value < 1:
        raise argparse.ArgumentTypeError(f"must be a positive number of ticks, got {value}")
    return value


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m game_demo", description=__doc__.splitlines()[0])
    parser.add_argument("--headless", action="store_true", help="render offscreen with EGL")
    parser.add_argument("--autoplay", action="store_true", help="a scripted player plays to the win screen")
    parser.add_argument("--seed", type=int, default=None)
    parser.add_argument("--scene", type=Path, default=SCENE)
    parser.add_argument("--max-seconds", type=float, default=240.0, help="give up after this much game time")
    parser.add_argument("--screenshots", type=Path, default=Path("out/demo"), help="headless screenshot folder")
    parser.add_argument("--screenshot-every", type=_positive, default=300, help="ticks between headless screenshots")
    parser.add_argument("--no-render", action="store_true", help="autoplay without any rendering (fastest)")
    parser.add_argument("--size", nargs=2, type=int, default=None, metavar=("W", "H"))
    args = parser.parse_args(argv)
    logging.basicConfig(level=logging.INFO, format="%(levelname)s %(name)s: %(message)s")
    from engine.render.frontend import has_display

    try:
        app = App(args.scene, seed=args.seed)
    except ConfigError as exc:
        print(exc, file=sys.stderr)
        return 1
    from engine.render.frontend import ContextError

    try:
        if not args.headless and not args.no_render and has_display():
            return play_window(app, args)
        if not args.autoplay:
            log.info("no display: running the autoplay headless, screenshots go to %s", args.screenshots)
        return autoplay(app, args)
    except ContextError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 1


def autoplay(app: App, args: argparse.Namespace) -> int:
    from game_demo.autoplay import AutoPilot
    from game_demo.scripts.common import GameState

    size = tuple(args.size) if args.size else (app.config.render.width, app.config.render.height)
    if args.size and args.no_render:  # no renderer: the scene's size is the window the pilot and picking use
        app.config.render = app.config.render.model_copy(update={"width": size[0], "height": size[1]})
    pilot = AutoPilot()  # mouse positions in the engine's window: the renderer's size, or the scene's without one
    app.pre_tick.append(pilot)
    renderer = None
    if not args.no_render:
        from engine.render.frontend import headless_renderer

        renderer = headless_renderer(app, *size)
    max_ticks = int(args.max_seconds / app.dt)
    shots = 0
    state = None
    for tick in range(1, max_ticks + 1):
        app.step(1)
        state = app.world.try_resource(GameState)
        done = state is not None and state.phase != "playing"
        if renderer is not None and (tick % args.screenshot_every == 0 or done):
            renderer.reset_frame_clock()  # frames hundreds of ticks apart: no frame rate to show
            app.render_frame()
            renderer.save_screenshot(args.screenshots / f"frame_{tick:05d}.png")
            shots += 1
        if done:
            break
    phase = state.phase if state else "no game state"
    log.info("autoplay finished: %s after %.1f s of game time (%d shots fired, %d drags)", phase,
             app.world.tick * app.dt, pilot.shots, pilot.drags)
    if renderer is not None:
        log.info("wrote %d screenshot(s) to %s", shots, args.screenshots)
        renderer.release()
    print(app.state_hash())
    return 0 if phase == "won" else 1


def play_window(app: App, args: argparse.Namespace) -> int:
    from engine.render.frontend import _run_window

    if args.autoplay:
        from game_demo.autoplay import AutoPilot

        app.pre_tick.append(AutoPilot())
    size = tuple(args.size) if args.size else (app.config.render.width, app.config.render.height)
    _run_window(app, size, None, None, None, False)
    return 0


if __name__ == "__main__":
    sys.exit(main())
