"""Render graph (frame graph): passes declare resources; compiling orders, culls and pools them.

Each frame, passes are declared with a *setup* callback that says which resources the pass creates,
reads and writes, and an *execute* callback that records the GL work. :meth:`RenderGraph.compile`
validates the declarations, orders passes by their dependencies (ties broken by declaration order),
culls passes whose outputs nobody reads, and computes each resource's lifetime; :meth:`execute`
then runs the passes, taking transient resources from a :class:`ResourcePool` just before their
first use and handing them back right after their last use, so later passes and later frames reuse
them.

One :class:`RenderGraph` lives as long as the renderer; :meth:`RenderGraph.reset` is the per-frame
entry point. It forgets the frame's declarations (handles from before it become stale) but keeps
the pool and the compile cache, so a frame whose declared structure matches an earlier one reuses
that compiled graph instead of compiling again (see :attr:`RenderGraph.compile_count`)::

    graph = RenderGraph(ResourcePool(factory=make_texture, destroy=free_texture))
    for each frame:
        graph.reset()
        heights = graph.import_resource("height_field", height_texture, TextureDesc(256, 256, "r32f"))
        graph.add_pass("water", setup=..., execute=...)
        graph.execute()

Compilation follows skaarj1989/FrameGraph (``src/FrameGraph.cpp``): a pass's reference count is the
number of versions it writes that someone reads; culling a pass releases its reads, which may in
turn cull their producers. Resources are versioned: each write returns a new handle, so the order of
writes is explicit in the declarations. A read may also name a resource (``builder.read("hdr")``):
it then reads the resource's last version this frame, which lets a consumer be declared before its
producer (plugins add passes in any order).

This module is pure Python; GL objects enter only through the pool's factory and imported resources.
"""

from __future__ import annotations

import difflib
import heapq
import itertools
from collections import OrderedDict, defaultdict
from collections.abc import Callable, Hashable, Iterable
from dataclasses import dataclass, field

_TEXTURE_FORMATS: dict[str, tuple[int, str]] = {
    # format: (components, moderngl dtype)
    "r8": (1, "f1"), "rg8": (2, "f1"), "rgb8": (3, "f1"), "rgba8": (4, "f1"),
    "r16f": (1, "f2"), "rg16f": (2, "f2"), "rgb16f": (3, "f2"), "rgba16f": (4, "f2"),
    "r32f": (1, "f4"), "rg32f": (2, "f4"), "rgb32f": (3, "f4"), "rgba32f": (4, "f4"),
    "depth16": (1, "f2"), "depth24": (1, "f4"), "depth32f": (1, "f4"),
}
_EPOCHS = itertools.count(1)  # every frame of every graph gets its own epoch: handles cannot cross


class GraphError(Exception):
    """A render graph declaration, compilation or execution error; the message names what is wrong."""


def _did_you_mean(word: str, choices: Iterable[str]) -> str:
    close = difflib.get_close_matches(word, list(choices), n=1)
    return f", did you mean '{close[0]}'?" if close else ""


def _quoted(names: Iterable[str]) -> str:
    items = [f"'{name}'" for name in names]
    return items[0] if len(items) == 1 else ", ".join(items[:-1]) + " and " + items[-1]


def _positive_int(value: object) -> bool:
    return isinstance(value, int) and not isinstance(value, bool) and value > 0


@dataclass(frozen=True)
class TextureDesc:
    """A 2-D texture: size in pixels and format (``"rgba8"``, ``"rgba16f"``, ``"r32f"``, ``"depth24"``...)."""

    width: int
    height: int
    format: str = "rgba8"

    def __post_init__(self) -> None:
        if not (_positive_int(self.width) and _positive_int(self.height)):
            raise GraphError(f"TextureDesc size must be positive integers, got {self.width!r} x {self.height!r}")
        if self.format not in _TEXTURE_FORMATS:
            known = ", ".join(_TEXTURE_FORMATS)
            hint = _did_you_mean(self.format, _TEXTURE_FORMATS)
            raise GraphError(f"unknown texture format '{self.format}'{hint} (known: {known})")

    @property
    def components(self) -> int:
        """Channels per texel (1 for depth formats)."""
        return _TEXTURE_FORMATS[self.format][0]

    @property
    def dtype(self) -> str:
        """moderngl's dtype string for the format (``"f1"``, ``"f2"`` or ``"f4"``)."""
        return _TEXTURE_FORMATS[self.format][1]

    @property
    def is_depth(self) -> bool:
        """True for depth formats (a depth attachment rather than a colour texture)."""
        return self.format.startswith("depth")

    def __str__(self) -> str:
        return f"{self.width}x{self.height} {self.format}"


