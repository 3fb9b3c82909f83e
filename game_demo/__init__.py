"""The playable demo: a game built on the engine's public API (scripts, TOML scene, prefabs, commands)."""


class _Plugin:
    name = "game_demo"

    def build(self, registry) -> None:
        from game_demo.scripts import SCRIPTS

        registry.add_scripts(SCRIPTS)


plugin = _Plugin()
