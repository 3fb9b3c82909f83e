"""Input: platform events in, per-tick input state out, recordable and replayable.

Windows and test harnesses push :class:`InputEvent` objects into the :class:`InputQueue`; the input
stage moves the events due this tick into :class:`InputState`.  Key names are lower-case strings
("w", "space", "tab", "escape", "f1", "1"); mouse buttons are "left", "right", "middle".
"""

from __future__ import annotations

import json
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any, Iterable, Iterator

from engine.config import suggest

KINDS = ("key_down", "key_up", "mouse_move", "button_down", "button_up", "scroll")
_KEY_KINDS = ("key_down", "key_up")
_BUTTON_KINDS = ("button_down", "button_up")

# The key names the window produces (engine/render/frontend.py key_name: pyglet's key symbol names, lower case,
# digits without pyglet's leading underscore, left and right shift and ctrl as one key each).
_NAMED_KEYS = (
    "space enter tab escape backspace delete insert home end pageup pagedown left right up down shift ctrl lalt ralt "
    "lcommand rcommand lmeta rmeta loption roption lwindows rwindows menu capslock numlock scrolllock pause break "
    "print sysreq clear linefeed begin select execute find help cancel undo redo scriptswitch "
    "minus equal plus comma period slash backslash semicolon colon apostrophe doublequote quoteleft asciitilde "
    "asciicircum bracketleft bracketright braceleft braceright parenleft parenright less greater bar ampersand "
    "asterisk at dollar exclamation percent pound question underscore "
    "num_add num_subtract num_multiply num_divide num_decimal num_separator num_equal num_enter num_space num_tab "
    "num_begin num_delete num_insert num_home num_end num_page_up num_page_down num_left num_right num_up num_down "
    "num_f1 num_f2 num_f3 num_f4").split()
KEY_NAMES = frozenset([*"abcdefghijklmnopqrstuvwxyz", *"0123456789", *(f"f{i}" for i in range(1, 25)),
                       *(f"num_{i}" for i in range(10)), *_NAMED_KEYS])
# other spellings of the same keys (pyglet's aliases, and the sides the window folds into one key)
KEY_ALIASES = {"return": "enter", "lshift": "shift", "rshift": "shift", "lctrl": "ctrl", "rctrl": "ctrl",
               "hash": "pound", "grave": "quoteleft", "modeswitch": "scriptswitch", "num_prior": "num_page_up",
               "num_next": "num_page_down"}
BUTTON_NAMES = ("left", "right", "middle")


def key_name(name: str) -> str:
    """The engine's name of a key, from any spelling the window's toolkit uses: case-insensitive ("A" is "a",
    "Left" the left arrow "left", "ESCAPE" "escape"), pyglet's symbol names ("_1" is "1", "RETURN" "enter",
    "LSHIFT" "shift").  A name that is no key raises ``ValueError`` with the near miss and the valid names."""
    text = str(name).lower()
    if text.startswith("_") and text[1:].isdigit():
        text = text[1:]
    text = KEY_ALIASES.get(text, text)
    if text in KEY_NAMES or text.isdigit() or text.startswith("user_key("):  # the last two: keys pyglet cannot name
        return text
    close = suggest(text, KEY_NAMES | KEY_ALIASES.keys())
    hint = f"; did you mean '{KEY_ALIASES.get(close, close)}'?" if close else ""
    raise ValueError(f"unknown key name {name!r}{hint} (key names, case-insensitive: a-z, 0-9, f1-f24, "
                     f"num_0-num_9, {', '.join(_NAMED_KEYS)})")


def button_name(name: str) -> str:
    """The engine's name of a mouse button: "left", "right", "middle" (any case), or the number pyglet gives an
    extra button ("8")."""
    text = str(name).lower()
    if text in BUTTON_NAMES or text.isdigit():
        return text
    close = suggest(text, BUTTON_NAMES)
    hint = f"; did you mean '{close}'?" if close else ""
    raise ValueError(f"unknown mouse button {name!r}{hint} (buttons: {', '.join(BUTTON_NAMES)}, or a number)")