@dataclass(frozen=True)
class BufferDesc:
    """A GPU buffer of ``size`` bytes."""

    size: int

    def __post_init__(self) -> None:
        if not _positive_int(self.size):
            raise GraphError(f"BufferDesc size must be a positive integer number of bytes, got {self.size!r}")

    def __str__(self) -> str:
        return f"{self.size} B buffer"


@dataclass(frozen=True)
class ResourceHandle:
    """One version of a resource in one frame of one graph.

    Each write returns a handle to a new version. A handle read after its resource was written again,
    or used after :meth:`RenderGraph.reset` or in another graph, is stale and rejected. A read by name
    returns a handle with ``index == -1`` that stands for the resource's last version this frame.
    """

    index: int
    version: int
    name: str
    graph_epoch: int = field(default=-1, repr=False)

    @property
    def by_name(self) -> bool:
        """True for the handle of a read by name (resolved when the graph compiles)."""
        return self.index < 0


@dataclass(frozen=True)
class _Resource:
    name: str
    desc: Hashable | None
    imported: bool
    creator: str | None  # the pass that created a transient resource


@dataclass(frozen=True)
class _Write:
    index: int
    source: int  # version written over
    version: int  # version produced


@dataclass(frozen=True)
class _PassDecl:
    name: str
    side_effect: bool
    creates: tuple[int, ...]
    reads: tuple[tuple[int, int], ...]  # (resource index, version)
    named_reads: tuple[str, ...]
    writes: tuple[_Write, ...]
    no_wait: tuple[tuple[int, int], ...] = ()  # reads that need not wait for their writer (PassBuilder.read)


@dataclass(frozen=True)
class _Structure:
    """Everything compilation depends on; also the compile cache key."""

    resources: tuple[_Resource, ...]
    passes: tuple[_PassDecl, ...]
    final_versions: tuple[int, ...]


@dataclass(frozen=True)
class _Step:
    pass_index: int
    acquire: tuple[int, ...]  # transient resources to take from the pool before the pass
    release: tuple[int, ...]  # transient resources to hand back after it


class ResourcePool:
    """Transient GPU resources kept across frames and reused for identical descriptors.

    ``factory(desc)`` makes a new object when no free one matches; ``destroy(obj)`` frees one in
    :meth:`trim` and :meth:`clear`. Descriptors are compared by value, so only an identical
    descriptor reuses an object.
    """

    def __init__(self, factory: Callable[[Hashable], object], destroy: Callable[[object], None] | None = None) -> None:
        self._factory = factory
        self._destroy = destroy
        self._free: dict[Hashable, list[tuple[object, int]]] = {}  # desc -> [(object, frame released)]
        self._live: dict[int, tuple[object, Hashable]] = {}  # id(object) -> (object, desc)
        self.allocations = 0  # factory calls
        self.frame = 0  # frames seen (advanced once per RenderGraph.execute)

    @property
    def live_count(self) -> int:
        """Objects acquired and not yet released."""
        return len(self._live)

    @property
    def free_count(self) -> int:
        """Objects waiting in the pool for reuse."""
        return sum(len(free) for free in self._free.values())

    def acquire(self, desc: Hashable) -> object:
        """A free object made for ``desc``, or a new one from the factory."""
        free = self._free.get(desc)
        if free:
            obj = free.pop()[0]
        else:
            obj = self._factory(desc)
            self.allocations += 1
        self._live[id(obj)] = (obj, desc)
        return obj

    def release(self, desc: Hashable, obj: object) -> None:
        """Return ``obj`` (acquired for ``desc``) to the pool for reuse."""
        entry = self._live.get(id(obj))
        if entry is None or entry[0] is not obj:
            raise GraphError(f"cannot release {obj!r} ({desc}): it is not in use from this pool "
                             "(released twice, or an imported resource?)")
        if entry[1] != desc:
            raise GraphError(f"cannot release {obj!r} as {desc}: it was acquired as {entry[1]}")
        del self._live[id(obj)]
        self._free.setdefault(desc, []).append((obj, self.frame))

    def advance_frame(self) -> None:
        """Mark the end of a frame (for :meth:`trim`)."""
        self.frame += 1

    def trim(self, max_idle_frames: int) -> int:
        """Destroy free objects unused for more than ``max_idle_frames`` whole frames; return how many."""
        return self._drop(lambda released: self.frame - released - 1 > max_idle_frames)

    def clear(self) -> int:
        """Destroy every free object; return how many."""
        return self._drop(lambda released: True)

    def _drop(self, expired: Callable[[int], bool]) -> int:
        dropped = 0
        for desc, free in list(self._free.items()):
            keep = [entry for entry in free if not expired(entry[1])]
            for obj, released in free:
                if expired(released) and self._destroy is not None:
                    self._destroy(obj)
            dropped += len(free) - len(keep)
            if keep:
                self._free[desc] = keep
            else:
                del self._free[desc]
        return dropped


