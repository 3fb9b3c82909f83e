"""Hot reload of the scene file and every preset it loaded.

:class:`HotReloader` polls the files' contents (size, mtime, then a BLAKE2b digest, so an editor's
touch without a change does nothing).  On a change it re-plans the whole scene:

* invalid: the last good config stays in force; the problems (file, key path, value, expectation,
  did-you-mean) go to the log and to :class:`ReloadStatus`, which the HUD shows until the file is fixed;
* valid: per entity (matched by position and name), each component whose config changed is either
  swapped in place (its ``structural`` keys unchanged: the new parameters are live at the next tick and
  the simulation state is kept) or rebuilt alone; script parameters are swapped in place; entities
  added to or removed from the file are spawned or despawned.

The scene's settings (``[scene]``, ``[render]``) on reload:

* ``fixed_dt`` and ``max_catchup_steps`` are live (the clock takes them).  The new plan is validated at the new
  ``fixed_dt``, and so are the loaded prefabs and the components of other entities spawned while running
  (spawners): a step that one of them cannot run at (an unstable water surface) refuses the whole edit, so no
  system raises on the next tick;
* ``seed``: a running world keeps its random streams; the new seed applies on restart (R), and the HUD says so;
* ``plugins``: systems and render passes cannot be swapped into a running game, so a changed list holds the
  whole edit back and says to run the game again (R rebuilds the scene with the plugins already loaded);
* ``[render]`` is live (the renderer reads the new settings the next frame) except ``width``, ``height`` (the
  window's size) and ``vsync`` (set when the window opens), which keep their running values and are noted.  The
  light (sun, sky, ambient, fog) is world state that scripts may change (``render.light``): the light keys the
  edit changed are written into it, the others keep what scripts set (engine/render/lighting.py).

A watched file that goes from content to zero bytes is taken for an editor's save in progress: the reload is
held back (a scene that suddenly has no entities would despawn the whole world and respawn it from scratch)
and the HUD says so until the file is saved again.  A failed reload also watches the files that the failed
scene names but could not read: creating a missing preset or asset, or fixing a broken one, reloads.  The asset
files a loaded scene's components read (height maps, textures) are watched too: editing one rebuilds the components
that name it, although their config is the same.

Prefabs (engine/prefab.py) are watched from their first spawn: the prefab's file, the presets it reads and the assets
its components name.  Every reload plans the loaded prefabs again at the new step, with the scene (a problem in
either refuses the whole edit and the library keeps spawning the last good prefabs); a valid edit is what the next
spawns get, and the live entities spawned from it are brought up to date like a scene's entities (parameters swapped
in place, a structural change or an edited asset rebuilds that component, scripts' parameters swapped), except that
each keeps its own position (the spawner gave it) and its name.
"""

from __future__ import annotations

import hashlib
import logging
from collections.abc import Iterable
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

from pydantic import ValidationError

from engine.config import (STOCK_CONFIGS, ConfigError, Problem, locate_line, read_toml, resolve_asset,
                           resolve_inside)
from engine.prefab import PrefabInstance, PrefabLibrary
from engine.render.lighting import follow_file
from engine.registry import BuildContext
from engine.scene import EntityPlan, EntityRecord, build_problem, plan_scene, spawn_entity
from engine.script import Scripts, make_slot

if TYPE_CHECKING:
    from engine.app import App

log = logging.getLogger("engine.reload")


@dataclass
class ReloadStatus:
    """World resource: the outcome of the last reload (errors stay until the files are fixed)."""

    errors: list[str] = field(default_factory=list)
    warnings: list[str] = field(default_factory=list)  # the scene's warnings (App.warnings), kept up to date
    reloads: int = 0
    last_changes: list[str] = field(default_factory=list)


def _fingerprint(path: Path) -> tuple:
    try:
        st = path.stat()
        return st.st_size, st.st_mtime_ns, hashlib.blake2b(path.read_bytes(), digest_size=16).hexdigest()
    except OSError:
        return (None, None, None)


