"""The demo's scripts: they use only the public scripting API (``engine.Script``, ``ctx.call`` commands)."""

from game_demo.scripts.chaser import DustDevilChaser
from game_demo.scripts.player import Player
from game_demo.scripts.rules import GameRules
from game_demo.scripts.target import TargetScript

SCRIPTS = [Player, TargetScript, GameRules, DustDevilChaser]