class PassBuilder:
    """Declares one pass's resource accesses; given to the pass's setup callback."""

    def __init__(self, graph: RenderGraph, pass_name: str) -> None:
        self._graph = graph
        self._pass = pass_name
        self._creates: list[int] = []
        self._reads: list[tuple[int, int]] = []
        self._named_reads: list[str] = []
        self._writes: list[_Write] = []
        self._no_wait: list[tuple[int, int]] = []
        self._sealed = False

    def create(self, name: str, desc: Hashable) -> ResourceHandle:
        """Declare a transient resource (taken from the pool); write it before anyone reads it."""
        self._check_open("create", name)
        index = self._graph._declare(name, desc, imported=False, creator=self._pass)
        self._creates.append(index)
        return self._graph._handle(index, 0)

    def read(self, target: ResourceHandle | str, wait: bool = True) -> ResourceHandle:
        """Declare a read of a handle's version, or by name of the resource's last version this frame.

        ``wait=False``: the pass samples it on the GPU right after a small pass wrote it (a shadow map), so the
        CPU has no reason to wait there: the read does not make the pass the frame's synchronisation point
        (:attr:`CompiledGraph.sync_pass`), where the renderer hands the queued passes to the GPU and overlaps
        the next simulation ticks with them."""
        self._check_open("read", target)
        if isinstance(target, ResourceHandle) and target.by_name:
            self._graph._check_epoch(target, self._pass, "reads")
            target = target.name
        if isinstance(target, str):
            return self._read_by_name(target)
        index = self._graph._check_handle(target, self._pass, "reads")
        self._graph._check_latest(target, self._pass)
        if (index, target.version) not in self._reads:
            self._reads.append((index, target.version))
        if not wait and (index, target.version) not in self._no_wait:
            self._no_wait.append((index, target.version))
        return target

    def write(self, handle: ResourceHandle) -> ResourceHandle:
        """Declare a write over ``handle``'s version; returns the handle of the new version."""
        self._check_open("write", handle)
        index = self._graph._check_handle(handle, self._pass, "writes")
        version = self._graph._new_version(index, self._pass)
        self._writes.append(_Write(index, handle.version, version))
        return self._graph._handle(index, version)

    def _read_by_name(self, name: str) -> ResourceHandle:
        if not name:
            raise GraphError(f"pass '{self._pass}' reads a resource with an empty name")
        if name not in self._named_reads:
            self._named_reads.append(name)
        return ResourceHandle(-1, -1, name, self._graph._epoch)

    def _check_open(self, verb: str, what: object) -> None:
        if self._sealed:
            raise GraphError(f"pass '{self._pass}' tried to {verb} {what!r} after its setup returned; "
                             "declare resources inside the setup callback")

    def _declaration(self, side_effect: bool) -> _PassDecl:
        return _PassDecl(self._pass, side_effect, tuple(self._creates), tuple(self._reads),
                         tuple(self._named_reads), tuple(self._writes), tuple(self._no_wait))


class PassContext:
    """What a pass's execute callback sees: the resources it declared."""

    def __init__(self, graph: RenderGraph, pass_index: int, objects: dict[int, object]) -> None:
        self._graph = graph
        self._decl = graph._passes[pass_index]
        self._objects = objects

    @property
    def pass_name(self) -> str:
        """The name of the running pass."""
        return self._decl.name

    def get(self, handle: ResourceHandle | str) -> object:
        """The resource object (pooled or imported) behind a handle or resource name."""
        index = self._graph._index_for(handle, self._decl.name)
        if index not in _touched(self._decl, self._graph._by_name):
            name = self._graph._resources[index].name
            raise GraphError(f"pass '{self._decl.name}' uses '{name}' without declaring it; "
                             "add builder.read(...) or builder.write(...) to its setup")
        return self._objects[index]


