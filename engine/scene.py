"""Scenes: TOML files listing entities with components (by registered name) and scripts.

    [scene]
    name = "sandbox"
    seed = 7

    [[entities]]
    name = "emitter"
    scripts = [{ name = "spin", params = { speed = 45.0 } }]
    [entities.components.Transform]
    position = [0.0, 1.0, 0.0]
    [entities.components.EnergyWaveEmitter]
    preset = "energy_wave/reference"   # configs/effects/energy_wave/reference.toml
    beam_speed = 30.0                # overrides the preset

Loading validates everything first and reports every problem of every file at once; only a scene
without problems is spawned, so a bad edit never leaves a half-built world.
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any, Literal

from pydantic import Field, field_validator

from engine.config import (Color3, ConfigError, ConfigModel, Problem, Vec3, deep_merge, locate_line, model_problems,
                           STOCK_CONFIGS, format_key, read_toml, resolve_inside, suggest)
from engine.registry import BuildContext, Registry, RegistryError
from engine.script import Scripts, make_slot
from engine.world import World

from pydantic import ValidationError

log = logging.getLogger("engine.scene")


class ScriptRef(ConfigModel):
    name: str = Field(description="Registered script name (never a Python path).")
    params: dict[str, Any] = Field(default_factory=dict, description="Validated by the script's Params model.")
    enabled: bool = True


class EntityConfig(ConfigModel):
    name: str = Field("", max_length=128)
    components: dict[str, dict[str, Any]] = Field(default_factory=dict)
    scripts: list[ScriptRef] = Field(default_factory=list, max_length=64)


def nonzero_direction(direction: tuple[float, ...]) -> tuple[float, ...]:
    """The check of ``[render] sun_direction`` (and of the ``render.light`` command's): any length but zero."""
    if math.sqrt(sum(x * x for x in direction)) < 1e-9:
        raise ValueError("expected a non-zero direction (the sun's light comes from it)")
    return direction


class RenderSettings(ConfigModel):
    width: int = Field(960, ge=16, le=8192, description="Window / offscreen width in pixels.")
    height: int = Field(540, ge=16, le=8192, description="Window / offscreen height in pixels.")
    exposure: float = Field(1.0, gt=0.0, le=64.0, description="Tone-mapping exposure.")
    render_scale: float = Field(1.0, ge=0.25, le=1.0,
                                description="3D views render at this fraction of the window size and are upscaled "
                                            "when presented (the HUD stays sharp): the usual remedy for fill-bound "
                                            "software rasterisers.")
    antialiasing: Literal["auto", "fxaa", "off"] = Field(
        "auto", description="Post-process anti-aliasing of the window image (the HUD excepted): fxaa (Lottes's fast "
                            "approximate anti-aliasing, quality variant: one full-screen pass that finds luma edges "
                            "and blends across them), off, or auto: fxaa on a hardware GPU, off on a software "
                            "rasteriser, where the pass costs about half a 30 fps frame (18 ms for the demo's "
                            "640 x 360 view on llvmpipe, 2 cores). It runs on each view at the view's own size, "
                            "before upscaling (render_scale).")
    software_render_scale: float | None = Field(
        None, ge=0.25, le=1.0, description="render_scale on a software rasteriser (llvmpipe, where the fill rate is "
                                           "the limit), so that a scene draws at full size on a GPU and at a "
                                           "fraction on the CPU. Unset: render_scale everywhere.")
    dynamic_resolution: bool = Field(
        False, description="In a window's real-time loop, lower the 3D views' render scale (down to "
                           "min_render_scale) while frames take longer than 1 / target_fps, and raise it back "
                           "towards render_scale (or software_render_scale) when they are well under; it never "
                           "draws above the set scale. Fixed-step runs, screenshots and tests draw at the set scale.")
    target_fps: float = Field(30.0, ge=5.0, le=240.0,
                              description="The frame rate dynamic_resolution holds (frames a second).")
    min_render_scale: float = Field(0.35, ge=0.25, le=1.0,
                                    description="The lowest render scale dynamic_resolution goes to (it stays at "
                                                "the set scale when that is lower).")
    overlap_ticks: bool = Field(True, description="In a window, run each frame's simulation ticks while the GPU "
                                                  "draws the previous state (one frame more latency; a software "
                                                  "rasteriser then draws on its threads while Python simulates). "
                                                  "False: tick, then draw, one after the other.")
    static_layer_cache: bool = Field(True, description="Keep each view's static layer (the clear, the terrain, the "
                                                       "sky and the other opaque features that declare a static key) "
                                                       "once it was the same two frames running, and copy it back "
                                                       "instead of redrawing it while the camera, the light and "
                                                       "those features stay unchanged; the picture is the same bits.")
    shadows: bool = Field(True, description="Sun shadows: the casters (lit meshes, and plugin features that "
                                            "draw into it) are drawn into a depth map seen from the sun, fitted to "
                                            "each view's first shadow_distance metres; the terrain and the meshes "
                                            "are darkened where it hides the sun (cameras can opt out: Camera "
                                            "shadows). Nothing is drawn when no entity casts a shadow.")
    shadow_map_size: int | None = Field(None, ge=256, le=8192,
                                        description="Shadow map resolution in texels a side. Unset: 2048 on a "
                                                    "hardware GPU, 1024 on a software rasteriser (clearing and "
                                                    "sampling the map are CPU work there).")
    shadow_distance: float = Field(50.0, gt=0.0, le=10000.0,
                                   description="Shadows cover each view's frustum out to this distance "
                                               "in metres and fade out over its last fifth; a smaller distance gives "
                                               "sharper shadows (the same texels over less ground). Orthographic "
                                               "views too: a map camera high above the ground needs a distance "
                                               "beyond its height, or Camera shadows = false.")
    shadow_filter: Literal["auto", "hard", "soft"] = Field(
        "auto", description="hard: one depth comparison filtered bilinearly (2 x 2 texels); soft: four of them "
                            "spread over 4 x 4 texels (percentage-closer filtering); auto: soft on a hardware "
                            "GPU, hard on a software rasteriser.")
    shadow_bias: float = Field(1.0, ge=0.0, le=16.0,
                               description="Receivers look up the map this many shadow-map texels along their "
                                           "normal (normal-offset bias): raise it against shadow acne (stripes), "
                                           "lower it when shadows detach from their casters (peter-panning).")
    terrain_shadows: bool = Field(True, description="The terrain's own shadows: each height field shades itself "
                                                    "and the first terrain shades the meshes and the grass where "
                                                    "its hills hide the sun, at any distance (a shadow-height map "
                                                    "re-made when the sun or the terrain changes; a texture fetch "
                                                    "per pixel on meshes, nothing per frame on the terrain and "
                                                    "the grass).")
    sky_top: Color3 = Field((0.25, 0.45, 0.85), description="Sky colour at the zenith (linear RGB).")
    sky_horizon: Color3 = Field((0.75, 0.85, 0.95), description="Sky colour at the horizon (linear RGB).")
    sun_direction: Vec3 = Field((0.4, 0.8, 0.3), description="Direction towards the sun (any length but zero).")
    sun_color: Color3 = Field((1.0, 0.95, 0.85), description="Sun colour and intensity (linear RGB).")
    ambient: float = Field(0.35, ge=0.0, le=4.0, description="Ambient light intensity.")
    fog_density: float = Field(0.004, ge=0.0, le=1.0, description="Exponential distance fog per metre.")
    @field_validator("sun_direction")
    @classmethod
    def _sun_nonzero(cls, direction: tuple[float, ...]) -> tuple[float, ...]:
        return nonzero_direction(direction)

    vsync: bool = Field(True, description="In a window, wait for the display's refresh between frames.")


class SceneSettings(ConfigModel):
    name: str = Field("untitled", max_length=128, description="Shown in the window's title.")
    seed: int = Field(0, ge=0, le=2**63 - 1, description="Root seed of every random stream.")
    fixed_dt: float = Field(1.0 / 60.0, ge=1.0 / 1000.0, le=0.1, description="Fixed simulation step in seconds.")
    max_catchup_steps: int = Field(5, ge=1, le=32, description="Cap on fixed steps run for one slow frame.")
    plugins: list[str] | None = Field(None, description="Plugins to load (default: all installed).")


class SceneConfig(ConfigModel):
    scene: SceneSettings = Field(default_factory=SceneSettings)
    render: RenderSettings = Field(default_factory=RenderSettings)
    entities: list[EntityConfig] = Field(default_factory=list, max_length=100_000)


@dataclass
class EntityPlan:
    """One validated entity, ready to spawn."""

    name: str
    components: list[tuple[str, Any]]  # (registered name, validated config)
    scripts: list[tuple[type, Any, bool]]  # (script class, validated params, enabled)


@dataclass
class ScenePlan:
    file: Path
    configs_root: Path
    config: SceneConfig
    entities: list[EntityPlan] = field(default_factory=list)
    files: list[Path] = field(default_factory=list)  # the scene and every preset it read
    warnings: list[Problem] = field(default_factory=list)  # legal but probably not meant (Registry.add_scene_check)


# The engine's own presets (configs/effects/ beside the engine package): a scene's preset name that its own
# configs root does not hold resolves here, so a game kept in its own folder can use the stock presets.


def find_configs_root(path: Path) -> Path:
    """The nearest ancestor folder named ``configs``; otherwise the scene's own folder."""
    path = Path(path).resolve()
    for parent in path.parents:
        if parent.name == "configs":
            return parent
    return path.parent


def read_scene(path: str | Path) -> tuple[SceneConfig, dict, str]:
    path = Path(path)
    data, text = read_toml(path)
    try:
        return SceneConfig.model_validate(data), data, text
    except ValidationError as exc:
        raise ConfigError(model_problems(exc, SceneConfig, str(path), (), text)) from None


def plan_scene(path: str | Path, registry: Registry, configs_root: Path | None = None) -> ScenePlan:
    """Validate a scene and every preset it names; raise one ConfigError listing all problems.

    A problem in the scene's shape (say a bad ``[scene]`` key) does not hide the problems inside the
    entities: every entity table that can be read is checked too.
    """
    path = Path(path)
    data, text = read_toml(path)
    root = Path(configs_root) if configs_root else find_configs_root(path)
    problems: list[Problem] = []
    config: SceneConfig | None = None
    try:
        config = SceneConfig.model_validate(data)
    except ValidationError as exc:
        problems.extend(model_problems(exc, SceneConfig, str(path), (), text))
    context: dict[str, Any] = {"configs_root": root}
    settings = config.scene if config is not None else _valid_or_none(SceneSettings, data.get("scene", {}))
    if settings is not None:
        context["fixed_dt"] = settings.fixed_dt
        problems.extend(plugin_problems(path, registry, settings.plugins, text))
    files = [path]
    raw_entities = data.get("entities", [])
    entities = []
    for i, raw in enumerate(raw_entities if isinstance(raw_entities, list) else []):
        if isinstance(raw, dict):
            ent, found = plan_entity(registry, raw, path, text, ("entities", i), root, files, context)
            entities.append(ent)
            problems.extend(found)
    if config is not None:  # over the entities that validated: every problem is reported at once
        problems.extend(scene_budget_problems(path, config, entities))
    if problems or config is None:
        raise ConfigError(problems)
    plan = ScenePlan(path, root, config, entities, files)
    plan.warnings = scene_warnings(registry, plan, text)
    return plan


def plugin_problems(path: Path, registry: Registry, names: list[str] | None, text: str) -> list[Problem]:
    """``[scene] plugins`` against the registry the scene is loaded with: every name must be a plugin installed
    there, whether App built the registry from this list or was given one (``App(..., registry=...)``)."""
    problems = []
    for name in names or ():
        error = registry.plugin_error(name)
        if error is not None:
            problems.append(Problem(str(path), "scene.plugins", str(error), line=locate_line(text, ("scene", "plugins"))))
    return problems


def scene_budget_problems(path: Path, config: SceneConfig, entities: list[EntityPlan]) -> list[Problem]:
    """A component's joint limits (``scene_budgets(fixed_dt)``: what, cost, limit) hold for the whole scene too:
    each limit bounds one entity, and a scene may hold 100,000 entities, so the sum over every entity of a
    component is capped by the same limit (two fields of 600,000 plants are refused like one of 1.2 million)."""
    totals: dict[tuple[str, str], list] = {}
    for i, ent in enumerate(entities):
        for cname, cfg in ent.components:
            budgets = getattr(cfg, "scene_budgets", None)
            for what, cost, limit in (budgets(config.scene.fixed_dt) if callable(budgets) else ()):
                entry = totals.setdefault((cname, what), [0, limit, []])
                entry[0] += cost
                if cost:
                    entry[2].append(i)
    problems = []
    for (cname, what), (total, limit, users) in totals.items():
        if total > limit and len(users) > 1:  # one entity over its limit is its own model's error
            listed = ", ".join(f"entities[{i}]" for i in users[:6]) + (", ..." if len(users) > 6 else "")
            problems.append(Problem(str(path), "entities", f"the scene's {len(users)} {cname} entities together "
                                    f"need {total:,.0f} {what}, more than the {limit:,.0f} one entity may have "
                                    f"({listed}); lower them or use fewer", None))
    return problems


def scene_warnings(registry: Registry, plan: ScenePlan, text: str) -> list[Problem]:
    """Run the registered scene checks (``Registry.add_scene_check``).  A check that fails is itself reported
    as a warning: a plugin's lint must not keep a valid scene from loading."""
    found: list[Problem] = []
    for check in registry.scene_checks:
        try:
            found.extend(check(plan, text))
        except Exception as exc:  # noqa: BLE001
            name = getattr(check, "__qualname__", repr(check))
            found.append(Problem(str(plan.file), "", f"scene check {name} failed: {type(exc).__name__}: {exc}"))
    return found


def _valid_or_none(model: type[ConfigModel], data: Any) -> Any:
    try:
        return model.model_validate(data)
    except ValidationError:
        return None


def plan_entity(registry: Registry, raw: dict, file: Path, text: str, key: tuple, root: Path,
                files: list[Path] | None = None, context: dict | None = None) -> tuple[EntityPlan, list[Problem]]:
    """Check the components (with their presets) and scripts of one entity table; returns the plan and the
    problems found.  The table's own shape (``name``, unknown keys) is the caller's model's job, so each
    problem is reported once."""
    problems: list[Problem] = []
    comps = []
    components = raw.get("components", {})
    for cname, values in (components.items() if isinstance(components, dict) else ()):
        if not isinstance(values, dict):
            continue  # reported by EntityConfig
        try:
            comps.append((cname, load_component(registry, cname, values, file, text, key + ("components", cname),
                                                root, files, context)))
        except ConfigError as exc:
            problems.extend(exc.problems)
    scripts = []
    refs = raw.get("scripts", [])
    for j, item in enumerate(refs if isinstance(refs, list) else []):
        ref = _valid_or_none(ScriptRef, item)
        if ref is None:
            continue  # reported by EntityConfig
        try:
            scripts.append((*_load_script(registry, ref, file, text, key + ("scripts", j)), ref.enabled))
        except ConfigError as exc:
            problems.extend(exc.problems)
    name = raw.get("name", "")
    return EntityPlan(name if isinstance(name, str) else "", comps, scripts), problems


def load_component(registry: Registry, cname: str, values: dict, file: Path, text: str, key: tuple,
                   root: Path, files: list[Path] | None = None, context: dict | None = None) -> Any:
    """Validate one component table (with its optional preset) against the registered model.

    ``context`` reaches the model's validators (``info.context``): the scene passes ``fixed_dt`` so that
    stability limits that depend on the time step are checked when the file is validated.
    """
    try:
        spec = registry.component(cname)
    except RegistryError as exc:
        raise ConfigError([Problem(str(file), format_key(key), exc.problem, suggestion=exc.suggestion,
                                   line=locate_line(text, key))]) from None
    values = dict(values)
    preset_name = values.pop("preset", None)
    preset: dict = {}
    preset_file: Path | None = None
    preset_text = ""
    if preset_name is not None:
        preset_file, preset, preset_text = _load_preset(spec, preset_name, file, text, key, root)
        if files is not None and preset_file not in files:
            files.append(preset_file)
    merged = deep_merge(preset, values)
    try:
        return spec.model.model_validate(merged, context=context)
    except ValidationError as exc:
        problems = []
        for p in model_problems(exc, spec.model, str(file), key, text, data=merged, context=context):
            top = p.key[len(format_key(key)) + 1:].split(".")[0].split("[")[0]
            if preset_file is not None and top in preset and top not in values:
                sub = p.key[len(format_key(key)) + 1:]
                line = locate_line(preset_text, sub.replace("[", ".[").split(".")) if sub else None
                p = Problem(str(preset_file), sub, p.message, p.value, p.suggestion, line)
            problems.append(p)
        raise ConfigError(problems) from None


def _load_preset(spec, preset_name: Any, file: Path, text: str, key: tuple, root: Path):
    where = dict(file=str(file), key=format_key(key + ("preset",)), line=locate_line(text, key + ("preset",)))
    if not isinstance(preset_name, str):
        raise ConfigError([Problem(message="expected a preset name string", value=preset_name, **where)])
    if spec.preset_dir is None:
        raise ConfigError([Problem(message=f"component '{spec.name}' has no presets", value=preset_name, **where)])
    rel = preset_name if "/" in preset_name else f"{spec.preset_dir}/{preset_name}"
    try:
        preset_file = resolve_inside(Path(root) / "effects", rel, ".toml")
        stock = resolve_inside(STOCK_CONFIGS / "effects", rel, ".toml")
    except ValueError as exc:
        raise ConfigError([Problem(message=str(exc), value=preset_name, **where)]) from None
    if not preset_file.is_file() and stock.is_file():
        preset_file = stock  # the game's configs/ has no such preset: the engine's stock one
    if not preset_file.is_file():
        available = sorted({p.stem for folder in (preset_file.parent, stock.parent) if folder.is_dir()
                            for p in folder.glob("*.toml")})
        close = suggest(preset_file.stem, available)
        raise ConfigError([Problem(message=f"preset not found: {preset_file} (available: "
                                   f"{', '.join(available) or 'none'})", value=preset_name,
                                   suggestion=close, **where)])
    data, preset_text = read_toml(preset_file)
    return preset_file, data, preset_text


def _load_script(registry: Registry, ref: ScriptRef, file: Path, text: str, key: tuple):
    try:
        cls = registry.script(ref.name)
    except RegistryError as exc:
        raise ConfigError([Problem(str(file), format_key(key + ("name",)), exc.problem, suggestion=exc.suggestion,
                                   line=locate_line(text, key + ("name",)))]) from None
    try:
        return cls, cls.Params.model_validate(ref.params)
    except ValidationError as exc:
        raise ConfigError(model_problems(exc, cls.Params, str(file), key + ("params",), text)) from None
    except Exception as exc:  # a script's own validator raising something else must not take loading down
        problem = build_problem(file, format_key(key + ("params",)), exc)
        raise ConfigError([replace(problem, line=locate_line(text, key + ("params",)))]) from None



@dataclass
class EntityRecord:
    """What the scene built for one entity, for hot reload: configs and the component types they made."""

    entity: int
    name: str
    components: dict[str, tuple[Any, list[type]]] = field(default_factory=dict)


def build_problem(file: Path | str, key: str, exc: BaseException) -> Problem:
    """A component factory's failure as a problem: ValueError and OSError carry a message for people (a
    missing asset, an unstable parameter); anything else is named by its type, with the traceback in the log."""
    if isinstance(exc, (ValueError, OSError, ConfigError)):
        return Problem(str(file), key, f"cannot build: {exc}")
    log.error("building %s of %s raised", key, file, exc_info=exc)
    return Problem(str(file), key, f"cannot build: {type(exc).__name__}: {exc} (traceback in the log)")


def build_component(world: World, registry: Registry, plan: ScenePlan, entity: int, name: str, cname: str,
                    cfg: Any) -> list[Any]:
    ctx = BuildContext(world, entity, name, str(plan.file), plan.configs_root)
    return registry.component(cname).instantiate(cfg, ctx)


def spawn_entity(world: World, registry: Registry, plan: ScenePlan, index: int, ent: EntityPlan) -> EntityRecord:
    """Spawn one planned entity; a failing build raises ConfigError and leaves nothing behind."""
    from engine.builtin import Name

    entity = world.spawn()
    record = EntityRecord(entity, ent.name)
    if ent.name:
        world.add(entity, Name(ent.name))
    problems = []
    for cname, cfg in ent.components:
        try:
            built = build_component(world, registry, plan, entity, ent.name, cname, cfg)
        except Exception as exc:  # a plugin's factory failing on this config must not take the engine down
            problems.append(build_problem(plan.file, f"entities[{index}].components.{cname}", exc))
            continue
        for comp in built:
            world.add(entity, comp)
        record.components[cname] = (cfg, [type(c) for c in built])
    slots = []
    for j, (cls, params, enabled) in enumerate(ent.scripts or ()):
        try:  # a script's constructor raising is the scene's error, like a component that cannot be built
            slot = make_slot(world, entity, cls, params, f"{plan.file}: entities[{index}].scripts[{j}]")
        except Exception as exc:
            problems.append(build_problem(plan.file, f"entities[{index}].scripts[{j}]", exc))
            continue
        slot.enabled = enabled
        slots.append(slot)
    if problems:
        world.despawn(entity)
        raise ConfigError(problems)
    if slots:
        world.add(entity, Scripts(slots))
    return record


def spawn_plan(world: World, registry: Registry, plan: ScenePlan) -> list[EntityRecord]:
    """Create every planned entity (in file order, so ids follow the file); all or nothing."""
    problems: list[Problem] = []
    records = []
    for i, ent in enumerate(plan.entities):
        try:
            records.append(spawn_entity(world, registry, plan, i, ent))
        except ConfigError as exc:
            problems.extend(exc.problems)
    if problems:
        for record in records:
            world.despawn(record.entity)
        raise ConfigError(problems)
    return records