RUN_AGAIN_RENDER_KEYS = ("width", "height", "vsync")  # [render] keys the window takes when it opens
MAX_WATCHED_ASSETS = 64  # files a failed scene names that a reload also watches (each poll reads them)


class HotReloader:
    """Watches an app's scene and presets and applies edits to the live world."""

    def __init__(self, app: App) -> None:
        if app.plan is None:
            raise ValueError("hot reload needs an app built from a scene file")
        self.app = app
        self.status = ReloadStatus(warnings=[str(w) for w in app.warnings])
        app.world.insert_resource(self.status)
        self._world = app.world
        self._started = app.plan.config  # the file's settings when the game started (window size, vsync, seed)
        self._held: set[Path] = set()  # emptied files (a save in progress?) whose reload is held back
        self._prints: dict[Path, tuple] = {}
        self._assets_changed: set[Path] = set()  # asset files whose content changed since the last reload
        self._prefabs_seen: tuple[Any, dict[str, EntityPlan]] = (None, {})  # (library, plans whose files are watched)
        self._watch(app.plan.files + self._plan_assets(app.plan))

    def _watch(self, files: list[Path]) -> None:
        self._prints = {Path(f): _fingerprint(Path(f)) for f in files}
        self._prefabs_seen = (None, {})
        self._watch_prefabs()

    def _watch_prefabs(self) -> None:
        """Watch the files of the prefabs loaded since the last look (a prefab is read when it is first spawned):
        each prefab's file and presets as they were when read (an edit made since then reloads at this poll), and
        the assets its components name."""
        library = self.app.world.try_resource(PrefabLibrary)
        if library is None:
            return
        seen_library, seen = self._prefabs_seen
        if seen_library is not library:
            seen = {}
        for path, read in library.files.items():
            if path not in self._prints:
                now = _fingerprint(path)
                self._prints[path] = now if read == now[:2] else (*(read or (None, None)), None)
        loaded = library.loaded()
        fresh = [plan for name, plan in loaded.items() if seen.get(name) is not plan]
        if fresh:
            assets = [path for path in _entity_assets(fresh, self.app.plan.configs_root) if path not in self._prints]
            room = MAX_WATCHED_ASSETS - sum(1 for path in self._prints if path.suffix.lower() != ".toml")
            for path in assets[:max(room, 0)]:
                self._prints[path] = _fingerprint(path)
        self._prefabs_seen = (library, loaded)

    def changed(self) -> bool:
        self._watch_prefabs()
        found = False
        for path, old in self._prints.items():
            new = _fingerprint(path)
            if new != old and (new[0], new[2]) != (old[0], old[2]):
                found = True
                if path.suffix.lower() != ".toml":  # an asset: the components naming it are rebuilt
                    self._assets_changed.add(path)
            elif new != old:
                self._prints[path] = new  # same content, touched: remember the new mtime
        return found

    def _plan_assets(self, plan) -> list[Path]:
        """The asset files (height maps, textures) the components of a loaded scene name and that exist: watched,
        so that editing one rebuilds the components that use it (their config did not change)."""
        return _entity_assets(plan.entities, plan.configs_root)[:MAX_WATCHED_ASSETS]

    def _uses_changed_asset(self, cfg: Any) -> bool:
        if not self._assets_changed:
            return False
        return any(path in self._assets_changed
                   for path in _asset_paths(cfg.model_dump(mode="json", warnings=False), self.app.plan.configs_root))

    def poll(self) -> bool:
        """Reload when a watched file's content changed; returns True when a reload was attempted."""
        self._follow_restart()
        if not self.changed():
            return False
        self.reload()
        return True

    def reload(self) -> bool:
        """Re-plan and apply (F5 calls this directly). Returns True when the new config is in force."""
        app = self.app
        self._follow_restart()
        emptied = self._emptied()
        if emptied:
            return self._refuse([Problem(str(path), "", "the file is empty, as an editor leaves it part-way through "
                                         "a save: the running world stays; save the file again to apply it (a file "
                                         "meant to be empty needs at least a comment)") for path in emptied],
                                hold=emptied)
        plugins = self._plugins_problem()
        if plugins is not None:
            return self._refuse([plugins])
        try:
            plan = plan_scene(app.plan.file, app.registry, app.plan.configs_root)
        except ConfigError as exc:  # the prefabs' problems too (at the running step): every problem at once
            _, problems = self._replan_prefabs(app.dt)
            return self._refuse(exc.problems + problems, also_watch=self._named_files() + self._prefab_named_files())
        prefabs, problems = self._replan_prefabs(plan.config.scene.fixed_dt)
        problems += self._time_step_problems(plan)
        if problems:
            return self._refuse(problems, also_watch=plan.files + self._prefab_named_files())
        self._held = set()
        self.status.errors = []
        for warning in plan.warnings:
            log.warning("%s", warning)
        try:  # the settings first: what is spawned or rebuilt below sees the new config and clock
            changes = self._apply_settings(plan)
            changes += self._apply(plan)
            changes += self._apply_prefabs(prefabs, plan.config.scene.fixed_dt)
        except Exception as exc:  # noqa: BLE001 - a plugin's hook failing must not take the game down
            log.error("reload of %s failed while applying", plan.file, exc_info=exc)
            self.status.errors.append(f"{plan.file}: reload failed while applying: {type(exc).__name__}: {exc}")
            changes = ["reload failed while applying; see the errors"]
        self._watch(plan.files + self._plan_assets(plan))
        self._assets_changed = set()
        app.plan = plan
        notes = self._notes()
        for note in notes:
            log.warning("%s", note)
        self.status.warnings = [str(w) for w in plan.warnings] + [str(n) for n in notes]
        self.status.reloads += 1
        self.status.last_changes = changes
        log.info("reloaded %s: %s", plan.file, "; ".join(changes) or "no effective change")
        return True

    def _refuse(self, problems: list[Problem], also_watch: Iterable[Path] = (),
                hold: Iterable[Path] = ()) -> bool:
        """Keep the last good config and the running world; report ``problems`` until the files change.  The
        watch list grows by ``also_watch`` (what the failed edit names), so that fixing those files reloads."""
        self._watch([*self._prints, *also_watch])  # fingerprints now: the same content is not reported every poll
        self._held = set(hold)
        self.status.errors = [str(p) for p in problems]
        log.error("reload failed; keeping the last good config:\n%s", ConfigError(problems))
        return False

    def _follow_restart(self) -> None:
        """A restart (R) builds a new world: the status moves to it, and the notes that the restart settled go."""
        app = self.app
        if app.world is self._world:
            return
        self._world = app.world
        app.world.insert_resource(self.status)
        self.status.warnings = [str(w) for w in app.warnings] + [str(n) for n in self._notes()]

    # ------------------------------------------------------------- what a reload may not apply
    def _emptied(self) -> list[Path]:
        """Watched files that had content and now have none (an editor truncates before it writes)."""
        found = []
        for path, (size, _, _) in self._prints.items():
            try:
                now = path.stat().st_size
            except OSError:
                continue
            if now == 0 and (size or path in self._held):
                found.append(path)
        return found

    def _plugins_problem(self) -> Problem | None:
        """A changed ``[scene] plugins`` list: its systems cannot join a running schedule (nor its render passes
        a running renderer), and planning with the running registry would call its components unknown."""
        app = self.app
        try:
            data, text = read_toml(app.plan.file)
        except ConfigError:
            return None  # plan_scene reports it
        scene = data.get("scene")
        wanted = scene.get("plugins") if isinstance(scene, dict) else None
        if not (wanted is None or (isinstance(wanted, list) and all(isinstance(n, str) for n in wanted))):
            return None  # not a list of names: plan_scene reports it
        running = app.config.scene.plugins
        if wanted == running:
            return None

        def shown(names: list[str] | None) -> str:
            return "every installed plugin" if names is None else "[" + ", ".join(names) + "]"

        return Problem(str(app.plan.file), "scene.plugins",
                       f"plugins changed from {shown(running)} to {shown(wanted)}: plugins load when the game starts, "
                       "so run it again to load them (restart, R, rebuilds the scene with the plugins already "
                       "loaded); until then the running world and the last good config stay in force",
                       line=locate_line(text, ("scene", "plugins")))

    def _time_step_problems(self, plan) -> list[Problem]:
        """A new ``fixed_dt`` against the entities spawned while running (prefabs, spawners): plan_scene
        validated the scene's own at the new step, these were validated at the old one.  A component whose
        config passes at the old step and fails at the new one (a water surface's stability limit) refuses the
        edit: applied, its system would raise on the next tick.  The components a prefab gave its entities are
        left out: the prefab is planned again at the new step (a problem there is the prefab file's), and the
        reload brings them to that plan."""
        from engine.builtin import Name

        app, world = self.app, self.app.world
        new_dt, old_dt = plan.config.scene.fixed_dt, app.clock.dt
        if new_dt == old_dt:
            return []
        in_scene = {record.entity for record in app.records}
        library = world.try_resource(PrefabLibrary)
        loaded = library.loaded() if library is not None else {}
        seen: set[tuple[int, type]] = {(entity, type(cfg)) for entity, (instance,) in world.query(PrefabInstance)
                                       if instance.prefab in loaded for cfg, _ in instance.components.values()}
        problems = []
        line = locate_line(_text(plan.file), ("scene", "fixed_dt"))
        for cname, spec in app.registry.components.items():
            for entity, (cfg,) in world.query(spec.model):
                if entity in in_scene or (entity, spec.model) in seen:
                    continue
                seen.add((entity, spec.model))
                reason = _unsuited(spec.model, cfg, old_dt, new_dt)
                if reason is not None:
                    name = world.try_get(entity, Name)
                    label = f"entity {entity}" + (f" '{name.value}'" if name is not None else "")
                    problems.append(Problem(str(plan.file), "scene.fixed_dt",
                                            f"{label}, spawned while running, cannot run at this step: {cname}: "
                                            f"{reason}; the running world keeps fixed_dt {old_dt:g} s",
                                            value=new_dt, line=line))
        return problems

    def _named_files(self) -> list[Path]:
        """The files a scene that failed to load names: its presets where engine.scene looks for them (found or
        not), and the strings in its component tables and their presets that name a file under the configs root
        (a texture, a height map).  Watched until the next reload, so creating or fixing one reloads."""
        try:
            data, _ = read_toml(self.app.plan.file)
        except ConfigError:
            return []
        entities = data.get("entities")
        return self._named_by(entities if isinstance(entities, list) else [])

    def _prefab_named_files(self) -> list[Path]:
        """:meth:`_named_files` for the loaded prefabs: the presets and assets their files name, found or not."""
        library = self.app.world.try_resource(PrefabLibrary)
        tables = []
        for name in library.loaded() if library is not None else ():
            try:
                tables.append(read_toml(library.file_of(name))[0])
            except (ConfigError, ValueError):
                pass
        return self._named_by(tables)

    def _named_by(self, entities: list[Any]) -> list[Path]:
        """The presets (where engine.scene looks for them) and the assets named by entity tables."""
        root = self.app.plan.configs_root
        files: list[Path] = []
        assets: list[Path] = []
        for raw in entities:
            components = raw.get("components") if isinstance(raw, dict) else None
            for cname, values in components.items() if isinstance(components, dict) else ():
                if not isinstance(values, dict):
                    continue
                tables = [values]
                for preset in self._preset_paths(cname, values.get("preset"), root):
                    files.append(preset)
                    try:
                        tables.append(read_toml(preset)[0])
                    except ConfigError:
                        pass
                for table in tables:
                    assets.extend(_asset_paths(table, root))
        return files + list(dict.fromkeys(assets))[:MAX_WATCHED_ASSETS]

    def _preset_paths(self, cname: str, name: Any, root: Path) -> list[Path]:
        """Where engine.scene looks for preset ``name`` of component ``cname``: the game's configs, then the
        engine's stock ones."""
        if not isinstance(name, str):
            return []
        if "/" not in name:
            spec = self.app.registry.components.get(cname)
            if spec is None or spec.preset_dir is None:
                return []
            name = f"{spec.preset_dir}/{name}"
        paths = []
        for base in (Path(root) / "effects", STOCK_CONFIGS / "effects"):
            try:
                paths.append(resolve_inside(base, name, ".toml"))
            except ValueError:
                pass
        return paths

    # ------------------------------------------------------------------ settings
    def _apply_settings(self, plan) -> list[str]:
        """Bring the clock, the app's config and the renderer to the plan's ``[scene]`` and ``[render]``."""
        app = self.app
        before, new = app.plan.config, plan.config  # the file as it was and as it is
        changes = []
        clock = app.clock
        if new.scene.fixed_dt != clock.dt:
            changes.append(f"scene: fixed_dt {clock.dt:g} -> {new.scene.fixed_dt:g} s")
            clock.dt = float(new.scene.fixed_dt)
            clock.accumulator = min(clock.accumulator, clock.dt * (1.0 - 1e-12))  # less than one step waits
        if new.scene.max_catchup_steps != clock.max_steps:
            changes.append(f"scene: max_catchup_steps {clock.max_steps} -> {new.scene.max_catchup_steps}")
            clock.max_steps = int(new.scene.max_catchup_steps)
        if new.scene.seed != before.scene.seed:
            if app.seed_from_scene:
                app.seed = int(new.scene.seed)
                changes.append(f"scene: seed {before.scene.seed} -> {new.scene.seed}, applies on restart (R)")
            else:
                changes.append(f"scene: seed {new.scene.seed} not used: this run's seed {app.seed} was given when "
                               "it started")
        running = app.config.render
        render = new.render.model_copy(update={k: getattr(running, k) for k in RUN_AGAIN_RENDER_KEYS})
        live = _diff(running, render)
        waiting = [k for k in RUN_AGAIN_RENDER_KEYS if getattr(new.render, k) != getattr(before.render, k)]
        app.config = new.model_copy(update={"render": render})
        follow_file(app.world, render)  # the light keys the file changed; the others keep what scripts set
        if live:
            if app.renderer is not None:
                app.renderer.use_settings(render)
            changes.append(f"render: {', '.join(live)} updated")
        if waiting:
            changes.append(f"render: {', '.join(waiting)} apply when the game is run again")
        return changes

    def _notes(self) -> list[Problem]:
        """What the file asks for that the running game does not do yet (shown with the warnings until done)."""
        app = self.app
        wanted, started = app.plan.config, self._started
        text = _text(app.plan.file)
        notes = []

        def note(key: str, message: str, value: Any) -> None:
            notes.append(Problem(str(app.plan.file), key, message, value, line=locate_line(text, key.split("."))))

        seed = wanted.scene.seed
        if app.seed_from_scene and seed != app.world.seed:
            note("scene.seed", f"applies on restart (R); the running world keeps seed {app.world.seed}", seed)
        elif not app.seed_from_scene and seed != started.scene.seed:
            note("scene.seed", f"not used: this run's seed {app.seed} was given when it started", seed)
        for key in ("width", "height"):
            if getattr(wanted.render, key) != getattr(started.render, key):
                note(f"render.{key}", "the window's size is not reloaded: resize the window, or run the game again",
                     getattr(wanted.render, key))
        if wanted.render.vsync != started.render.vsync:
            note("render.vsync", "set when the window opens: applies when the game is run again",
                 wanted.render.vsync)
        return notes

    # ----------------------------------------------------------------- applying
    def _apply(self, plan) -> list[str]:
        """Bring the world to ``plan`` entity by entity.  A planned entity keeps the live entity it was built
        as: the old one at the same index with the same name, else the first unused old one of that name (so
        inserting an entity above the others keeps every simulation running).  An entity whose update fails
        keeps what it had; ``app.records`` always ends up describing the world as it is."""
        app, world = self.app, self.app.world
        changes: list[str] = []
        records: list[EntityRecord] = []
        old_records = list(app.records)
        used: set[int] = set()

        def live(j: int, name: str | None = None) -> bool:
            old = old_records[j]
            return j not in used and (name is None or old.name == name) and world.alive(old.entity)

        matched: list[EntityRecord | None] = []  # by name: the same index first, then the first unused
        for i, ent in enumerate(plan.entities):
            order = ([i] if i < len(old_records) else []) + [j for j in range(len(old_records)) if j != i]
            j = next((j for j in order if live(j, ent.name)), None)
            if j is not None:
                used.add(j)
            matched.append(None if j is None else old_records[j])
        replaced: list[EntityRecord | None] = []  # an entity renamed in place: the new one replaces the old
        for i, old in enumerate(matched):
            take = old is None and i < len(old_records) and live(i)
            if take:
                used.add(i)
            replaced.append(old_records[i] if take else None)
        for i, ent in enumerate(plan.entities):
            old, previous = matched[i], replaced[i]
            if old is None:
                try:  # build the new entity first: if it fails, the entity it replaces stays
                    record = spawn_entity(world, app.registry, plan, i, ent)
                except ConfigError as exc:
                    self.status.errors.extend(str(p) for p in exc.problems)
                    changes.append(f"entities[{i}] '{ent.name}': spawn failed"
                                   + (f", kept '{previous.name}'" if previous is not None else ""))
                    if previous is not None:
                        records.append(previous)
                    continue
                if previous is not None:
                    world.despawn(previous.entity)
                    changes.append(f"despawned '{previous.name}'")
                records.append(record)
                changes.append(f"spawned '{ent.name}'")
                continue
            records.append(old)
            try:
                changes += self._apply_components(old, ent, plan.file, f"entities[{i}].")
                changes += self._apply_scripts(old, ent, f"{plan.file}: entities[{i}].scripts")
            except Exception as exc:  # noqa: BLE001 - a plugin's hook failing keeps this entity as it was
                log.error("reload of %s: entities[%d] '%s' failed", plan.file, i, ent.name, exc_info=exc)
                self.status.errors.append(f"{plan.file}: entities[{i}] '{ent.name}': update failed: "
                                          f"{type(exc).__name__}: {exc}")
                changes.append(f"entities[{i}] '{ent.name}': update failed, kept as it was")
        for j, old in enumerate(old_records):
            if j not in used and world.alive(old.entity):
                world.despawn(old.entity)
                changes.append(f"despawned '{old.name}'")
        app.records = records
        return changes

    # ------------------------------------------------------------------ prefabs
    def _replan_prefabs(self, fixed_dt: float) -> tuple[dict[str, tuple[EntityPlan, dict]], list[Problem]]:
        """The running game's loaded prefabs, planned again from their files at ``fixed_dt``, and their problems."""
        library = self.app.world.try_resource(PrefabLibrary)
        if library is None:
            return {}, []
        return library.replan(fixed_dt)

    def _apply_prefabs(self, prefabs: dict[str, tuple[EntityPlan, dict]], fixed_dt: float) -> list[str]:
        """Put the prefabs' new plans in force for the next spawns (a line names each prefab that changed), and
        bring every live entity spawned from one (ascending ids) to its new plan, as a scene's entity is brought to
        its new table, keeping its position.  The same change or error on many entities of one prefab is reported
        once, with their number."""
        from engine.builtin import Name
        from engine.spatial import Transform

        world = self.app.world
        library = world.try_resource(PrefabLibrary)
        if library is None:
            return []
        before = library.loaded()
        library.use(prefabs, fixed_dt)
        changes: dict[str, int] = {f"prefab {name}: the next spawns take the edit": 1
                                   for name, (plan, _) in prefabs.items() if before.get(name) != plan}
        errors = len(self.status.errors)
        for entity, (instance,) in list(world.query(PrefabInstance)):
            if instance.prefab not in prefabs:
                continue
            ent = prefabs[instance.prefab][0]
            file = library.file_of(instance.prefab)
            name = world.try_get(entity, Name)
            record = EntityRecord(entity, name.value if name is not None else ent.name, instance.components)
            label = f"prefab {instance.prefab}"
            before = world.try_get(entity, Transform)
            try:
                found = self._apply_components(record, ent, file, "", label)
                found += self._apply_scripts(record, ent, f"{file}: scripts", label)
            except Exception as exc:  # noqa: BLE001 - a plugin's hook failing keeps this entity as it was
                log.error("reload of prefab %s: entity %d failed", file, entity, exc_info=exc)
                self.status.errors.append(f"{file}: update failed: {type(exc).__name__}: {exc}")
                found = [f"{label}: update failed, kept as it was"]
            after = world.try_get(entity, Transform)
            if before is not None and after is not None and after is not before:
                after.position = before.position.copy()  # where it was spawned, or has gone since: not the prefab's
            for change in found:
                changes[change] = changes.get(change, 0) + 1
        self.status.errors[errors:] = list(dict.fromkeys(self.status.errors[errors:]))
        return [change if n == 1 else f"{change} ({n} entities)" for change, n in changes.items()]

    # ----------------------------------------------------------------- entities
    def _apply_components(self, record: EntityRecord, ent, file: Path, prefix: str,
                          label: str | None = None) -> list[str]:
        """Bring ``record``'s components to the configs of ``ent`` (an entity's plan from ``file``; problems are
        reported at ``prefix`` + ``components.<name>``); changes are named after ``label`` (the entity's name)."""
        world, registry = self.app.world, self.app.registry
        label = record.name if label is None else label
        changes = []
        new_names = {cname for cname, _ in ent.components}
        for cname in [c for c in record.components if c not in new_names]:
            for ctype in record.components.pop(cname)[1]:
                if world.has(record.entity, ctype):
                    world.remove(record.entity, ctype)
            changes.append(f"{label}: removed {cname}")
        for cname, cfg in ent.components:
            old = record.components.get(cname)
            asset_edited = self._uses_changed_asset(cfg)  # same config, new height map or texture: rebuilt
            if old is not None and old[0] == cfg and not asset_edited:
                continue
            spec = registry.component(cname)
            key = f"{prefix}components.{cname}"
            try:
                swapped = old is not None and not asset_edited and self._swap_in_place(spec, old, cfg, record.entity)
            except Exception as exc:  # noqa: BLE001 - a live_update hook raised: put the old config back
                world.add(record.entity, old[0])
                self.status.errors.append(str(build_problem(file, key, exc)))
                changes.append(f"{label}.{cname}: update failed, kept the old one")
                continue
            if swapped:
                record.components[cname] = (cfg, old[1])
                changes.append(f"{label}.{cname}: parameters updated ({', '.join(_diff(old[0], cfg))})")
                continue
            try:
                ctx = BuildContext(world, record.entity, record.name, str(file), self.app.plan.configs_root)
                built = spec.instantiate(cfg, ctx)
            except Exception as exc:  # noqa: BLE001 - the old component stays in force
                self.status.errors.append(str(build_problem(file, key, exc)))
                changes.append(f"{label}.{cname}: rebuild failed, kept the old one")
                continue
            types = [type(c) for c in built]
            for ctype in old[1] if old else []:
                if ctype not in types and world.has(record.entity, ctype):
                    world.remove(record.entity, ctype)
            for comp in built:
                world.add(record.entity, comp)
            record.components[cname] = (cfg, types)
            changes.append(f"{label}.{cname}: rebuilt" + (" (a file it reads changed)" if asset_edited else ""))
        return changes

    def _swap_in_place(self, spec, old: tuple[Any, list[type]], cfg: Any, entity: int) -> bool:
        world = self.app.world
        old_cfg, types = old
        if spec.build is not None:
            if spec.structural is None or type(cfg) not in types:
                return False
            if any(key in spec.structural for key in _diff(old_cfg, cfg)):
                return False
        world.add(entity, cfg)
        if spec.live_update is not None:
            spec.live_update(old_cfg, cfg, world, entity)
        return True

    def _apply_scripts(self, record: EntityRecord, ent, key: str, label: str | None = None) -> list[str]:
        world = self.app.world
        label = record.name if label is None else label
        scripts = world.try_get(record.entity, Scripts)
        slots = scripts.slots if scripts else []
        wanted = ent.scripts
        if [s.name for s in slots] == [cls.script_name for cls, _, _ in wanted]:
            changes = []
            for slot, (cls, params, enabled) in zip(slots, wanted):
                if slot.script.params != params:
                    slot.script.params = params
                    changes.append(f"{label}: script '{slot.name}' parameters updated")
            return changes
        new_slots = [make_slot(world, record.entity, cls, params, f"{key}[{j}]")
                     for j, (cls, params, _) in enumerate(wanted)]
        for slot, (_, _, enabled) in zip(new_slots, wanted):
            slot.enabled = enabled
        if scripts is not None:
            world.remove(record.entity, Scripts)
        if new_slots:
            world.add(record.entity, Scripts(new_slots))
        return [f"{label}: scripts replaced"]


