"""ecsfx: an entity-component-system engine with a scripting API and paper-faithful effect systems."""

from engine.app import App
from engine.registry import BuildContext, Registry
from engine.schedule import Stage
from engine.script import Script, ScriptContext, script
from engine.world import World

__all__ = ["App", "BuildContext", "Registry", "Script", "ScriptContext", "Stage", "World", "script"]