class CompiledGraph:
    """The result of compiling one declared structure; shared by every frame with that structure.

    ``order``: names of the passes that run, in order. ``culled``: names of the passes that do not.
    ``lifetimes``: resource name -> (first, last) position in ``order`` of the passes that use it.
    """

    def __init__(self, structure: _Structure, reads: list[tuple[tuple[int, int], ...]],
                 order: list[int], culled: list[bool]) -> None:
        self._structure = structure
        self._reads = reads
        self._culled = culled
        self._positions = {pass_index: step for step, pass_index in enumerate(order)}
        spans = _spans(structure, reads, order)
        self.order: list[str] = [structure.passes[p].name for p in order]
        self.culled: list[str] = [decl.name for decl, dead in zip(structure.passes, culled) if dead]
        self.lifetimes: dict[str, tuple[int, int]] = {
            structure.resources[index].name: span for index, span in sorted(spans.items())}
        self._steps = _steps(structure, order, spans)
        # the first pass that reads what an earlier pass of the frame wrote (a version >= 1): the GPU must have
        # finished that work before it can go on, so it is where the CPU would first wait (RenderGraph.execute)
        self.first_sync: int | None = next((step for step, p in enumerate(order)
                                            if any(version >= 1 and (index, version) not in
                                                   structure.passes[p].no_wait
                                                   for index, version in reads[p])), None)
        self.sync_pass: str | None = None if self.first_sync is None else self.order[self.first_sync]

    def __repr__(self) -> str:
        return f"CompiledGraph(order={self.order}, culled={self.culled})"

    def to_dot(self) -> str:
        """The graph in Graphviz format: passes are boxes, resource versions ellipses, culled dashed."""
        lines = ["digraph render_graph {", "  rankdir=LR;"]
        lines += [self._pass_node(p) for p in range(len(self._structure.passes))]
        nodes, edges = self._resource_nodes_and_edges()
        lines += nodes + edges + ["}"]
        return "\n".join(lines) + "\n"

    def _pass_node(self, p: int) -> str:
        decl = self._structure.passes[p]
        status = "culled" if self._culled[p] else f"#{self._positions[p]}"
        label = f"{_dot_escape(decl.name)}\\n{status}" + ("\\nside effect" if decl.side_effect else "")
        style = ", style=dashed" if self._culled[p] else (", style=bold" if decl.side_effect else "")
        return f'  {_dot_id("pass", decl.name)} [shape=box, label="{label}"{style}];'

    def _resource_nodes_and_edges(self) -> tuple[list[str], list[str]]:
        users: dict[tuple[int, int], list[int]] = defaultdict(list)
        edges = []
        for p, decl in enumerate(self._structure.passes):
            for index, version in self._reads[p]:
                users[(index, version)].append(p)
                edges.append(self._edge(self._version_id(index, version), _dot_id("pass", decl.name), p))
            for write in decl.writes:
                users[(write.index, write.version)].append(p)
                edges.append(self._edge(_dot_id("pass", decl.name), self._version_id(write.index, write.version), p))
        nodes = [self._version_node(key, all(self._culled[p] for p in passes)) for key, passes in sorted(users.items())]
        return nodes, edges

    def _version_node(self, key: tuple[int, int], dead: bool) -> str:
        resource = self._structure.resources[key[0]]
        detail = "imported" if resource.imported else "transient"
        if resource.desc is not None:
            detail += f" {resource.desc}"
        label = f"{_dot_escape(resource.name)} v{key[1]}\\n{_dot_escape(detail)}"
        style = ", style=dashed" if dead else (", peripheries=2" if resource.imported else "")
        return f'  {self._version_id(*key)} [shape=ellipse, label="{label}"{style}];'

    def _version_id(self, index: int, version: int) -> str:
        return _dot_id("res", f"{self._structure.resources[index].name}@{version}")

    def _edge(self, source: str, target: str, p: int) -> str:
        return f"  {source} -> {target}{' [style=dashed]' if self._culled[p] else ''};"


def _dot_escape(text: str) -> str:
    return text.replace("\\", "\\\\").replace('"', '\\"')


def _dot_id(kind: str, name: str) -> str:
    return f'"{kind}:{_dot_escape(name)}"'


