"""Command line: ``python -m engine run|validate|schema|docs|gallery|graph|warm``."""

from __future__ import annotations

import argparse
import json
import logging
import os
import sys
import traceback
from collections.abc import Sequence
from pathlib import Path

from engine.config import ConfigError, Problem, read_toml, validate
from engine.plugin_option import NamedPlugin, PluginOptionError, load_plugins, registry_with
from engine.registry import Registry, RegistryError, default_registry
from engine.script import ScriptError
from engine.state import StateHashError


def _int_in(low: int, high: int):
    """An argparse type: a whole number in [low, high] (argparse turns the ValueError into a usage error)."""

    def parse(text: str) -> int:
        value = int(text)
        if not low <= value <= high:
            raise ValueError(text)
        return value

    parse.__name__ = f"whole number in [{low}, {high}]"
    return parse


def _add_plugin_option(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--plugin", action="append", default=[], metavar="MODULE[:ATTR]",
                        help="also install this plugin, importable from the current directory (repeatable); "
                             "ATTR defaults to the module's 'plugin', else the one plugin it defines; a class is "
                             "instantiated (docs/extending.md)")


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m engine", description="ecsfx engine tools")
    sub = parser.add_subparsers(dest="command", required=True)

    run = sub.add_parser("run", help="run a scene")
    run.add_argument("scene")
    run.add_argument("--headless", action="store_true", help="force offscreen EGL rendering")
    run.add_argument("--no-render", action="store_true", help="simulate only, no GL at all")
    run.add_argument("--steps", type=_int_in(0, 10**9), default=None, help="run exactly N fixed ticks, then exit")
    run.add_argument("--seed", type=_int_in(0, 2**63 - 1), default=None)
    run.add_argument("--hash", action="store_true", help="print the final state hash as the last line")
    run.add_argument("--record", type=Path, help="record per-tick input to FILE")
    run.add_argument("--replay", type=Path, help="replay per-tick input from FILE")
    run.add_argument("--print-schedule", action="store_true", help="print the system order and exit")
    run.add_argument("--strict", action="store_true", help="re-raise script errors")
    run.add_argument("--screenshot", type=Path, help="write the last frame to PATH (PNG)")
    run.add_argument("--screenshot-every", nargs=2, metavar=("N", "DIR"), help="write every N-th frame to DIR")
    run.add_argument("--profile", action="store_true", help="print per-pass timings at exit")
    run.add_argument("--size", nargs=2, type=_int_in(16, 8192), metavar=("W", "H"), help="override the render size")
    _add_plugin_option(run)

    val = sub.add_parser("validate", help="validate scenes and presets")
    val.add_argument("paths", nargs="+", type=Path)
    _add_plugin_option(val)

    sch = sub.add_parser("schema", help="write a JSON Schema per registered component")
    sch.add_argument("--out", type=Path, required=True)

    docs = sub.add_parser("docs", help="write docs/reference/<component>.md from the config models")
    docs.add_argument("--out", type=Path, default=Path("docs/reference"))

    gal = sub.add_parser("gallery", help="render every preset in configs/effects/ headless to a PNG")
    gal.add_argument("--out", type=Path, default=Path("docs/gallery"))
    gal.add_argument("--configs", type=Path, default=Path("configs"))
    gal.add_argument("--size", nargs=2, type=_int_in(16, 8192), default=(320, 200), metavar=("W", "H"))
    gal.add_argument("--only", help="only presets whose path contains this text")

    gr = sub.add_parser("graph", help="print the compiled render graph of a scene")
    gr.add_argument("scene")
    gr.add_argument("--dot", action="store_true", help="Graphviz format (culled passes dashed)")
    gr.add_argument("--out", type=Path, help="write to a file instead of stdout")
    _add_plugin_option(gr)

    warm = sub.add_parser("warm", help="compile the kernels the scenes use, in parallel processes (first run)")
    warm.add_argument("scenes", nargs="+", type=Path)
    warm.add_argument("--jobs", type=_int_in(1, 256), default=None, help="processes at once (default: the cores)")
    warm.add_argument("--steps", type=_int_in(1, 10**6), default=90, help="ticks per scene (default 90)")
    warm.add_argument("--no-render", action="store_true", help="simulate only (no GL; render kernels not compiled)")

    args = parser.parse_args(argv)
    logging.basicConfig(level=logging.INFO, format="%(levelname)s %(name)s: %(message)s")
    try:
        if args.command == "run":
            from engine.runner import run_command

            return run_command(args)
        if args.command == "validate":
            return validate_command(args.paths, load_plugins(args.plugin))
        if args.command == "schema":
            return schema_command(args.out)
        if args.command == "docs":
            from engine.docgen import write_reference

            written = write_reference(default_registry(), args.out)
            print(f"wrote {len(written)} reference page(s) to {args.out}")
            return 0
        if args.command == "gallery":
            from engine.gallery import gallery_command

            return gallery_command(args)
        if args.command == "warm":
            from engine.warm import warm_command

            return warm_command(args.scenes, args.jobs, args.steps, headless=not args.no_render)
        if args.command == "graph":
            from engine.runner import graph_command

            return graph_command(args)
    except ConfigError as exc:
        print(exc, file=sys.stderr)
        return 1
    except PluginOptionError as exc:  # a --plugin value naming no usable plugin: one line (the cause on request)
        if os.environ.get("ECSFX_TRACEBACK") and exc.__cause__ is not None:
            raise
        print(f"error: {exc}", file=sys.stderr)
        return 1
    except StateHashError as exc:  # a script or plugin keeping something that is not state: theirs to fix
        print(f"error: {exc}", file=sys.stderr)
        return 1
    except RegistryError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 1
    except ScriptError as exc:  # --strict: the script's error, with the script's own traceback (README)
        cause = "".join(traceback.format_exception(exc.__cause__)) if exc.__cause__ else ""
        print(f"{cause}error: {exc}", file=sys.stderr)
        return 1
    except Exception as exc:  # noqa: BLE001 - the last resort: a sentence for people, the traceback on request
        return _unexpected(exc)
    return 0


