"""The water_surface effect plugin (being written: registers its components, systems and render passes)."""


class _Plugin:
    name = "water_surface"

    def build(self, registry) -> None:
        pass


plugin = _Plugin()
