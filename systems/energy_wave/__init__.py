"""The energy_wave effect plugin (being written: registers its components, systems and render passes)."""


class _Plugin:
    name = "energy_wave"

    def build(self, registry) -> None:
        pass


plugin = _Plugin()
