"""``python -m engine run`` and ``graph``: headless or windowed runs, hashes, recordings, pictures."""

from __future__ import annotations

import argparse
import logging
import os
import sys
from pathlib import Path

from engine.app import App
from engine.builtin import InputSource
from engine.input import InputRecorder, InputReplay

log = logging.getLogger("engine.run")
MAX_REPLAY_TICKS = 10**9  # a replay header asking for more is a broken file, not a run to start
DEFAULT_HEADLESS_STEPS = 300


def has_display() -> bool:
    return bool(os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY"))


def attach_input_source(app: App, record: Path | None, replay: Path | InputReplay | None) -> InputSource | None:
    recorder = InputRecorder({"scene": str(app.scene_path), "seed": app.seed}) if record else None
    replayer = replay if isinstance(replay, InputReplay) or replay is None else InputReplay(replay)
    if recorder is None and replayer is None:
        return None
    source = InputSource(recorder, replayer)
    app.world.insert_resource(source)
    return source


def run_command(args: argparse.Namespace) -> int:
    every = getattr(args, "screenshot_every", None)
    if every and not (every[0].isdigit() and int(every[0]) >= 1):
        print(f"error: --screenshot-every N DIR: N must be a whole number of frames >= 1, got {every[0]!r}",
              file=sys.stderr)
        return 1
    seed, replay = args.seed, None
    if args.replay:
        try:
            replay = InputReplay(args.replay)
            seed = replay_seed(args.replay, replay.meta, args.seed)
        except (OSError, ValueError) as exc:
            print(f"error: {exc}", file=sys.stderr)
            return 1
        recorded = replay.meta.get("scene")
        if isinstance(recorded, str) and Path(recorded).name != Path(args.scene).name:
            log.warning("%s was recorded in %s, not %s: the replay will not reproduce that run", args.replay,
                        recorded, args.scene)
    app = App(args.scene, registry=_plugin_registry(args), seed=seed, strict=args.strict)
    if args.print_schedule:
        print(app.schedule.describe(app.clock.dt))
        return 0
    try:
        source = attach_input_source(app, args.record, replay)
    except (OSError, ValueError) as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 1
    steps = args.steps
    if source is not None and source.replay is not None and steps is None:
        ticks = source.replay.meta.get("ticks", 0)
        if isinstance(ticks, bool) or not isinstance(ticks, int) or not 0 <= ticks <= MAX_REPLAY_TICKS:
            print(f"error: {args.replay}:1: ticks: expected an integer in [0, {MAX_REPLAY_TICKS}], got {ticks!r}",
                  file=sys.stderr)
            return 1
        steps = ticks
    if args.no_render:
        app.step(steps if steps is not None else DEFAULT_HEADLESS_STEPS)
    else:
        from engine.render.frontend import run_rendered

        run_rendered(app, args, steps)
    if source is not None and source.recorder is not None:
        source.recorder.save(args.record, app.world.tick)
        log.info("recorded %d ticks of input to %s", app.world.tick, args.record)
    if args.hash:
        print(app.state_hash())
    return 0


def _plugin_registry(args: argparse.Namespace):
    """The registry of the scene's plugins and the ``--plugin`` ones; None without ``--plugin`` (App builds it)."""
    from engine.plugin_option import load_plugins, scene_registry

    return scene_registry(args.scene, load_plugins(getattr(args, "plugin", None)))


def replay_seed(path: Path, meta: dict, asked: int | None) -> int | None:
    """The seed a replay runs with: the recording's (its header's ``seed``), so that it reproduces the recorded
    run; ``--seed`` may repeat it but not contradict it (the run would not be the one recorded)."""
    from engine.app import MAX_SEED

    if "seed" not in meta:
        return asked
    seed = meta["seed"]
    if isinstance(seed, bool) or not isinstance(seed, int) or not 0 <= seed <= MAX_SEED:
        raise ValueError(f"{path}:1: seed: expected an integer in [0, {MAX_SEED}], got {seed!r}")
    if asked is not None and asked != seed:
        raise ValueError(f"{path}:1: the recording was made with seed {seed}, not --seed {asked}; leave --seed out "
                         "to replay it")
    return seed


def graph_command(args: argparse.Namespace) -> int:
    from engine.render.frontend import compiled_graph_dot

    text = compiled_graph_dot(args.scene, dot=args.dot, registry=_plugin_registry(args))
    if args.out:
        args.out.write_text(text, encoding="utf-8")
    else:
        print(text)
    return 0