class RenderGraph:
    """Declares, compiles (with a cache) and executes the render passes of each frame.

    Keep one graph for the renderer's lifetime and call :meth:`reset` at the start of every frame;
    the pool and the compile cache survive it. Setup callbacks run inside :meth:`add_pass`.
    """

    def __init__(self, pool: ResourcePool | None = None, *, cache_size: int = 8) -> None:
        if not _positive_int(cache_size):
            raise GraphError(f"cache_size must be a positive integer, got {cache_size!r}")
        self._pool = pool
        self._cache: OrderedDict[_Structure, CompiledGraph] = OrderedDict()
        self._cache_size = cache_size
        self._compile_count = 0
        self.reset()

    @property
    def pool(self) -> ResourcePool | None:
        """The pool transient resources come from."""
        return self._pool

    @property
    def compile_count(self) -> int:
        """How many times a structure was actually compiled (compile-cache misses that succeeded)."""
        return self._compile_count

    def reset(self) -> None:
        """Start a new frame: forget passes, resources and handles; keep the pool and compile cache."""
        self._epoch = next(_EPOCHS)
        self._resources: list[_Resource] = []
        self._versions: list[int] = []  # latest version of each resource
        self._producers: dict[tuple[int, int], str] = {}  # (index, version) -> writing pass
        self._by_name: dict[str, int] = {}
        self._imported: dict[int, object] = {}
        self._passes: list[_PassDecl] = []
        self._executes: list[Callable[[PassContext], None]] = []

    def import_resource(self, name: str, resource: object, desc: Hashable | None = None) -> ResourceHandle:
        """Bring a persistent resource (atlas, height field, screen) into this frame; never pooled.

        A pass that writes an imported resource is never culled: its effect outlives the frame.
        """
        if resource is None:
            raise GraphError(f"import_resource('{name}') got None instead of a resource object")
        index = self._declare(name, desc, imported=True, creator=None)
        self._imported[index] = resource
        return self._handle(index, 0)

    def add_pass(self, name: str, setup: Callable[[PassBuilder], None],
                 execute: Callable[[PassContext], None], side_effect: bool = False) -> None:
        """Declare a pass: ``setup(builder)`` runs now; ``execute(context)`` runs in :meth:`execute`.

        ``side_effect=True`` keeps the pass (and its inputs) even when nobody reads its outputs.
        """
        self._check_new_pass(name, setup, execute)
        builder = PassBuilder(self, name)
        saved = (len(self._resources), list(self._versions), dict(self._producers))
        try:
            setup(builder)
        except BaseException:
            self._rollback(*saved)
            raise
        finally:
            builder._sealed = True
        self._passes.append(builder._declaration(bool(side_effect)))
        self._executes.append(execute)

    def compile(self) -> CompiledGraph:
        """Validate, order, cull and plan resource lifetimes; cached by the declared structure."""
        structure = _Structure(tuple(self._resources), tuple(self._passes), tuple(self._versions))
        compiled = self._cache.get(structure)
        if compiled is not None:
            self._cache.move_to_end(structure)
            return compiled
        compiled = _compile(structure)
        self._compile_count += 1
        self._cache[structure] = compiled
        if len(self._cache) > self._cache_size:
            self._cache.popitem(last=False)
        return compiled

    def execute(self, on_sync: Callable[[], None] | None = None) -> None:
        """Compile (cached), then run the passes in order with their resources materialized.

        ``on_sync`` is called once: just before the first pass that reads what an earlier pass of the frame
        wrote (:attr:`CompiledGraph.sync_pass`), or after the last pass when none does.  Up to there the GPU
        has work queued that nothing waits for yet; the renderer flushes it there and lets the CPU do other
        work (the next simulation ticks) while the GPU, or a software rasteriser's threads, draw.
        """
        compiled = self.compile()
        objects: dict[int, object] = dict(self._imported)
        acquired: dict[int, object] = {}
        try:
            for position, step in enumerate(compiled._steps):
                if on_sync is not None and position == compiled.first_sync:
                    callback, on_sync = on_sync, None
                    callback()
                self._acquire(step, objects, acquired)
                self._run(step.pass_index, objects)
                self._release(step.release, objects, acquired)
        finally:
            self._release(tuple(acquired), objects, acquired)  # only left over when a pass raised
            if self._pool is not None:
                self._pool.advance_frame()
        if on_sync is not None:
            on_sync()

    def to_dot(self) -> str:
        """The compiled graph in Graphviz format (see :meth:`CompiledGraph.to_dot`)."""
        return self.compile().to_dot()

    # -- declaration helpers (used by PassBuilder) -------------------------------------------

    def _check_new_pass(self, name: str, setup: object, execute: object) -> None:
        if not isinstance(name, str) or not name:
            raise GraphError(f"a pass needs a non-empty name, got {name!r}")
        if any(decl.name == name for decl in self._passes):
            raise GraphError(f"pass '{name}' is declared twice this frame; pass names must be unique "
                             "(call reset() at the start of each frame)")
        for role, callback in (("setup", setup), ("execute", execute)):
            if not callable(callback):
                raise GraphError(f"pass '{name}': {role} must be callable, got {callback!r}")

    def _rollback(self, resource_count: int, versions: list[int], producers: dict[tuple[int, int], str]) -> None:
        for index in range(resource_count, len(self._resources)):
            del self._by_name[self._resources[index].name]
            self._imported.pop(index, None)
        del self._resources[resource_count:]
        self._versions = versions
        self._producers = producers

    def _declare(self, name: str, desc: Hashable | None, imported: bool, creator: str | None) -> int:
        who = f"pass '{creator}'" if creator else "import_resource"
        if not isinstance(name, str) or not name:
            raise GraphError(f"{who}: a resource needs a non-empty name, got {name!r}")
        if name in self._by_name:
            first = self._resources[self._by_name[name]]
            origin = "imported" if first.imported else f"created by pass '{first.creator}'"
            raise GraphError(f"{who} declares resource '{name}', which is already {origin} this frame; "
                             "resource names must be unique")
        _check_desc(name, desc, who, required=not imported)
        self._resources.append(_Resource(name, desc, imported, creator))
        self._versions.append(0)
        self._by_name[name] = len(self._resources) - 1
        return len(self._resources) - 1

    def _handle(self, index: int, version: int) -> ResourceHandle:
        return ResourceHandle(index, version, self._resources[index].name, self._epoch)

    def _new_version(self, index: int, pass_name: str) -> int:
        self._versions[index] += 1
        self._producers[(index, self._versions[index])] = pass_name
        return self._versions[index]

    def _check_epoch(self, handle: ResourceHandle, pass_name: str, verb: str) -> None:
        if handle.graph_epoch != self._epoch:
            raise GraphError(f"pass '{pass_name}' {verb} a stale handle to '{handle.name}' (version "
                             f"{handle.version}): it belongs to an earlier frame or another RenderGraph; "
                             "declare the resource again after reset()")

    def _check_handle(self, handle: object, pass_name: str, verb: str) -> int:
        if not isinstance(handle, ResourceHandle):
            raise GraphError(f"pass '{pass_name}' {verb} {handle!r}: expected a ResourceHandle from "
                             "create, import_resource or write" + (" (or a resource name)" if verb == "reads" else ""))
        self._check_epoch(handle, pass_name, verb)
        if handle.by_name:
            raise GraphError(f"pass '{pass_name}' {verb} '{handle.name}' through a read-by-name handle; "
                             "write the handle returned by create, import_resource or write")
        index = handle.index
        if not (0 <= index < len(self._resources)) or self._resources[index].name != handle.name:
            raise GraphError(self._unknown(pass_name, verb, handle.name))
        if handle.version > self._versions[index]:
            raise GraphError(f"pass '{pass_name}' {verb} unknown version {handle.version} of '{handle.name}' "
                             f"(latest is {self._versions[index]})")
        return index

    def _check_latest(self, handle: ResourceHandle, pass_name: str) -> None:
        latest = self._versions[handle.index]
        if handle.version < latest:
            writer = self._producers[(handle.index, handle.version + 1)]
            raise GraphError(f"pass '{pass_name}' reads a stale handle to '{handle.name}' (version "
                             f"{handle.version}): pass '{writer}' has since written it (now version {latest}); "
                             "read the handle that write returned")

    def _unknown(self, pass_name: str, verb: str, name: str) -> str:
        known = ", ".join(f"'{known}'" for known in self._by_name) or "none"
        return (f"pass '{pass_name}' {verb} unknown resource '{name}'{_did_you_mean(name, self._by_name)} "
                f"(declared this frame: {known})")

    def _index_for(self, handle: ResourceHandle | str, pass_name: str) -> int:
        if isinstance(handle, ResourceHandle):
            self._check_epoch(handle, pass_name, "uses")
            if not handle.by_name:
                return self._check_handle(handle, pass_name, "uses")
            handle = handle.name
        if not isinstance(handle, str) or handle not in self._by_name:
            raise GraphError(self._unknown(pass_name, "uses", str(handle)))
        return self._by_name[handle]

    # -- execution helpers -------------------------------------------------------------------

    def _acquire(self, step: _Step, objects: dict[int, object], acquired: dict[int, object]) -> None:
        for index in step.acquire:
            resource = self._resources[index]
            if self._pool is None:
                raise GraphError(f"pass '{self._passes[step.pass_index].name}' needs transient resource "
                                 f"'{resource.name}' ({resource.desc}) but the graph has no pool; "
                                 "use RenderGraph(pool=ResourcePool(factory))")
            objects[index] = acquired[index] = self._pool.acquire(resource.desc)

    def _release(self, indices: tuple[int, ...], objects: dict[int, object], acquired: dict[int, object]) -> None:
        for index in indices:
            obj = acquired.pop(index)
            del objects[index]
            self._pool.release(self._resources[index].desc, obj)

    def _run(self, pass_index: int, objects: dict[int, object]) -> None:
        try:
            self._executes[pass_index](PassContext(self, pass_index, objects))
        except Exception as error:
            error.add_note(f"while executing render pass '{self._passes[pass_index].name}'")
            raise