def _diff(old: Any, new: Any) -> list[str]:
    fields = type(new).model_fields if hasattr(type(new), "model_fields") else {}
    return [k for k in fields if getattr(old, k, None) != getattr(new, k, None)]


def _text(path: Path) -> str:
    try:
        return Path(path).read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError):
        return ""


def _unsuited(model: type, cfg: Any, old_dt: float, new_dt: float) -> str | None:
    """Why ``cfg`` fails validation at ``new_dt`` while it passes at ``old_dt`` (None when it passes at both, or
    when it does not survive the round trip through a dict at all: then nothing is known about the step)."""
    try:
        data = cfg.model_dump()
    except Exception:  # noqa: BLE001 - not a pydantic model after all
        return None

    def problem(dt: float) -> str | None:
        try:
            model.model_validate(data, context={"fixed_dt": dt})
        except ValidationError as exc:
            return "; ".join(str(error.get("msg", "")) for error in exc.errors())
        except Exception as exc:  # noqa: BLE001 - a validator raising something else is a failure too
            return f"{type(exc).__name__}: {exc}"
        return None

    return problem(new_dt) if problem(old_dt) is None else None


def _entity_assets(entities: Iterable[EntityPlan], root: Path) -> list[Path]:
    """The asset files (height maps, textures) that the components of planned entities name and that exist."""
    found = [path for ent in entities for _, cfg in ent.components
             for path in _asset_paths(cfg.model_dump(mode="json", warnings=False), root) if path.is_file()]
    return list(dict.fromkeys(found))


def _asset_paths(table: Any, root: Path) -> list[Path]:
    """The strings in ``table`` (nested tables and arrays too) that name a file under the configs root, as
    engine.config.resolve_asset finds it (a texture, a height map): those with a file suffix."""
    found = []
    stack = [table]
    while stack:
        value = stack.pop()
        if isinstance(value, dict):
            stack.extend(value.values())
        elif isinstance(value, list):
            stack.extend(value)
        elif isinstance(value, str) and len(value) < 512 and Path(value).suffix:
            try:
                found.append(resolve_asset(root, value))
            except (ValueError, OSError):
                pass
    return found
