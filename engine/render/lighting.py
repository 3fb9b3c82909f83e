"""The scene's light as world state: the sun, the sky, the ambient light and the fog, which scripts may change.

* :class:`Lighting`: a world resource flagged as state (hashes, snapshots), made when the world is made from the
  scene's ``[render]`` table (the defaults without an app): what the renderer draws with
  (:meth:`engine.render.renderer.Renderer.extract`), so a time-of-day cycle replays and rewinds like the rest.
* ``render.light`` (:func:`light_command`): sets the given fields, validated with ``[render]``'s own field
  definitions (:data:`LightSettings`); a bad value raises a ConfigError naming the key and keeps the light.
* :func:`follow_file`: the light follows the scene file key by key.  A key whose value in the ``[render]``
  settings changed since the world last took them (a hot reload's edit) is written into the light; the others keep
  what scripts set.

No GL here: headless runs (``--no-render``) have the same light and the same state hash.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from typing import Any

from pydantic import create_model, field_validator

from engine.config import ConfigModel, as_data, validate
from engine.scene import RenderSettings, nonzero_direction
from engine.world import World

LIGHT_KEYS = ("sun_direction", "sun_color", "ambient", "sky_top", "sky_horizon", "fog_density")

# the light's fields exactly as [render] defines them (types, bounds, descriptions) and its sun direction check
LightSettings = create_model(
    "LightSettings", __base__=ConfigModel, __doc__="The light keys of [render]: what render.light validates.",
    __validators__={"_sun_nonzero": field_validator("sun_direction")(lambda cls, v: nonzero_direction(v))},
    **{key: (RenderSettings.model_fields[key].annotation, RenderSettings.model_fields[key]) for key in LIGHT_KEYS})


def _plain(value: Any) -> Any:
    """A validated light value as plain Python floats (a tuple for a vector): hashed as float64 bytes."""
    return tuple(float(x) for x in value) if isinstance(value, (tuple, list)) else float(value)


@dataclass(frozen=True)
class Lighting:
    """World resource (state): the light drawn, with ``[render]``'s meaning for each field.

    Frozen: change it through ``render.light`` (validated), which puts a new one in the world."""

    sun_direction: tuple[float, float, float]  # towards the sun, any length but zero
    sun_color: tuple[float, float, float]
    ambient: float
    sky_top: tuple[float, float, float]
    sky_horizon: tuple[float, float, float]
    fog_density: float

    @classmethod
    def of(cls, settings: Any) -> Lighting:
        """The light of ``settings`` (RenderSettings, LightSettings or anything with the six attributes)."""
        return cls(**{key: _plain(getattr(settings, key)) for key in LIGHT_KEYS})

    def values(self) -> dict[str, Any]:
        return {key: getattr(self, key) for key in LIGHT_KEYS}


@dataclass
class FileLight:
    """World resource (not state): the ``[render]`` light as the world last took it from the scene's settings (when
    made, then at each hot reload), so that :func:`follow_file` tells a file's edit from what scripts set."""

    values: dict[str, Any] = field(default_factory=dict)


def scene_settings(world: World) -> RenderSettings:
    """The ``[render]`` settings of the world's app (the defaults without one)."""
    from engine.app import App

    app = world.try_resource(App)
    return app.config.render if app is not None else RenderSettings()


def setup_lighting(world: World) -> None:
    """``registry.on_world``: the light of a new world is the scene's ``[render]`` light."""
    light = Lighting.of(scene_settings(world))
    world.insert_resource(light, state=True)
    world.insert_resource(FileLight(light.values()))


def set_light(world: World, changes: dict[str, Any], file: str = "render.light") -> Lighting:
    """Set the given light fields (the others stay); validated like ``[render]``: a bad value or an unknown key
    raises :class:`engine.config.ConfigError` naming it (``file`` says where it came from) and keeps the light.
    Returns the new light."""
    light = world.resource(Lighting)
    if not changes:
        return light
    merged = {key: as_data(value) for key, value in (light.values() | changes).items()}
    new = Lighting.of(validate(LightSettings, merged, file=file))
    if new != light:
        world.insert_resource(new, state=True)
        return new
    return light


def light_command(world: World, entity: int, **values: Any) -> Lighting:
    """``ctx.call("render.light", sun_direction=(x, y, z), sun_color=(r, g, b), ambient=a, sky_top=(r, g, b),
    sky_horizon=(r, g, b), fog_density=d)``: set the fields given, keep the others, return the new
    :class:`Lighting` (called with none: the light in force).  Validated like the scene's ``[render]``: a bad value
    or an unknown key (with a "did you mean") raises a ConfigError and the light stays as it was."""
    return set_light(world, values)


def follow_file(world: World, settings: Any) -> list[str]:
    """Bring the world's light to a new version of the scene's ``[render]`` ``settings`` (a hot reload; a renderer
    given settings, :meth:`~engine.render.renderer.Renderer.use_settings`): each light key whose value changed since
    the world last took the file's light is written into :class:`Lighting`; keys the file did not change keep what
    scripts set.  Returns the keys written."""
    light, seen = world.try_resource(Lighting), world.try_resource(FileLight)
    if light is None or seen is None:
        return []
    wanted = Lighting.of(settings).values()
    changed = [key for key in LIGHT_KEYS if wanted[key] != seen.values.get(key)]
    if changed:
        seen.values.update({key: wanted[key] for key in changed})
        world.insert_resource(replace(light, **{key: wanted[key] for key in changed}), state=True)
    return changed
