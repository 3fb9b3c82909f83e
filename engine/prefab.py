"""Prefabs: entity templates in ``configs/prefabs/<name>.toml`` that scripts spawn by name.

A prefab file has the shape of one scene entity (``name``, ``[components.X]`` tables with optional
presets, ``scripts``).  It is validated like a scene, once, and cached; spawning builds fresh runtime
components for a reserved entity id and queues the spawn as a deferred command, so it is safe inside
a script's update.  Tuning stays in TOML: a script names the prefab, never its values.
"""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from engine.config import ConfigError, Problem, model_problems, read_toml, resolve_inside
from engine.registry import BuildContext, Registry
from engine.scene import EntityConfig, EntityPlan, _load_script, load_component

if TYPE_CHECKING:
    from engine.app import App
    from engine.world import World

from pydantic import ValidationError


class PrefabLibrary:
    """Validated prefabs under one configs root, loaded on first use (a non-state resource)."""

    def __init__(self, registry: Registry, root: Path) -> None:
        self.registry = registry
        self.root = Path(root)
        self._plans: dict[str, EntityPlan] = {}

    @classmethod
    def of(cls, app: App) -> PrefabLibrary:
        """The app's library (created on first use)."""
        library = app.world.try_resource(cls)
        if library is None:
            if app.plan is None:
                raise ConfigError([Problem("<no scene>", "", "prefabs need an app built from a scene file")])
            library = cls(app.registry, app.plan.configs_root)
            app.world.insert_resource(library)
        return library

    def plan(self, name: str) -> EntityPlan:
        cached = self._plans.get(name)
        if cached is not None:
            return cached
        try:
            path = resolve_inside(self.root / "prefabs", name, ".toml")
        except ValueError as exc:
            raise ConfigError([Problem(name, "", str(exc))]) from None
        if not path.is_file():
            available = sorted(p.stem for p in (self.root / "prefabs").glob("*.toml"))
            raise ConfigError([Problem(str(path), "", f"prefab not found (available: {', '.join(available) or 'none'})")])
        data, text = read_toml(path)
        try:
            ent = EntityConfig.model_validate(data)
        except ValidationError as exc:
            raise ConfigError(model_problems(exc, EntityConfig, str(path), (), text)) from None
        registry = self.registry
        comps, scripts, problems = [], [], []
        for cname, values in ent.components.items():
            try:
                comps.append((cname, load_component(registry, cname, values, path, text, ("components", cname),
                                                    self.root)))
            except ConfigError as exc:
                problems.extend(exc.problems)
        for j, ref in enumerate(ent.scripts):
            try:
                scripts.append((*_load_script(registry, ref, path, text, ("scripts", j)), ref.enabled))
            except ConfigError as exc:
                problems.extend(exc.problems)
        if problems:
            raise ConfigError(problems)
        plan = EntityPlan(ent.name or name, comps, scripts)
        self._plans[name] = plan
        return plan

    def spawn(self, world: World, name: str, position: Any = None, extra: tuple = ()) -> int:
        """Queue a spawn of prefab ``name`` (optionally moved to ``position``); returns the reserved id."""
        from engine.builtin import Name
        from engine.script import Scripts, make_slot
        from engine.spatial import Transform

        plan = self.plan(name)
        entity = world.reserve()
        built: list[Any] = [Name(plan.name)]
        ctx = BuildContext(world, entity, plan.name, str(self.root / "prefabs" / f"{name}.toml"), self.root)
        for cname, cfg in plan.components:
            built += self.registry.component(cname).instantiate(cfg, ctx)
        if position is not None:
            transform = next((c for c in built if isinstance(c, Transform)), None)
            if transform is None:
                transform = Transform()
                built.append(transform)
            transform.position = np.asarray(position, float).copy()
        if plan.scripts:
            slots = []
            for cls, params, enabled in plan.scripts:
                slot = make_slot(world, entity, cls, params)
                slot.enabled = enabled
                slots.append(slot)
            built.append(Scripts(slots))
        built.extend(extra)
        world.commands.spawn_reserved(entity, built)
        return entity
