"""``python -m engine gallery``: render every preset in configs/effects/ headless to a PNG.

Each preset is dropped into a scene template: ``configs/gallery/<effect>.toml`` when the effect ships
one, else its showcase scene ``configs/scenes/<effect>_showcase.toml`` (a valid scene whose
``preset = "<effect>/..."`` lines are pointed at each preset in turn; a ``#:gallery-steps N`` line, in
the template or in the preset itself, sets the ticks simulated before the picture), otherwise a generic stage (flat terrain, an orbit camera, the
component on an entity above the origin).  ``docs/gallery.md`` lists the pictures
with the preset names and the first comment line of each preset.
"""

from __future__ import annotations

import argparse
import logging
import re
import tempfile
from pathlib import Path

from engine.config import ConfigError, Problem, suggest
from engine.registry import default_registry

log = logging.getLogger("engine.gallery")

GENERIC = """
[scene]
name = "gallery"
seed = 1

[[entities]]
name = "ground"
[entities.components.Transform]
[entities.components.Terrain]
size_exponent = 4
spacing = 2.0
amplitude = 0.0

[[entities]]
name = "camera"
[entities.components.Transform]
[entities.components.Camera]
controller = "orbit"
target = [0.0, 2.0, 0.0]
distance = 14.0
pitch = -20.0

[[entities]]
name = "subject"
[entities.components.Transform]
position = [0.0, 1.0, 0.0]
[entities.components.@COMPONENT@]
preset = "@PRESET@"
"""


def _template(configs: Path, preset: Path) -> str:
    """The stage named by the preset's ``#:gallery-template NAME`` line, else the effect's gallery stage,
    else its showcase scene, else the generic stage."""
    effect = preset.parent.name
    candidates = [configs / "gallery" / f"{line.split()[-1]}.toml"
                  for line in preset.read_text(encoding="utf-8").splitlines() if line.startswith("#:gallery-template")]
    candidates += [configs / "gallery" / f"{effect}.toml", configs / "scenes" / f"{effect}_showcase.toml"]
    for candidate in candidates:
        if candidate.exists() and f'"{effect}/' in candidate.read_text(encoding="utf-8"):
            return candidate.read_text(encoding="utf-8")
    return GENERIC


def preset_title(path: Path) -> str:
    """The preset's first block of comment lines (after ``#:schema``), joined into one paragraph."""
    lines: list[str] = []
    for line in path.read_text(encoding="utf-8").splitlines():
        text = line.strip()
        if text.startswith("#:"):
            continue
        if not text.startswith("#"):
            if lines:
                break
            continue
        lines.append(text.lstrip("#").strip())
    return " ".join(lines)


def gallery_command(args: argparse.Namespace) -> int:
    from engine.app import App
    from engine.render.frontend import create_headless_context
    from engine.render.renderer import Renderer

    registry = default_registry()
    configs = args.configs.resolve()
    out = args.out
    presets = _selected_presets(configs, registry, args.only)
    ctx = create_headless_context()
    entries, failures = [], []
    with tempfile.TemporaryDirectory(prefix="ecsfx-gallery-") as stage:
        for preset, spec in presets:
            rel = f"{preset.parent.name}/{preset.stem}"
            try:
                text = _template(configs, preset)
                steps = _gallery_steps(text, configs / "gallery", preset)
                text = text.replace("@COMPONENT@", spec.name).replace("@PRESET@", rel)
                text = re.sub(rf'preset\s*=\s*"{re.escape(preset.parent.name)}/[^"]*"', f'preset = "{rel}"', text)
                scene = Path(stage) / f"{preset.parent.name}__{preset.stem}.toml"
                scene.write_text(text, encoding="utf-8")
                app = App(scene, configs_root=configs)
                renderer = Renderer(app, ctx, *args.size)
                app.step(steps)
                app.render_frame()
                target = out / preset.parent.name / f"{preset.stem}.png"
                renderer.save_screenshot(target)
                renderer.release()
                print(f"rendered {rel} -> {target}")
            except (ConfigError, UnicodeDecodeError) as exc:
                failures.append((rel, f"{rel}: {exc}"))
    # The index lists every preset with a picture (rendered now or by an earlier run), so a run with --only
    # updates its pictures without dropping the others from the page; a preset that failed now is left out.
    failed = {rel for rel, _ in failures}
    for preset, _ in _selected_presets(configs, registry, None):
        rel, target = f"{preset.parent.name}/{preset.stem}", out / preset.parent.name / f"{preset.stem}.png"
        if rel not in failed and target.is_file():
            entries.append((rel, target, preset_title(preset)))
    _write_index(out, entries)
    for _, failure in failures:
        print(failure)
    return 1 if failures else 0


def _selected_presets(configs: Path, registry, only: str | None) -> list[tuple[Path, object]]:
    """The presets to render (with their component spec); a wrong folder or an ``--only`` that matches
    nothing is an error, not an empty gallery."""
    effects = configs / "effects"
    if not effects.is_dir():
        raise ConfigError([Problem(str(effects), "--configs", "no effects/ folder here: expected the configs "
                                                              "root (the folder holding effects/ and scenes/)")])
    found = []
    for preset in sorted(effects.glob("*/*.toml")):
        spec = registry.preset_component(preset.parent.name)
        if spec is not None:
            found.append((preset, spec))
    if only:
        names = [f"{p.parent.name}/{p.stem}" for p, _ in found]
        selected = [(p, spec) for (p, spec), name in zip(found, names) if only in name]
        if not selected:
            raise ConfigError([Problem(str(effects), "--only", f"no preset matches (available: {', '.join(names)})",
                                       only, suggest(only, names))])
        return selected
    if not found:
        raise ConfigError([Problem(str(effects), "", "no presets of a registered component here")])
    return found


def _gallery_steps(template: str, template_dir: Path, preset: Path) -> int:
    """Ticks simulated before the picture: ``#:gallery-steps N`` (the preset's own line wins)."""
    steps = 90
    for file, text in ((template_dir, template), (preset, preset.read_text(encoding="utf-8"))):
        for number, line in enumerate(text.splitlines(), start=1):
            if line.startswith("#:gallery-steps"):
                value = line.split()[-1]
                if not value.isdigit() or not 0 <= int(value) <= 100_000:
                    raise ConfigError([Problem(str(file), "#:gallery-steps", "expected a whole number of ticks "
                                               "in [0, 100000]", value, line=number if file == preset else None)])
                steps = int(value)
    return steps


def _write_index(out: Path, entries: list[tuple[str, Path, str]]) -> None:
    index = out.parent / "gallery.md"
    lines = ["# Preset gallery", "", "<!-- generated by `python -m engine gallery`; do not edit -->", "",
             "Every preset in `configs/effects/`, rendered headless.", ""]
    current = None
    for rel, target, title in entries:
        effect = rel.split("/")[0]
        if effect != current:
            lines += [f"## {effect}", ""]
            current = effect
        lines += [f"### `{rel}`", "", title, "", f"![{rel}]({target.relative_to(index.parent).as_posix()})", ""]
    index.write_text("\n".join(lines), encoding="utf-8")
