"""``--plugin MODULE[:ATTR]``: a game outside an installed package runs, validates and graphs with the command line."""

import os
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

from engine.app import App
from engine.cli import main
from engine.plugin_option import PluginOptionError, load_plugin, load_plugins, registry_with

ROOT = Path(__file__).resolve().parents[2]

PLUGIN = '''
from dataclasses import dataclass

from pydantic import Field

from engine import Stage
from engine.config import ConfigModel


class SpinnerConfig(ConfigModel):
    """Turns an angle at a rate."""

    rate: float = Field(1.0, gt=0.0, le=100.0, description="Radians per second.")


@dataclass
class SpinnerState:
    angle: float = 0.0


def build_spinner(cfg, ctx):
    return [cfg, SpinnerState()]


def spin(world, dt):
    for _, (cfg, state) in world.query(SpinnerConfig, SpinnerState):
        state.angle += cfg.rate * dt


class SpinnerPlugin:
    name = "{name}"

    def build(self, registry):
        registry.add_component("Spinner", SpinnerConfig, build_spinner, preset_dir="spinner")
        registry.add_system(spin, Stage.SIMULATION, name="{name}.spin")
'''

SCENE = """\
[scene]
name = "spin"
{plugins}
[[entities]]
name = "top"
[entities.components.Transform]
position = [0.0, 1.0, 0.0]
[entities.components.Spinner]
rate = 2.5
"""


def write_game(folder: Path, module: str, plugins: str = "", tail: str = "plugin = SpinnerPlugin()\n") -> Path:
    """A game's folder: a plugin module ``module`` (plugin name = module name) and a scene using its component."""
    (folder / f"{module}.py").write_text(PLUGIN.format(name=module) + tail)
    scenes = folder / "configs" / "scenes"
    scenes.mkdir(parents=True, exist_ok=True)
    (scenes / "spin.toml").write_text(SCENE.format(plugins=plugins))
    return scenes / "spin.toml"


def engine_cli(folder: Path, *args: str) -> subprocess.CompletedProcess:
    """``python -m engine ...`` run from the game's folder (this checkout's engine on the path)."""
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    return subprocess.run([sys.executable, "-m", "engine", *args], capture_output=True, text=True, cwd=folder,
                          env=env)


@pytest.fixture
def fresh_modules(monkeypatch):
    """In-process imports of plugin modules from tmp_path: sys.path and the imported modules are put back after."""
    monkeypatch.setattr(sys, "path", list(sys.path))
    before = set(sys.modules)
    yield
    for name in set(sys.modules) - before:
        if name.startswith("cliplug_"):
            del sys.modules[name]


def test_run_with_plugin_hashes_as_the_api_and_without_it_the_component_is_unknown(tmp_path, monkeypatch,
                                                                                       fresh_modules):
    write_game(tmp_path, "cliplug_run")
    args = ("run", "configs/scenes/spin.toml", "--no-render", "--steps", "5", "--hash")
    done = engine_cli(tmp_path, *args, "--plugin", "cliplug_run")
    assert done.returncode == 0, done.stderr
    digest = done.stdout.split()[-1]
    assert len(digest) == 32

    monkeypatch.syspath_prepend(str(tmp_path))  # the same game through the Python API gives the same state
    registry = registry_with(load_plugins(["cliplug_run"]))
    app = App(tmp_path / "configs/scenes/spin.toml", registry=registry)
    app.step(5)
    assert app.state_hash() == digest

    without = engine_cli(tmp_path, *args)
    assert without.returncode == 1
    assert "spin.toml:" in without.stderr
    assert "entities[0].components.Spinner: unknown component 'Spinner'" in without.stderr
    assert "Traceback" not in without.stderr


def test_scene_plugins_list_may_name_a_command_line_plugin(tmp_path):
    write_game(tmp_path, "cliplug_listed", plugins='plugins = ["cliplug_listed"]')
    args = ("run", "configs/scenes/spin.toml", "--no-render", "--steps", "3", "--print-schedule")
    done = engine_cli(tmp_path, *args, "--plugin", "cliplug_listed:SpinnerPlugin")
    assert done.returncode == 0, done.stderr
    assert "cliplug_listed.spin" in done.stdout
    assert "energy_wave" not in done.stdout  # the scene's list still decides which installed plugins load

    without = engine_cli(tmp_path, *args)
    assert without.returncode == 1
    assert "scene.plugins" in without.stderr and "unknown plugin 'cliplug_listed'" in without.stderr


def test_validate_with_plugin(tmp_path):
    write_game(tmp_path, "cliplug_val")
    preset = tmp_path / "configs" / "effects" / "spinner"
    preset.mkdir(parents=True)
    (preset / "fast.toml").write_text("rate = 50.0\n")
    done = engine_cli(tmp_path, "validate", "configs/", "--plugin", "cliplug_val")
    assert done.returncode == 0, done.stderr
    assert "validated 2 file(s): 2 ok" in done.stdout

    (preset / "fast.toml").write_text("rate = 500.0\n")
    bad = engine_cli(tmp_path, "validate", "configs/", "--plugin", "cliplug_val")
    assert bad.returncode == 1 and "fast.toml:1: rate: expected less than or equal to 100" in bad.stderr

    without = engine_cli(tmp_path, "validate", "configs/scenes/spin.toml")
    assert without.returncode == 1 and "unknown component 'Spinner'" in without.stderr


