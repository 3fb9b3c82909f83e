"""Dynamic resolution: the render scale follows the measured frame time to hold a target frame rate.

A software rasteriser (or a slow GPU) pays for most of a frame per pixel, so drawing the 3D views at fewer pixels
is the lever that holds a frame rate on a slower machine, as console engines do.  ``[render] dynamic_resolution``
turns it on for the window's real-time loop (:meth:`engine.app.App.advance` feeds each frame's measured length to
:meth:`engine.render.renderer.Renderer.frame_time`); fixed-step runs, screenshots and tests draw at the set scale.

The controller is pure arithmetic on frame times, so it is tested without a renderer.  It looks at the median of
the last ``window`` frames (one slow frame, a bake or a hitch, does not move it) and models the frame's cost
pessimistically as if all of it were proportional to the pixel count, i.e. to scale²:

* over budget (median above ``target · (1 + margin)``): down to ``scale · sqrt(target / median)``, the least
  reduction that could be enough, at least one ``step`` and on the grid of steps; when part of the frame does not
  scale with the pixels, the next window lowers it again;
* under budget: up by one ``step`` only when even the pessimistic model keeps the next scale under the target
  (``median · (next / scale)² ≤ target · headroom``).  The part of a frame that does not shrink with the pixels
  makes the real cost at the larger scale lower than that prediction, so a raise does not overshoot, and the
  scale does not swing between two steps;
* never below ``low`` nor above ``high`` (the set ``render_scale``: it only ever lowers it).

After a change the next ``settle`` frames are not sampled (new targets are allocated at the new size) and the
window starts empty, so every decision rests on frames drawn at the scale it judges.
"""

from __future__ import annotations

import math
import statistics
from collections import deque

__all__ = ["DynamicResolution"]


class DynamicResolution:
    """The render scale for the next frame from the measured length of the last ones (see the module docstring).

    ``scale`` is None until the controller has lowered the scale (the set scale is used); :meth:`reset` forgets
    everything (new settings)."""

    def __init__(self, step: float = 0.05, window: int = 12, settle: int = 2, margin: float = 0.02,
                 headroom: float = 0.9) -> None:
        if not (0.0 < step < 1.0 and window >= 1 and settle >= 0 and margin >= 0.0 and 0.0 < headroom <= 1.0):
            raise ValueError("step in (0, 1), window >= 1, settle >= 0, margin >= 0, headroom in (0, 1]")
        self.step, self.window, self.settle, self.margin, self.headroom = step, window, settle, margin, headroom
        self.scale: float | None = None
        self.changes = 0  # scale changes made (tests, the bench)
        self._times: deque[float] = deque(maxlen=window)
        self._skip = 0

    def reset(self) -> None:
        """Back to the set scale, with no frames seen."""
        self.scale = None
        self._times.clear()
        self._skip = 0

    def update(self, frame_seconds: float, target_seconds: float, low: float, high: float) -> float:
        """Take one frame's measured length; return the scale to draw the next frame at, in [low, high]."""
        if not (target_seconds > 0.0 and 0.0 < low <= high):
            raise ValueError(f"need target_seconds > 0 and 0 < low <= high (got {target_seconds}, {low}, {high})")
        current = high if self.scale is None else min(max(self.scale, low), high)
        if self._skip:
            self._skip -= 1
            return self._keep(current, high)
        if math.isfinite(frame_seconds) and frame_seconds >= 0.0:
            self._times.append(frame_seconds)
        if len(self._times) < self.window:
            return self._keep(current, high)
        median = statistics.median(self._times)
        new = current
        if median > target_seconds * (1.0 + self.margin) and current > low:
            ideal = current * math.sqrt(target_seconds / median)
            new = max(low, min(self._grid_floor(ideal), self._grid_floor(current - self.step)))
        elif current < high:
            up = min(high, self._grid_floor(current + self.step))  # the next step of the grid above
            if median * (up / current) ** 2 <= target_seconds * self.headroom:
                new = up
        if new != current:
            self.changes += 1
            self._times.clear()
            self._skip = self.settle
        return self._keep(new, high)

    def _keep(self, scale: float, high: float) -> float:
        scale = round(scale, 6)
        self.scale = None if scale >= high else scale
        return scale

    def _grid_floor(self, x: float) -> float:
        """The largest multiple of ``step`` at or below ``x`` (a hair of rounding tolerated)."""
        return round(math.floor(x / self.step + 1e-9) * self.step, 6)
