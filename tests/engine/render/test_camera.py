"""Camera controllers and matrices (no GL)."""

import numpy as np

from engine.app import App
from engine.input import InputEvent, InputQueue
from engine.registry import BuildContext
from engine.render.components import Camera, CameraConfig, build_camera, camera_matrices, viewport_pixels
from engine.spatial import Transform


def app_with_two_cameras():
    app = App()  # no scene: window size falls back to the default render settings (960 x 540)
    w = app.world
    cams = []
    for name, cfg in (("main", CameraConfig(controller="orbit")),
                      ("mini", CameraConfig(controller="orbit", viewport=[0.75, 0.75, 0.25, 0.25], priority=1))):
        e = w.spawn(Transform())
        w.add(e, build_camera(cfg, BuildContext(w, e, name, "", None)))
        cams.append(e)
    return app, cams


def drag(app, x, y, dx):
    q = app.world.resource(InputQueue)
    q.push(InputEvent("mouse_move", x=x, y=y))
    q.push(InputEvent("button_down", "right", x=x, y=y))
    app.step(1)
    for _ in range(3):
        q.push(InputEvent("mouse_move", x=x + dx, y=y, dx=dx))
        app.step(1)
    q.push(InputEvent("button_up", "right", x=x, y=y))
    app.step(1)


def test_right_drag_turns_only_the_camera_it_started_on():
    app, (main, mini) = app_with_two_cameras()
    yaw_main, yaw_mini = app.world.get(main, Camera).yaw, app.world.get(mini, Camera).yaw
    drag(app, 900.0, 500.0, 10.0)  # inside the minimap (top-right quarter)
    assert app.world.get(main, Camera).yaw == yaw_main
    assert app.world.get(mini, Camera).yaw != yaw_mini
    yaw_mini = app.world.get(mini, Camera).yaw
    drag(app, 100.0, 100.0, 10.0)  # inside the main view only
    assert app.world.get(main, Camera).yaw != yaw_main and app.world.get(mini, Camera).yaw == yaw_mini


def test_camera_matrices_match_viewport_rounding():
    app, (main, mini) = app_with_two_cameras()
    view, proj, rect = camera_matrices(app.world.get(mini, Camera), app.world.get(mini, Transform), (961, 541))
    assert rect == viewport_pixels((0.75, 0.75, 0.25, 0.25), (961, 541)) == (721, 406, 240, 135)
    assert np.isclose(proj[1, 1] / proj[0, 0], 240 / 135)


def test_camera_config_rejects_inconsistent_values():
    import pytest

    from engine.config import ConfigError, validate

    for bad, text in (({"near": 10.0, "far": 5.0}, "less than far"), ({"viewport": [0.8, 0.0, 0.5, 1.0]}, "inside"),
                      ({"viewport": [0.0, 0.0, 0.0, 1.0]}, "inside")):
        with pytest.raises(ConfigError, match=text):
            validate(CameraConfig, bad, "camera.toml")


def test_camera_config_rejects_sizes_below_single_precision():
    """A near plane or ortho height of 1e-300 validated and filled the projection with inf and NaN (the
    matrices are single precision); the lower bounds name the key."""
    import pytest

    from engine.config import ConfigError, validate

    for key, bound in (("near", "0.0001"), ("ortho_height", "0.001"), ("distance", "0.001")):
        with pytest.raises(ConfigError) as err:
            validate(CameraConfig, {key: 1e-300}, "camera.toml")
        assert f"{key}: expected greater than or equal to {bound} " in str(err.value) + " "
