"""The grass_field effect plugin (being written: registers its components, systems and render passes)."""


class _Plugin:
    name = "grass_field"

    def build(self, registry) -> None:
        pass


plugin = _Plugin()
