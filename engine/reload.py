"""Hot reload of the scene file and every preset it loaded.

:class:`HotReloader` polls the files' contents (size, mtime, then a BLAKE2b digest, so an editor's
touch without a change does nothing).  On a change it re-plans the whole scene:

* invalid: the last good config stays in force; the problems (file, key path, value, expectation,
  did-you-mean) go to the log and to :class:`ReloadStatus`, which the HUD shows until the file is fixed;
* valid: per entity (matched by position and name), each component whose config changed is either
  swapped in place (its ``structural`` keys unchanged: the new parameters are live at the next tick and
  the simulation state is kept) or rebuilt alone; script parameters are swapped in place; entities
  added to or removed from the file are spawned or despawned.
"""

from __future__ import annotations

import hashlib
import logging
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

from engine.config import ConfigError
from engine.scene import EntityRecord, build_component, build_problem, plan_scene, spawn_entity
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


class HotReloader:
    """Watches an app's scene and presets and applies edits to the live world."""

    def __init__(self, app: App) -> None:
        if app.plan is None:
            raise ValueError("hot reload needs an app built from a scene file")
        self.app = app
        self.status = ReloadStatus(warnings=[str(w) for w in app.warnings])
        app.world.insert_resource(self.status)
        self._prints: dict[Path, tuple] = {}
        self._watch(app.plan.files)

    def _watch(self, files: list[Path]) -> None:
        self._prints = {Path(f): _fingerprint(Path(f)) for f in files}

    def changed(self) -> bool:
        for path, old in self._prints.items():
            new = _fingerprint(path)
            if new != old and (new[0], new[2]) != (old[0], old[2]):
                return True
            self._prints[path] = new  # same content, touched: remember the new mtime
        return False

    def poll(self) -> bool:
        """Reload when a watched file's content changed; returns True when a reload was attempted."""
        if not self.changed():
            return False
        self.reload()
        return True

    def reload(self) -> bool:
        """Re-plan and apply (F5 calls this directly). Returns True when the new config is in force."""
        app = self.app
        try:
            plan = plan_scene(app.plan.file, app.registry, app.plan.configs_root)
        except ConfigError as exc:
            self._watch(list(self._prints))  # do not report the same broken content every poll
            self.status.errors = [str(p) for p in exc.problems]
            log.error("reload failed; keeping the last good config:\n%s", exc)
            return False
        self.status.errors = []
        self.status.warnings = [str(w) for w in plan.warnings]
        for warning in plan.warnings:
            log.warning("%s", warning)
        try:
            changes = self._apply(plan)
        except Exception as exc:  # noqa: BLE001 - a plugin's hook failing must not take the game down
            log.error("reload of %s failed while applying", plan.file, exc_info=exc)
            self.status.errors.append(f"{plan.file}: reload failed while applying: {type(exc).__name__}: {exc}")
            changes = ["reload failed while applying; see the errors"]
        self._watch(plan.files)
        app.plan = plan
        self.status.reloads += 1
        self.status.last_changes = changes
        log.info("reloaded %s: %s", plan.file, "; ".join(changes) or "no effective change")
        return True

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
                changes += self._apply_components(plan, i, old, ent)
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

    def _apply_components(self, plan, index: int, record: EntityRecord, ent) -> list[str]:
        world, registry = self.app.world, self.app.registry
        changes = []
        new_names = {cname for cname, _ in ent.components}
        for cname in [c for c in record.components if c not in new_names]:
            for ctype in record.components.pop(cname)[1]:
                if world.has(record.entity, ctype):
                    world.remove(record.entity, ctype)
            changes.append(f"{record.name}: removed {cname}")
        for cname, cfg in ent.components:
            old = record.components.get(cname)
            if old is not None and old[0] == cfg:
                continue
            spec = registry.component(cname)
            key = f"entities[{index}].components.{cname}"
            try:
                swapped = old is not None and self._swap_in_place(spec, old, cfg, record.entity)
            except Exception as exc:  # noqa: BLE001 - a live_update hook raised: put the old config back
                world.add(record.entity, old[0])
                self.status.errors.append(str(build_problem(plan.file, key, exc)))
                changes.append(f"{record.name}.{cname}: update failed, kept the old one")
                continue
            if swapped:
                record.components[cname] = (cfg, old[1])
                changes.append(f"{record.name}.{cname}: parameters updated ({', '.join(_diff(old[0], cfg))})")
                continue
            try:
                built = build_component(world, registry, plan, record.entity, record.name, cname, cfg)
            except Exception as exc:  # noqa: BLE001 - the old component stays in force
                self.status.errors.append(str(build_problem(plan.file, key, exc)))
                changes.append(f"{record.name}.{cname}: rebuild failed, kept the old one")
                continue
            types = [type(c) for c in built]
            for ctype in old[1] if old else []:
                if ctype not in types and world.has(record.entity, ctype):
                    world.remove(record.entity, ctype)
            for comp in built:
                world.add(record.entity, comp)
            record.components[cname] = (cfg, types)
            changes.append(f"{record.name}.{cname}: rebuilt")
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

    def _apply_scripts(self, record: EntityRecord, ent, key: str) -> list[str]:
        world = self.app.world
        scripts = world.try_get(record.entity, Scripts)
        slots = scripts.slots if scripts else []
        wanted = ent.scripts
        if [s.name for s in slots] == [cls.script_name for cls, _, _ in wanted]:
            changes = []
            for slot, (cls, params, enabled) in zip(slots, wanted):
                if slot.script.params != params:
                    slot.script.params = params
                    changes.append(f"{record.name}: script '{slot.name}' parameters updated")
            return changes
        new_slots = [make_slot(world, record.entity, cls, params, f"{key}[{j}]")
                     for j, (cls, params, _) in enumerate(wanted)]
        for slot, (_, _, enabled) in zip(new_slots, wanted):
            slot.enabled = enabled
        if scripts is not None:
            world.remove(record.entity, Scripts)
        if new_slots:
            world.add(record.entity, Scripts(new_slots))
        return [f"{record.name}: scripts replaced"]


def _diff(old: Any, new: Any) -> list[str]:
    fields = type(new).model_fields if hasattr(type(new), "model_fields") else {}
    return [k for k in fields if getattr(old, k, None) != getattr(new, k, None)]