def _check_desc(name: str, desc: object, who: str, required: bool) -> None:
    if desc is None:
        if required:
            raise GraphError(f"{who}: transient resource '{name}' needs a descriptor (TextureDesc, BufferDesc)")
        return
    try:
        hash(desc)
    except TypeError:
        raise GraphError(f"{who}: the descriptor of '{name}' must be hashable (a frozen dataclass such as "
                         f"TextureDesc), got {desc!r}") from None


def _touched(decl: _PassDecl, by_name: dict[str, int]) -> list[int]:
    """Resource indices a pass declared in any way, in first-mention order."""
    indices = list(decl.creates) + [index for index, _ in decl.reads]
    indices += [by_name[name] for name in decl.named_reads if name in by_name]
    indices += [write.index for write in decl.writes]
    return list(dict.fromkeys(indices))


# -- compilation ---------------------------------------------------------------------------------


def _compile(structure: _Structure) -> CompiledGraph:
    reads, problems = _resolve_reads(structure)
    producers = _producers(structure)
    if not problems:
        problems = _access_problems(structure, reads, producers)
    if problems:
        raise GraphError(problems[0] if len(problems) == 1 else
                         "render graph has errors:\n  " + "\n  ".join(problems))
    edges = _dependencies(structure, reads, producers)
    _check_acyclic(structure, edges)
    culled = _cull(structure, reads, producers)
    order = _topological_order([p for p, dead in enumerate(culled) if not dead], edges)
    return CompiledGraph(structure, reads, order, culled)


