"""Injected input: event kinds and key names are checked when an InputEvent is made, keys spelled as the window
spells them."""

import importlib.util
import sys
import types
from pathlib import Path

import pytest

from engine.input import InputEvent, InputReplay, InputState


def test_an_unknown_event_kind_is_an_error_with_the_near_miss():
    """Was: InputEvent("keydown", "a") was queued and silently ignored by the input stage."""
    with pytest.raises(ValueError, match=r"unknown input event kind 'keydown'; did you mean 'key_down'\? "
                                         r"\(kinds: key_down, key_up, mouse_move, button_down, button_up, scroll\)"):
        InputEvent("keydown", "a")
    with pytest.raises(ValueError, match="did you mean 'button_up'"):
        InputEvent("buttonup", "left")


def test_key_names_are_case_insensitive_and_normalised_to_the_windows_names():
    """Was: "A" or "Left" never matched a script's is_down("a") / is_down("left"): the key was held under a name
    nobody asks for."""
    assert [InputEvent("key_down", k).key for k in ("A", "Left", "ESCAPE", "Space", "F1", "_1", "RETURN", "LShift",
                                                     "rctrl")] == \
        ["a", "left", "escape", "space", "f1", "1", "enter", "shift", "ctrl"]
    assert InputEvent("button_down", "Left", x=3.0).key == "left"
    state = InputState()
    state.apply([InputEvent("key_down", "A"), InputEvent("key_down", "Left")])
    assert state.is_down("a") and state.was_pressed("left")


def test_an_unknown_key_or_button_is_an_error_naming_the_valid_ones():
    with pytest.raises(ValueError, match=r"key_down event: unknown key name 'esc'; did you mean 'escape'\? "
                                         r"\(key names, case-insensitive: a-z, 0-9, f1-f24, .*space"):
        InputEvent("key_down", "esc")
    with pytest.raises(ValueError, match="unknown key name 'keyA'"):
        InputEvent("key_up", "keyA")
    with pytest.raises(ValueError, match="a key_down event needs a key"):
        InputEvent("key_down")
    with pytest.raises(ValueError, match="unknown mouse button 'lft'; did you mean 'left'"):
        InputEvent("button_down", "lft")
    with pytest.raises(ValueError, match="a mouse_move event takes no key"):
        InputEvent("mouse_move", "w", x=1.0)


def test_a_recording_with_an_unknown_key_names_the_file_and_line(tmp_path):
    path = tmp_path / "input.jsonl"
    path.write_text('{"format": "ecsfx-input/1", "ticks": 3}\n{"tick": 1, "events": [{"kind": "keydown", '
                    '"key": "w"}]}\n')
    with pytest.raises(ValueError, match=f"{path}:2: .*unknown input event kind 'keydown'"):
        InputReplay(path)


def _pyglet_keys() -> types.ModuleType:
    """pyglet's key table without importing pyglet.window (that opens a display)."""
    spec = importlib.util.find_spec("pyglet")
    source = Path(spec.origin).parent / "window" / "key.py"
    module = types.ModuleType("pyglet_window_key")
    exec(compile(source.read_text(encoding="utf-8"), str(source), "exec"), module.__dict__)
    return module


def test_every_key_the_window_sends_is_a_valid_key_name(monkeypatch):
    """The window's key_name (engine/render/frontend.py) never makes an event that raises: each pyglet key symbol's
    name is accepted unchanged, and pyglet's own spelling of it normalises to the same name."""
    from engine.input import KEY_NAMES
    from engine.render import frontend

    keys = _pyglet_keys()
    monkeypatch.setitem(sys.modules, "pyglet.window", types.SimpleNamespace(key=keys))
    names = {symbol: frontend.key_name(symbol) for symbol in keys._key_names}
    assert set(names.values()) <= KEY_NAMES
    for symbol, name in names.items():
        assert InputEvent("key_down", name).key == name
        assert InputEvent("key_up", keys.symbol_string(symbol)).key == name
    assert InputEvent("key_down", frontend.key_name(0x12345678)).key == "305419896"  # a symbol pyglet cannot name