def test_graph_with_plugin(tmp_path):
    write_game(tmp_path, "cliplug_graph")
    done = engine_cli(tmp_path, "graph", "configs/scenes/spin.toml", "--plugin", "cliplug_graph")
    assert done.returncode == 0, done.stderr
    assert "present.view0" in done.stdout
    without = engine_cli(tmp_path, "graph", "configs/scenes/spin.toml")
    assert without.returncode == 1 and "unknown component 'Spinner'" in without.stderr


BAD_MODULES = {
    "cliplug_empty": "X = 1\n",
    "cliplug_two": PLUGIN.format(name="two") + "class Other(SpinnerPlugin):\n    name = 'other'\n",
    "cliplug_raises": "raise RuntimeError('the game module is broken')\n",
    "cliplug_needs": "import cliplug_no_such_dependency\n",
    "cliplug_badbuild": PLUGIN.format(name="badbuild") + "\nclass Bad:\n    name = 'core'\n    def build(self, r): pass\n"
                        "\nclass Dup(SpinnerPlugin):\n    def build(self, registry):\n"
                        "        registry.add_component('Transform', dict)\n",
    "cliplug_args": "class P:\n    name = 'p'\n    def __init__(self, x): pass\n    def build(self, r): pass\n",
}


@pytest.mark.parametrize(("value", "message"), [
    ("cliplug_missing", "--plugin 'cliplug_missing': no module named 'cliplug_missing' in the current directory"),
    ("cliplug_ok:nope", "--plugin 'cliplug_ok:nope': module 'cliplug_ok' has no attribute 'nope'"),
    ("cliplug_ok:build_spinner", "cliplug_ok:build_spinner is a function, not a plugin"),
    ("cliplug_ok:SpinnerConfig", "cliplug_ok:SpinnerConfig is class SpinnerConfig, not a plugin"),
    ("cliplug_ok:", "expected an attribute name after ':'"),
    ("not a module", "expected MODULE or MODULE:ATTR"),
    ("cliplug_empty", "module 'cliplug_empty' has no attribute 'plugin' and defines no plugin"),
    ("cliplug_two", "module 'cliplug_two' defines several plugins (Other, SpinnerPlugin); name one"),
    ("cliplug_raises", "importing 'cliplug_raises' raised RuntimeError: the game module is broken"),
    ("cliplug_needs", "importing 'cliplug_needs' failed: No module named 'cliplug_no_such_dependency'"),
    ("cliplug_badbuild:Bad", "its plugin is named 'core', the name of a plugin the engine always installs"),
    ("cliplug_badbuild:Dup", "its build(registry) raised RegistryError: component 'Transform' is already registered"),
    ("cliplug_args", "cannot instantiate class cliplug_args:P: TypeError"),
])
def test_bad_plugin_values_are_one_line_errors(tmp_path, monkeypatch, capsys, fresh_modules, value, message):
    write_game(tmp_path, "cliplug_ok", tail="")
    for module, source in BAD_MODULES.items():
        (tmp_path / f"{module}.py").write_text(source)
    monkeypatch.chdir(tmp_path)
    for command in (["run", "configs/scenes/spin.toml", "--no-render", "--steps", "1"],
                    ["validate", "configs/scenes/spin.toml"]):
        code = main([*command, "--plugin", value])
        out = capsys.readouterr()
        assert code == 1
        assert out.err.startswith(f"error: --plugin {value!r}: ") and message in out.err, out.err
        assert len(out.err.strip().splitlines()) == 1 and "Traceback" not in out.err


def test_default_attribute_rules(tmp_path, monkeypatch, fresh_modules):
    """``plugin`` first; else the one plugin the module defines, an object before its class; a class is made."""
    monkeypatch.syspath_prepend(str(tmp_path))
    write_game(tmp_path, "cliplug_cls", tail="")
    assert type(load_plugin("cliplug_cls")).__name__ == "SpinnerPlugin"  # the only plugin: its class, instantiated
    write_game(tmp_path, "cliplug_obj", tail="the_plugin = SpinnerPlugin()\n")
    module = __import__("cliplug_obj")
    assert load_plugin("cliplug_obj") is module.the_plugin  # the object, not a second instance of its class
    write_game(tmp_path, "cliplug_attr", tail="plugin = SpinnerPlugin()\nclass Other(SpinnerPlugin):\n    pass\n")
    assert load_plugin("cliplug_attr") is __import__("cliplug_attr").plugin
    # the same plugin named twice installs once; two plugins of one name are refused
    assert len(load_plugins(["cliplug_attr", "cliplug_attr:plugin"])) == 1
    with pytest.raises(PluginOptionError, match="as is the one --plugin 'cliplug_attr' gives"):
        load_plugins(["cliplug_attr", "cliplug_attr:Other"])
