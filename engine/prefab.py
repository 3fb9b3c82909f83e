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

from engine.config import ConfigError, Problem, model_problems, read_toml, resolve_inside, suggest
from engine.registry import BuildContext, Registry
from engine.scene import EntityConfig, EntityPlan, build_problem, plan_entity

if TYPE_CHECKING:
    from engine.app import App
    from engine.world import World

from pydantic import ValidationError


class PrefabLibrary:
    """Validated prefabs under one configs root, loaded on first use (a non-state resource)."""

    def __init__(self, registry: Registry, root: Path, fixed_dt: float | None = None) -> None:
        self.registry = registry
        self.root = Path(root)
        self.fixed_dt = fixed_dt  # the step prefabs are checked at (a water surface's stability); None: alone
        self._plans: dict[str, EntityPlan] = {}

    @classmethod
    def of(cls, app: App) -> PrefabLibrary:
        """The app's library (created on first use)."""
        library = app.world.try_resource(cls)
        if library is None:
            if app.plan is None:
                raise ConfigError([Problem("<no scene>", "", "prefabs need an app built from a scene file")])
            library = cls(app.registry, app.plan.configs_root, app.dt)
            app.world.insert_resource(library)
        elif library.fixed_dt != app.dt:  # the step changed (a hot reload): check prefabs again at the new one
            library.fixed_dt = app.dt
            library._plans.clear()
        return library

    def plan(self, name: str) -> EntityPlan:
        cached = self._plans.get(name)
        if cached is not None:
            return cached
        try:
            path = resolve_inside(self.root / "prefabs", name, ".toml")
        except ValueError as exc:
            raise ConfigError([Problem(str(self.root / "prefabs"), "", str(exc), value=name)]) from None
        if not path.is_file():
            available = sorted(p.stem for p in (self.root / "prefabs").glob("*.toml"))
            raise ConfigError([Problem(str(path), "", f"prefab not found (available: {', '.join(available) or 'none'})",
                                       value=name, suggestion=suggest(name, available))])
        data, text = read_toml(path)
        problems = []
        try:
            ent = EntityConfig.model_validate(data)
        except ValidationError as exc:
            problems.extend(model_problems(exc, EntityConfig, str(path), (), text))
        context = {"configs_root": self.root}
        if self.fixed_dt is not None:
            context["fixed_dt"] = self.fixed_dt
        planned, found = plan_entity(self.registry, data, path, text, (), self.root, context=context)
        problems.extend(found)
        if problems:
            raise ConfigError(problems)
        comps, scripts = planned.components, planned.scripts
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
        file = str(self.root / "prefabs" / f"{name}.toml")
        ctx = BuildContext(world, entity, plan.name, file, self.root)
        problems = []
        for cname, cfg in plan.components:
            try:
                built += self.registry.component(cname).instantiate(cfg, ctx)
            except Exception as exc:  # reported like a bad file; nothing is spawned
                problems.append(build_problem(file, f"components.{cname}", exc))
        if problems:
            raise ConfigError(problems)
        problems = budget_problems(world, plan, file)
        if problems:
            raise ConfigError(problems)
        if position is not None:
            transform = next((c for c in built if isinstance(c, Transform)), None)
            if transform is None:
                transform = Transform()
                built.append(transform)
            transform.position = np.asarray(position, float).copy()
        if plan.scripts:
            slots = []
            for j, (cls, params, enabled) in enumerate(plan.scripts):
                slot = make_slot(world, entity, cls, params, f"{file}: scripts[{j}]")
                slot.enabled = enabled
                slots.append(slot)
            built.append(Scripts(slots))
        built.extend(extra)
        world.commands.spawn_reserved(entity, built)
        return entity


def budget_problems(world: World, plan: EntityPlan, file: str) -> list[Problem]:
    """The scene-wide budgets (``engine.scene.scene_budget_problems``) at run time: the prefab's cost of each
    (``scene_budgets(fixed_dt)``) plus that of every entity of the same component alive or queued to spawn
    (minus those queued to despawn) must stay within the limit one entity may have.  A spawner script that
    runs long cannot grow the scene past what loading it would have refused."""
    from engine.app import App

    found: list[Problem] = []
    fixed_dt = world.resource(App).config.scene.fixed_dt
    spawns, despawns = world.commands.pending()
    for cname, cfg in plan.components:
        budgets = getattr(cfg, "scene_budgets", None)
        if not callable(budgets):
            continue
        others = [c for entity, (c,) in world.query(type(cfg)) if entity not in despawns]
        others += [c for entity, comps in spawns if entity not in despawns for c in comps if type(c) is type(cfg)]
        costs: dict[str, float] = {}
        for other in others:
            for what, cost, _ in other.scene_budgets(fixed_dt):
                costs[what] = costs.get(what, 0) + cost
        for what, cost, limit in budgets(fixed_dt):
            if not cost:
                continue
            used = costs.get(what, 0)
            if used + cost > limit:
                found.append(Problem(file, f"components.{cname}",
                                     f"not spawned: with the {len(others)} {cname} entities alive or queued the "
                                     f"scene would need {used + cost:,.0f} {what}, more than the {limit:,.0f} "
                                     f"one entity may have; despawn some first or make the prefab smaller"))
    return found