@dataclass(frozen=True)
class InputEvent:
    """One platform event, as the window sends it and as tests, autopilots and replays inject it.

    ``kind`` is one of ``key_down``, ``key_up``, ``mouse_move``, ``button_down``, ``button_up``, ``scroll``;
    anything else raises ``ValueError`` naming the kinds (and the near miss: "keydown" -> "key_down").

    ``key`` names the key of ``key_down``/``key_up`` and the button of ``button_down``/``button_up``, spelled as
    the window spells it: lower case, "w", "1", "space", "enter", "escape", "tab", "shift", "ctrl", "left",
    "f1", "num_0" ... (:data:`KEY_NAMES`); buttons "left", "right", "middle".  Other spellings of a key are
    normalised to that name, case-insensitively ("A" -> "a", "Left" -> "left", "Escape" -> "escape",
    "RETURN" -> "enter", "LSHIFT" -> "shift"), so ``event.key`` is what ``InputState.is_down`` is asked with;
    a name that is no key ("esc", "keyA") raises ``ValueError`` with the near miss and the valid names.
    ``mouse_move`` and ``scroll`` take no key (``x``, ``y``: the pointer; ``dx``, ``dy``: the motion or the
    scroll amount in ``dy``).
    """

    kind: str
    key: str = ""
    x: float = 0.0
    y: float = 0.0
    dx: float = 0.0
    dy: float = 0.0

    def __post_init__(self) -> None:
        if self.kind not in KINDS:
            close = suggest(str(self.kind).lower().replace("-", "_"), KINDS)
            hint = f"; did you mean '{close}'?" if close else ""
            raise ValueError(f"unknown input event kind {self.kind!r}{hint} (kinds: {', '.join(KINDS)})")
        if self.kind in _KEY_KINDS + _BUTTON_KINDS:
            if not self.key:
                what = "key" if self.kind in _KEY_KINDS else "button"
                raise ValueError(f"a {self.kind} event needs a {what}: InputEvent({self.kind!r}, {what} name)")
            try:
                name = key_name(self.key) if self.kind in _KEY_KINDS else button_name(self.key)
            except ValueError as exc:
                raise ValueError(f"{self.kind} event: {exc}") from None
            object.__setattr__(self, "key", name)
        elif self.key:
            raise ValueError(f"a {self.kind} event takes no key (got {self.key!r}): keys go with key_down/key_up, "
                             "buttons with button_down/button_up")

    def to_json(self) -> dict[str, Any]:
        return {k: v for k, v in asdict(self).items() if v not in ("", 0.0)} | {"kind": self.kind}


@dataclass
class InputQueue:
    """Events waiting for the next tick's input stage (not part of the simulation state)."""

    events: list[InputEvent] = field(default_factory=list)

    def push(self, event: InputEvent) -> None:
        self.events.append(event)

    def take(self) -> list[InputEvent]:
        events, self.events = self.events, []
        return events


class KeySet:
    """A set of key and button names that iterates in the order they were added.  A Python ``set`` of strings
    iterates in an order that depends on the process's hash seed, so a script looping over this tick's presses
    would replay differently in another process; this one iterates the same everywhere.  Compares equal to a
    set with the same names."""

    __slots__ = ("_keys",)

    def __init__(self, keys: Iterable[str] = ()) -> None:
        self._keys = dict.fromkeys(keys)

    def add(self, key: str) -> None:
        self._keys[key] = None

    def discard(self, key: str) -> None:
        self._keys.pop(key, None)

    def __contains__(self, key: object) -> bool:
        return key in self._keys

    def __iter__(self) -> Iterator[str]:
        return iter(self._keys)

    def __len__(self) -> int:
        return len(self._keys)

    def __eq__(self, other: object) -> bool:
        if isinstance(other, KeySet):
            return self._keys.keys() == other._keys.keys()
        if isinstance(other, (set, frozenset)):
            return self._keys.keys() == other
        return NotImplemented

    __hash__ = None  # mutable, like set

    def __repr__(self) -> str:
        return f"KeySet({list(self._keys)!r})"

    def __hash_state__(self) -> set[str]:
        return set(self._keys)  # hashed as the set it was (the order of one tick's presses is not state)