def _unexpected(exc: Exception) -> int:
    """Report an exception no handler above expected, without a traceback (``ECSFX_TRACEBACK=1`` shows it)."""
    if os.environ.get("ECSFX_TRACEBACK"):
        raise exc
    frontend = sys.modules.get("engine.render.frontend")
    if isinstance(exc, OSError) or (frontend is not None and isinstance(exc, frontend.ContextError)):
        print(f"error: {exc}", file=sys.stderr)  # an unwritable path, no OpenGL: the user's to fix
        return 1
    print(f"internal error: {type(exc).__name__}: {exc}\n(a bug in the engine or a plugin; set ECSFX_TRACEBACK=1 "
          "to see the traceback)", file=sys.stderr)
    return 2


def _toml_files(paths: list[Path]) -> tuple[list[Path], list[Problem]]:
    files, problems = [], []
    for path in paths:
        if path.is_dir():
            found = sorted(path.rglob("*.toml"))
            if not found:
                problems.append(Problem(str(path), "", "no .toml files in this directory"))
            files.extend(found)
        elif path.is_file():
            files.append(path)
        else:
            problems.append(Problem(str(path), "", "no such file or directory"))
    return files, problems


def validate_file(path: Path, registry: Registry, plugins: Sequence[NamedPlugin] = ()):
    """Validate one TOML file: a scene, a prefab, or a preset under ``effects/<dir>/``.

    A scene that lists ``[scene] plugins`` is checked with those plugins and ``plugins`` (``--plugin``), as it
    runs.  Returns what it validated (a ScenePlan, a prefab's EntityPlan or the preset's config model); raises
    ConfigError listing every problem.
    """
    from engine.scene import plan_scene

    data, text = read_toml(path)
    if path.parent.name == "prefabs":
        from engine.prefab import PrefabLibrary

        return PrefabLibrary(registry, path.parent.parent).plan(path.stem)
    elif path.parent.parent.name == "effects":
        spec = registry.preset_component(path.parent.name)
        if spec is None:
            raise ConfigError([Problem(str(path), "", f"no registered component keeps presets in "
                                                      f"'{path.parent.name}/'")])
        return validate(spec.model, data, str(path), (), text, context={"configs_root": path.parent.parent.parent})
    elif "entities" in data or "scene" in data or path.parent.name == "scenes":
        scene_plugins = data.get("scene", {}).get("plugins") if isinstance(data.get("scene"), dict) else None
        if isinstance(scene_plugins, list) and all(isinstance(p, str) for p in scene_plugins):
            try:  # the scene's own plugins, as App loads it: a component of a plugin it does not list is unknown
                registry = registry_with(plugins, scene_plugins)
            except RegistryError as exc:
                raise ConfigError([Problem(str(path), "scene.plugins", str(exc), scene_plugins)]) from None
        return plan_scene(path, registry)
    else:
        raise ConfigError([Problem(str(path), "", "neither a scene (with [scene] or [[entities]]) nor a preset "
                                                  "under effects/<name>/")])


def validate_command(paths: list[Path], plugins: Sequence[NamedPlugin] = ()) -> int:
    registry = registry_with(plugins) if plugins else default_registry()
    files, problems = _toml_files(paths)
    failed = 0
    warnings = []
    for path in files:
        try:
            result = validate_file(path, registry, plugins)
        except ConfigError as exc:
            problems.extend(exc.problems)
            failed += 1
        else:
            warnings.extend(getattr(result, "warnings", ()))
    for p in problems:
        print(p, file=sys.stderr)
    for w in warnings:
        print(f"warning: {w}", file=sys.stderr)
    print(f"validated {len(files)} file(s): {len(files) - failed} ok, {failed} with problems"
          + (f", {len(warnings)} warning(s)" if warnings else ""))
    return 1 if problems else 0


def schema_command(out: Path) -> int:
    from engine.scene import SceneConfig

    registry = default_registry()
    out.mkdir(parents=True, exist_ok=True)
    written = []
    for name, spec in sorted(registry.components.items()):
        schema = spec.model.model_json_schema()
        schema["title"] = name
        schema.setdefault("description", spec.description)
        target = out / f"{name}.schema.json"
        target.write_text(json.dumps(schema, indent=2, sort_keys=True) + "\n", encoding="utf-8")
        written.append(target)
    from engine.scene import EntityConfig

    for name, model in (("scene", SceneConfig), ("entity", EntityConfig)):
        text = json.dumps(model.model_json_schema(), indent=2, sort_keys=True) + "\n"
        (out / f"{name}.schema.json").write_text(text, encoding="utf-8")
    print(f"wrote {len(written) + 2} schema file(s) to {out}")
    return 0
