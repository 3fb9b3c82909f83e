"""Prefabs: entity templates in ``configs/prefabs/<name>.toml`` that scripts spawn by name.

A prefab file has the shape of one scene entity (``name``, ``[components.X]`` tables with optional
presets, ``scripts``).  It is validated like a scene, once, and cached; spawning builds fresh runtime
components for a reserved entity id and queues the spawn as a deferred command, so it is safe inside
a script's update.  Tuning stays in TOML: a script names the prefab, never its values.

A spawned entity carries a :class:`PrefabInstance`: the prefab it came from and the config each of its components
was built from.  The library remembers every file a loaded prefab read (:attr:`PrefabLibrary.files`), so that a hot
reload (engine/reload.py) watches them, plans the prefabs again (:meth:`PrefabLibrary.replan`) and brings the live
instances up to date.
"""

from __future__ import annotations

from dataclasses import dataclass, field
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


@dataclass
class PrefabInstance:
    """Component of an entity spawned from a prefab: the prefab's name (as spawned, ``"smoke_puff"``) and, per
    component the prefab gave it, the config it was built from and the component types that made (as
    engine.scene.EntityRecord keeps them for a scene's entities).  A hot reload of the prefab's files compares
    these with the new plan: parameters are swapped in place, a structural change rebuilds that component."""

    prefab: str
    components: dict[str, tuple[Any, list[type]]] = field(default_factory=dict)

    def __hash_state__(self) -> Any:
        return {"prefab": self.prefab, "configs": {cname: cfg for cname, (cfg, _) in self.components.items()}}


def _stat(path: Path) -> tuple[int, int] | None:
    try:
        st = path.stat()
    except OSError:
        return None
    return st.st_size, st.st_mtime_ns


class PrefabLibrary:
    """Validated prefabs under one configs root, loaded on first use (a non-state resource)."""

    def __init__(self, registry: Registry, root: Path, fixed_dt: float | None = None) -> None:
        self.registry = registry
        self.root = Path(root)
        self.fixed_dt = fixed_dt  # the step prefabs are checked at (a water surface's stability); None: alone
        self._plans: dict[str, EntityPlan] = {}
        self._read: dict[str, list[Path]] = {}  # prefab name -> its file and the presets it read
        #: every file a loaded prefab read (its own and its presets) -> (size, mtime in ns) when it was read, so that
        #: a watcher that learns of the file later still sees an edit made since (engine/reload.py)
        self.files: dict[Path, tuple[int, int] | None] = {}

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
        plan, files = self._load(name, self.fixed_dt)
        self._plans[name] = plan
        self._remember(name, files)
        return plan

    def _load(self, name: str, fixed_dt: float | None) -> tuple[EntityPlan, dict[Path, tuple[int, int] | None]]:
        """Read and validate prefab ``name`` at ``fixed_dt``: its plan and the files it read (with their size and
        mtime before the read); raises ConfigError naming the file and key of every problem."""
        try:
            path = resolve_inside(self.root / "prefabs", name, ".toml")
        except ValueError as exc:
            raise ConfigError([Problem(str(self.root / "prefabs"), "", str(exc), value=name)]) from None
        if not path.is_file():
            available = sorted(p.stem for p in (self.root / "prefabs").glob("*.toml"))
            raise ConfigError([Problem(str(path), "", f"prefab not found (available: {', '.join(available) or 'none'})",
                                       value=name, suggestion=suggest(name, available))])
        files = {path: _stat(path)}
        data, text = read_toml(path)
        problems = []
        try:
            ent = EntityConfig.model_validate(data)
        except ValidationError as exc:
            problems.extend(model_problems(exc, EntityConfig, str(path), (), text))
        context = {"configs_root": self.root}
        if fixed_dt is not None:
            context["fixed_dt"] = fixed_dt
        presets: list[Path] = []
        planned, found = plan_entity(self.registry, data, path, text, (), self.root, presets, context=context)
        problems.extend(found)
        if problems:
            raise ConfigError(problems)
        files.update((preset, _stat(preset)) for preset in presets)
        return EntityPlan(ent.name or name, planned.components, planned.scripts), files

    def _remember(self, name: str, files: dict[Path, tuple[int, int] | None]) -> None:
        self._read[name] = list(files)
        self.files.update(files)

    # ------------------------------------------------------------------ hot reload
    def loaded(self) -> dict[str, EntityPlan]:
        """The prefabs loaded so far (spawned at least once, or planned), by name."""
        return dict(self._plans)

    def file_of(self, name: str) -> Path:
        """Prefab ``name``'s own file."""
        return resolve_inside(self.root / "prefabs", name, ".toml")

    def replan(self, fixed_dt: float) -> tuple[dict[str, tuple[EntityPlan, dict]], list[Problem]]:
        """Every loaded prefab read and validated again from its files, at ``fixed_dt``: ``({name: (plan, files)},
        problems)``.  The library itself does not change (:meth:`use` puts the new plans in force), so a hot reload
        that finds a problem keeps spawning the last good prefabs."""
        plans, problems = {}, []
        for name in self._plans:
            try:
                plans[name] = self._load(name, fixed_dt)
            except ConfigError as exc:
                problems.extend(exc.problems)
        return plans, problems

    def use(self, plans: dict[str, tuple[EntityPlan, dict]], fixed_dt: float) -> None:
        """Spawn from ``plans`` (:meth:`replan`'s) from now on, checked at ``fixed_dt``."""
        self.fixed_dt = fixed_dt
        self._plans = {name: plan for name, (plan, _) in plans.items()}
        self._read, self.files = {}, {}
        for name, (_, files) in plans.items():
            self._remember(name, files)

    # ------------------------------------------------------------------ spawning
    def spawn(self, world: World, name: str, position: Any = None, extra: tuple = ()) -> int:
        """Queue a spawn of prefab ``name`` (optionally moved to ``position``); returns the reserved id."""
        from engine.builtin import Name
        from engine.script import Scripts, make_slot
        from engine.spatial import Transform

        plan = self.plan(name)
        entity = world.reserve()
        built: list[Any] = [Name(plan.name)]
        instance = PrefabInstance(name)
        file = str(self.root / "prefabs" / f"{name}.toml")
        ctx = BuildContext(world, entity, plan.name, file, self.root)
        problems = []
        for cname, cfg in plan.components:
            try:
                made = self.registry.component(cname).instantiate(cfg, ctx)
            except Exception as exc:  # reported like a bad file; nothing is spawned
                problems.append(build_problem(file, f"components.{cname}", exc))
                continue
            built += made
            instance.components[cname] = (cfg, [type(c) for c in made])
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
        built.append(instance)
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
