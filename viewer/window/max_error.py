"""The settings panel's "max error" in the window: measure the candidates
for this view (a few passes a frame, so the window stays live), pick the
fastest settings within the budget, apply them, and put the user's settings
back when it is switched off.  The measuring and the choice are
viewer/measure/quality.py's; this is their timing in a running window.
"""

from __future__ import annotations

import copy
import sys

from ..measure import quality

#: Time per frame given to measuring (at least one pass).
QUALITY_STEP_S = 0.05


class MaxError:
    """The state of "max error" for one Viewer (`viewer`): the measurement
    in progress (`job`), the measured parts (measurement, cache,
    candidates), the last pick (`choice`), and the render settings it
    replaced (`saved`, None while it is off)."""

    def __init__(self, viewer):
        self.viewer = viewer
        self.job = None
        self.parts = None
        self.choice = None
        self.said = None      # (measurement, candidate, met) of the last pick printed on stderr
        self.saved = None     # render settings before the pick, restored when it is switched off
        self.status = ""      # the panel's and the HUD's line

    def close(self) -> None:
        """Stop measuring (the window closes, or the scene was reloaded)."""
        if self.job is not None:
            try:
                self.job.close()
            finally:
                self.job = None

    @property
    def on(self) -> bool:
        return self.viewer.panel is not None and self.viewer.panel.max_error_on

    def update(self, remeasure: bool = False) -> None:
        """The panel's "max error" changed: switched on (measure unless
        cached, then apply the pick), off (restore the settings), a new
        budget (pick again from the measurements), or "measure again"."""
        if not self.on:
            self.off("")
            return
        switched_on = self.saved is None
        if switched_on:
            r = self.viewer.scene.render
            self.saved = self.viewer.panel.user_render = (r.samples, r.max_depth, r.min_weight)
        elif self.job is not None and not remeasure:
            return  # measuring: the pick uses the new budget when it is done
        elif self.parts is not None and not remeasure:
            # another budget: pick again from the same measurements, if they
            # are this view's (the key holds the camera, the lights and the
            # window's size); else this view's, from the cache where it was
            # measured before
            fbw, fbh = self.viewer.framebuffer_size()
            key = quality.make_key(self.viewer.ctx, self.viewer.scene, quality.layout(max(1, fbw), max(1, fbh)))
            if key.stem() == self.parts[1].key.stem():
                self.finish()
                return
        self.close()
        fbw, fbh = self.viewer.framebuffer_size()
        scene = copy.deepcopy(self.viewer.scene)
        if remeasure and self.parts is not None:  # measure again: not from the cache
            meas, cache, cands = quality.prepare(self.viewer.ctx, scene, max(1, fbw), max(1, fbh))
            meas = quality.Measurement(self.viewer.ctx, scene, meas.layout, cands)
        else:
            meas, cache, cands = quality.prepare(self.viewer.ctx, scene, max(1, fbw), max(1, fbh))
        self.parts = (meas, cache, cands)
        self.job = None if meas.done else meas
        if meas.done:
            self.finish()
        else:
            self.status = f"max error {self.viewer.panel.max_error:.4g}: measuring\u2026 0%"
            self.viewer.say("max error: measuring (once per scene and window size)")

    def step(self) -> None:
        job = self.job
        try:
            done = job.step(QUALITY_STEP_S)
        except Exception as e:
            self.job = self.parts = None
            self.off("")
            self.viewer.error(f"max error: measuring failed: {e}")
            return
        self.viewer.ui_frames = max(self.viewer.ui_frames, 1)
        if done:
            self.job = None
            self.finish()
        else:
            self.status = (f"max error {self.viewer.panel.max_error:.4g}: measuring\u2026 "
                                   f"{100 * job.fraction:.0f}%")

    def finish(self) -> None:
        meas, cache, cands = self.parts
        choice = quality.finish(meas, cache, cands, self.viewer.panel.max_error)
        self.choice = choice
        c = choice.measured.candidate
        r = self.viewer.scene.render
        if (r.samples, r.max_depth, r.min_weight) != (c.samples, c.max_depth, c.min_weight):
            r.samples, r.max_depth, r.min_weight = c.samples, c.max_depth, c.min_weight
            self.viewer.controls.changed = True
        self.status = (f"max error {choice.max_error:.4g}: " + ("" if choice.met else "not reached, ")
                               + f"{c.samples} spp, depth {c.max_depth}, w {c.min_weight:g} "
                               f"(RMSE {choice.measured.rmse:.3g}"
                               + (f" +- {choice.measured.rmse_se:.2g})" if choice.measured.rmse_se > 0 else ")")
                               + (f"; {choice.cut_pixels} pixels left out: trees cut by the driver"
                                  if choice.cut_pixels else ""))
        self.viewer.say(self.status)
        # on stderr once per pick, not at every step of the budget's slider
        said = (id(meas), c.key(), choice.met)
        if said != self.said:
            self.said = said
            print(f"glassray: {choice.line()}", file=sys.stderr, flush=True)

    def off(self, message: str) -> None:
        self.close()
        if self.viewer.panel is not None:
            self.viewer.panel.max_error_on = False
        if self.saved is not None:
            r = self.viewer.scene.render
            r.samples, r.max_depth, r.min_weight = self.saved
            self.saved = None
            if self.viewer.panel is not None:
                self.viewer.panel.user_render = None
            self.viewer.controls.changed = True
        self.status = ""
        if message:
            self.viewer.say(message)