@dataclass
class InputState:
    """What scripts read: held keys and buttons, this tick's presses, the mouse.  The key collections are
    :class:`KeySet`: ``in`` tests, and iteration in the order the keys went down."""

    keys_down: KeySet = field(default_factory=KeySet)
    pressed: KeySet = field(default_factory=KeySet)
    released: KeySet = field(default_factory=KeySet)
    mouse: tuple[float, float] = (0.0, 0.0)
    mouse_delta: tuple[float, float] = (0.0, 0.0)
    scroll: float = 0.0

    def is_down(self, key: str) -> bool:
        return key in self.keys_down

    def was_pressed(self, key: str) -> bool:
        return key in self.pressed

    def was_released(self, key: str) -> bool:
        return key in self.released

    def apply(self, events: list[InputEvent]) -> None:
        """Start a new tick and fold ``events`` in (buttons share the key sets, named 'mouse_left' ...)."""
        self.pressed = KeySet()
        self.released = KeySet()
        dx = dy = 0.0
        self.scroll = 0.0
        for ev in events:
            name = ev.key if ev.kind.startswith("key") else f"mouse_{ev.key}"
            if ev.kind in ("key_down", "button_down"):
                if name not in self.keys_down:
                    self.pressed.add(name)
                self.keys_down.add(name)
                if ev.kind == "button_down":
                    self.mouse = (ev.x, ev.y)
            elif ev.kind in ("key_up", "button_up"):
                self.keys_down.discard(name)
                self.released.add(name)
            elif ev.kind == "mouse_move":
                self.mouse = (ev.x, ev.y)
                dx += ev.dx
                dy += ev.dy
            elif ev.kind == "scroll":
                self.scroll += ev.dy
        self.mouse_delta = (dx, dy)


class InputRecorder:
    """Records the events applied at each tick; saves them as JSON lines."""

    def __init__(self, meta: dict[str, Any]) -> None:
        self.meta = meta
        self.ticks: dict[int, list[InputEvent]] = {}

    def record(self, tick: int, events: list[InputEvent]) -> None:
        if events:
            self.ticks[tick] = list(events)

    def save(self, path: Path, total_ticks: int) -> None:
        path = Path(path)
        path.parent.mkdir(parents=True, exist_ok=True)
        with path.open("w", encoding="utf-8") as fh:
            fh.write(json.dumps({"format": "ecsfx-input/1", "ticks": total_ticks, **self.meta}) + "\n")
            for tick in sorted(self.ticks):
                fh.write(json.dumps({"tick": tick, "events": [e.to_json() for e in self.ticks[tick]]}) + "\n")


class InputReplay:
    """Feeds recorded events back at the ticks they were recorded at."""

    def __init__(self, path: Path) -> None:
        """Read a recording; a file that is not one raises ``ValueError`` naming the file and the line."""
        try:
            lines = Path(path).read_text(encoding="utf-8").splitlines()
        except UnicodeDecodeError as exc:
            raise ValueError(f"{path}: not an input recording (not UTF-8 text: {exc})") from None
        if not lines:
            raise ValueError(f"{path}: empty input recording")
        self.meta = _json_line(path, 1, lines[0])
        if not isinstance(self.meta, dict) or self.meta.get("format") != "ecsfx-input/1":
            found = self.meta.get("format") if isinstance(self.meta, dict) else self.meta
            raise ValueError(f"{path}:1: not an input recording (expected format 'ecsfx-input/1', got {found!r})")
        self.ticks: dict[int, list[InputEvent]] = {}
        for number, line in enumerate(lines[1:], start=2):
            item = _json_line(path, number, line)
            try:
                self.ticks[int(item["tick"])] = [InputEvent(**e) for e in item["events"]]
            except (KeyError, TypeError, ValueError) as exc:
                raise ValueError(f"{path}:{number}: expected {{\"tick\": N, \"events\": [...]}} with events like "
                                 f"{{\"kind\": \"key_down\", \"key\": \"w\"}} ({type(exc).__name__}: {exc})") from None

    def events_for(self, tick: int) -> list[InputEvent]:
        return self.ticks.get(tick, [])


def _json_line(path: Path, number: int, line: str) -> Any:
    try:
        return json.loads(line)
    except json.JSONDecodeError as exc:
        raise ValueError(f"{path}:{number}: not an input recording (invalid JSON: {exc.msg})") from None