def _resolve_reads(structure: _Structure) -> tuple[list[tuple[tuple[int, int], ...]], list[str]]:
    """Every pass's reads as (index, version); a read by name gets the last version of the frame."""
    by_name = {resource.name: index for index, resource in enumerate(structure.resources)}
    resolved, problems = [], []
    for decl in structure.passes:
        reads = list(decl.reads)
        for name in decl.named_reads:
            if name not in by_name:
                known = ", ".join(f"'{known}'" for known in by_name) or "none"
                problems.append(f"pass '{decl.name}' reads unknown resource '{name}'"
                                f"{_did_you_mean(name, by_name)} (declared this frame: {known})")
            elif (by_name[name], structure.final_versions[by_name[name]]) not in reads:
                reads.append((by_name[name], structure.final_versions[by_name[name]]))
        resolved.append(tuple(reads))
    return resolved, problems


def _producers(structure: _Structure) -> dict[tuple[int, int], int]:
    """(resource index, version) -> index of the pass whose write produced it."""
    return {(write.index, write.version): p
            for p, decl in enumerate(structure.passes) for write in decl.writes}


def _access_problems(structure: _Structure, reads: list[tuple[tuple[int, int], ...]],
                     producers: dict[tuple[int, int], int]) -> list[str]:
    return (_feedback_problems(structure, reads) + _writer_conflicts(structure)
            + _missing_inputs(structure, reads, producers))


def _feedback_problems(structure: _Structure, reads: list[tuple[tuple[int, int], ...]]) -> list[str]:
    """A pass that reads and writes the same resource (sampling what it renders into)."""
    problems = []
    for decl, pass_reads in zip(structure.passes, reads):
        written = {write.index for write in decl.writes}
        for index, version in pass_reads:
            if index in written:
                problems.append(f"pass '{decl.name}' reads and writes '{structure.resources[index].name}' "
                                f"(version {version}); a pass cannot sample what it renders into: "
                                "write a second resource and ping-pong between them")
    return problems


def _writer_conflicts(structure: _Structure) -> list[str]:
    """Two passes writing over the same version: neither sees the other's result, so no order exists."""
    writers: dict[tuple[int, int], list[str]] = defaultdict(list)
    for decl in structure.passes:
        for write in decl.writes:
            if decl.name not in writers[(write.index, write.source)]:
                writers[(write.index, write.source)].append(decl.name)
    return [f"passes {_quoted(names)} all write '{structure.resources[index].name}' version {version} "
            "with no order between them; chain the writes: write the handle the earlier write returned"
            for (index, version), names in writers.items() if len(names) > 1]


def _missing_inputs(structure: _Structure, reads: list[tuple[tuple[int, int], ...]],
                    producers: dict[tuple[int, int], int]) -> list[str]:
    problems = []
    for decl, pass_reads in zip(structure.passes, reads):
        for index, version in pass_reads:
            resource = structure.resources[index]
            if (index, version) not in producers and not resource.imported:
                problems.append(f"pass '{decl.name}' reads '{resource.name}' (version {version}), but no pass "
                                f"writes it and it is not imported (created by pass '{resource.creator}'); "
                                "write it before reading: handle = builder.write(builder.create(...))")
    return problems


def _dependencies(structure: _Structure, reads: list[tuple[tuple[int, int], ...]],
                  producers: dict[tuple[int, int], int]) -> dict[tuple[int, int], str]:
    """(before, after) pass pairs, each with the reason, in a deterministic order."""
    names = [decl.name for decl in structure.passes]
    readers: dict[tuple[int, int], list[int]] = defaultdict(list)
    for p, pass_reads in enumerate(reads):
        for key in pass_reads:
            readers[key].append(p)
    edges: dict[tuple[int, int], str] = {}
    for p, decl in enumerate(structure.passes):
        for key in reads[p]:
            if key in producers:
                edges.setdefault((producers[key], p), f"{names[p]} reads '{structure.resources[key[0]].name}'")
        for write in decl.writes:
            key = (write.index, write.source)
            what = structure.resources[write.index].name
            if key in producers:
                edges.setdefault((producers[key], p), f"{names[p]} writes '{what}' after {names[producers[key]]}")
            for reader in readers[key]:
                edges.setdefault((reader, p), f"{names[p]} overwrites '{what}' that {names[reader]} reads")
    return {edge: reason for edge, reason in edges.items() if edge[0] != edge[1]}


