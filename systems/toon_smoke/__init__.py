"""The toon_smoke effect plugin (being written: registers its components, systems and render passes)."""


class _Plugin:
    name = "toon_smoke"

    def build(self, registry) -> None:
        pass


plugin = _Plugin()
