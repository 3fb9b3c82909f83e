"""The dust_devil effect plugin (being written: registers its components, systems and render passes)."""


class _Plugin:
    name = "dust_devil"

    def build(self, registry) -> None:
        pass


plugin = _Plugin()