def _topological_order(nodes: list[int], edges: Iterable[tuple[int, int]]) -> list[int]:
    """Kahn's algorithm; among ready passes the earliest declared goes first."""
    successors: dict[int, list[int]] = {node: [] for node in nodes}
    waiting = dict.fromkeys(nodes, 0)
    for before, after in edges:
        if before in successors and after in successors:
            successors[before].append(after)
            waiting[after] += 1
    ready = [node for node in nodes if waiting[node] == 0]
    heapq.heapify(ready)
    order = []
    while ready:
        node = heapq.heappop(ready)
        order.append(node)
        for after in successors[node]:
            waiting[after] -= 1
            if waiting[after] == 0:
                heapq.heappush(ready, after)
    return order


def _check_acyclic(structure: _Structure, edges: dict[tuple[int, int], str]) -> None:
    everyone = list(range(len(structure.passes)))
    ordered = set(_topological_order(everyone, edges))
    if len(ordered) == len(everyone):
        return
    cycle = _find_cycle([p for p in everyone if p not in ordered], edges)
    names = [structure.passes[p].name for p in cycle]
    reasons = [edges[(a, b)] for a, b in zip(cycle, cycle[1:])]
    raise GraphError(f"cycle: {' -> '.join(names)} ({'; '.join(reasons)})")


def _find_cycle(stuck: list[int], edges: dict[tuple[int, int], str]) -> list[int]:
    """A cycle among passes Kahn's algorithm could not order, as [a, b, ..., a].

    Each stuck pass has a stuck predecessor, so walking predecessors must revisit a pass.
    """
    inside = set(stuck)
    predecessors: dict[int, list[int]] = defaultdict(list)
    for before, after in edges:
        if before in inside and after in inside:
            predecessors[after].append(before)
    path, node = [], min(stuck)
    while node not in path:
        path.append(node)
        node = min(predecessors[node])
    cycle = list(reversed(path[path.index(node):]))
    start = cycle.index(min(cycle))
    cycle = cycle[start:] + cycle[:start]
    return cycle + [cycle[0]]


def _cull(structure: _Structure, reads: list[tuple[tuple[int, int], ...]],
          producers: dict[tuple[int, int], int]) -> list[bool]:
    """FrameGraph culling: drop passes none of whose written versions is read, unless observable.

    A pass is observable when it has side effects or writes an imported (persistent) resource.
    Writing over a version keeps its contents (draw on top, load-op "keep"), so it uses that version
    just as a read does.  Culling a pass drops its uses, which may leave their producers unused in turn.
    """
    passes = structure.passes
    observable = [decl.side_effect or any(structure.resources[w.index].imported for w in decl.writes)
                  for decl in passes]
    reads = [tuple(pass_reads) + tuple((w.index, w.source) for w in decl.writes if (w.index, w.source) in producers)
             for decl, pass_reads in zip(passes, reads)]
    readers: dict[tuple[int, int], int] = defaultdict(int)
    for pass_reads in reads:
        for key in pass_reads:
            readers[key] += 1
    needed = [sum(1 for w in decl.writes if readers[(w.index, w.version)]) for decl in passes]
    stack = [p for p in range(len(passes)) if needed[p] == 0 and not observable[p]]
    culled = [False] * len(passes)
    while stack:
        p = stack.pop()
        culled[p] = True
        for key in reads[p]:
            readers[key] -= 1
            producer = producers.get(key)
            if readers[key] == 0 and producer is not None:
                needed[producer] -= 1
                if needed[producer] == 0 and not observable[producer]:
                    stack.append(producer)
    return culled


def _spans(structure: _Structure, reads: list[tuple[tuple[int, int], ...]],
           order: list[int]) -> dict[int, tuple[int, int]]:
    """Resource index -> (first, last) position in ``order`` of the passes that touch it."""
    by_name = {resource.name: index for index, resource in enumerate(structure.resources)}
    spans: dict[int, tuple[int, int]] = {}
    for step, p in enumerate(order):
        touched = _touched(structure.passes[p], by_name) + [index for index, _ in reads[p]]
        for index in dict.fromkeys(touched):
            spans[index] = (spans.get(index, (step, step))[0], step)
    return spans


def _steps(structure: _Structure, order: list[int], spans: dict[int, tuple[int, int]]) -> tuple[_Step, ...]:
    """Per executed pass: which transient resources to acquire before it and release after it."""
    transient = sorted(index for index in spans if not structure.resources[index].imported)
    return tuple(_Step(p,
                       tuple(index for index in transient if spans[index][0] == step),
                       tuple(index for index in transient if spans[index][1] == step))
                 for step, p in enumerate(order))
