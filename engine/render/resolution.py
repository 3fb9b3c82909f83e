"""Dynamic resolution: the render scale follows the measured frame time to hold a target frame rate.

A software rasteriser (or a slow GPU) pays for most of a frame per pixel, so drawing the 3D views at fewer pixels
is the lever that holds a frame rate on a slower machine, as console engines do.  ``[render] dynamic_resolution``
turns it on for the window's real-time loop (:meth:`engine.app.App.advance` feeds each frame's measured length to
:meth:`engine.render.renderer.Renderer.frame_time`); fixed-step runs, screenshots and tests draw at the set scale.

The controller is pure arithmetic on frame times, so it is tested without a renderer.  It looks at the median of
the last ``window`` frames (one slow frame, a bake or a hitch, does not move it) and models a frame as a fixed part
plus a part proportional to the pixel count, ``a + b · scale²``:

* over budget (median above ``target · (1 + margin)``): down to ``scale · sqrt(target / median)``, the least
  reduction that could be enough (as if all of the frame scaled with the pixels), at least one ``step`` and on the
  grid of steps; when part of the frame does not scale, the next window lowers it again;
* under budget: up by one ``step`` when the model predicts the next step at most ``target · headroom``:
  ``median + b · (next² − scale²)``.  The slope ``b`` comes from the medians measured at the last two scales
  (clamped to ``[0, median / scale²]``); until two scales were measured it is ``median / scale²``, as if all of
  the frame were pixels, which cannot overshoot.  A measured slope lets the scale climb back once a heavy moment
  is over, however large the frame's fixed part (a pessimistic model alone ratchets down: from 0.35 the demo's
  23 ms frames, 17 ms of them fixed, would never allow 0.4);
* a raise that the very next decision takes back blocks raises for a while, doubling with each such failure
  (``window · 2^failures`` frames, at most 64 windows), so a wrong slope (a load that changed between the two
  measurements) costs a few short dips, not a swing between two steps;
* never below ``low`` nor above ``high`` (the set ``render_scale``: it only ever lowers it).

After a change the next ``settle`` frames are not sampled (new targets are allocated at the new size) and the
window starts empty, so every decision rests on frames drawn at the scale it judges.

The frame length to feed is the time the frame's work took.  In a window with vsync the interval between frames
is rounded up to the display's refresh (16.7, 33.3, 50 ms at 60 Hz) and would hide the headroom: the window loop
feeds the time from the start of a frame to the end of its drawing, before the buffer swap waits
(:func:`engine.render.frontend._run_window`).
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
        self._measured: list[tuple[float, float]] = []  # (scale, median) of the last two scales measured
        self._raised = False  # the last change was a raise, not yet judged by a decision at its scale
        self._failures = 0  # raises taken back by the next decision, in a row
        self._blocked = 0  # frames before a raise is allowed again

    def reset(self) -> None:
        """Back to the set scale, with no frames seen."""
        self.scale = None
        self._times.clear()
        self._skip = 0
        self._measured.clear()
        self._raised = False
        self._failures = self._blocked = 0

    def update(self, frame_seconds: float, target_seconds: float, low: float, high: float) -> float:
        """Take one frame's measured length; return the scale to draw the next frame at, in [low, high]."""
        if not (target_seconds > 0.0 and 0.0 < low <= high):
            raise ValueError(f"need target_seconds > 0 and 0 < low <= high (got {target_seconds}, {low}, {high})")
        current = high if self.scale is None else min(max(self.scale, low), high)
        if self._blocked:
            self._blocked -= 1
        if self._skip:
            self._skip -= 1
            return self._keep(current, low, high)
        if math.isfinite(frame_seconds) and frame_seconds >= 0.0:
            self._times.append(frame_seconds)
        if len(self._times) < self.window:
            return self._keep(current, low, high)
        median = statistics.median(self._times)
        self._measure(current, median)
        new = current
        if median > target_seconds * (1.0 + self.margin) and current > low:
            ideal = current * math.sqrt(target_seconds / median)
            new = max(low, min(self._grid_floor(ideal), self._grid_floor(current - self.step)))
            if self._raised:  # the raise did not hold: wait longer before the next one
                self._failures += 1
                self._blocked = self.window * 2 ** min(self._failures, 6)
        elif self._raised:
            self._failures = 0  # the raise held
        if new == current and current < high and not self._blocked:
            up = min(high, self._grid_floor(current + self.step))  # the next step of the grid above
            predicted = median + self._slope(current, median) * (up * up - current * current)
            if predicted <= target_seconds * self.headroom:
                new = up
        self._raised = new > current  # judged by the next decision, at the new scale
        if new != current:
            self.changes += 1
            self._times.clear()
            self._skip = self.settle
        return self._keep(new, low, high)

    def _measure(self, scale: float, median: float) -> None:
        """Keep the latest median of this scale and of the scale measured before it."""
        if self._measured and self._measured[-1][0] == scale:
            self._measured[-1] = (scale, median)
        else:
            self._measured = self._measured[-1:] + [(scale, median)]

    def _slope(self, scale: float, median: float) -> float:
        """``b`` of the model ``a + b · scale²``: from the last two scales measured, clamped to [0, the whole
        frame as pixels]; the whole frame as pixels until two were measured."""
        most = median / (scale * scale)
        if len(self._measured) < 2:
            return most
        (s0, m0), (s1, m1) = self._measured
        return min(max((m1 - m0) / (s1 * s1 - s0 * s0), 0.0), most)

    def _keep(self, scale: float, low: float, high: float) -> float:
        # grid steps without float dust, and the bounds exactly (an off-grid set scale such as 0.47 stays 0.47)
        scale = high if scale >= high - 1e-6 else low if scale <= low + 1e-6 else round(scale, 6)
        self.scale = None if scale >= high else scale
        return scale

    def _grid_floor(self, x: float) -> float:
        """The largest multiple of ``step`` at or below ``x`` (a hair of rounding tolerated)."""
        return round(math.floor(x / self.step + 1e-9) * self.step, 6)
