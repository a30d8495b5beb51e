"""The viewer's part that selects and moves objects: a click picks the
object under the cursor (window/selection.py asks the GPU for the first
hit; window/pick.py decides which object a repeated click means and moves
it), the panel shows it, the outline follows it, and a move of it is an
undoable edit (window/history.py).

ObjectPicking is a part of Viewer (window/app.py), kept here because it is
one job: it reads and sets the viewer's `controls` (whose `selected` is
the selection: the panel and the outline follow it), `selection`, `scene`,
`renderer`, `panel`, `show_panel`, `history`, `needs_display` and
`_last_click`.
"""

from __future__ import annotations

import math

from . import backend  # noqa: F401  (first: it imports imgui-bundle before glfw; backend.py says why)

import glfw  # noqa: E402

from .pick import CLICK_PX, next_pick, objects_along, translate


def describe(scene, index: int) -> str:
    o = scene.objects[index]
    return f"{index}: {o.name} ({o.type})" if o.name else f"{index}: {o.type}"


class ObjectPicking:
    def _take_pick(self, fbw: int, fbh: int) -> None:
        """A click since the last frame: select what is under it."""
        req, self.controls.pick_request = self.controls.pick_request, None
        # a click on the panel (or the help) is theirs, even when ImGui did
        # not yet know the pointer was over it: moved there and clicked
        # within one frame, it had not claimed the mouse, and the click
        # selected in the view behind
        if req is None or self._on_ui(req):
            return
        ww, wh = glfw.get_window_size(self.window)
        # window coordinates to framebuffer pixels (they differ on a HiDPI screen)
        x, y = req[0] * fbw / max(ww, 1), req[1] * fbh / max(wh, 1)
        first = self.selection.first_hit(self.renderer, fbw, fbh, x, y)
        again = self._last_click is not None and math.dist(self._last_click, req) <= CLICK_PX
        along = objects_along(self.scene, fbw, fbh, x, y) if again and first >= 0 else []
        self._last_click = req
        self.select(next_pick(first, along, self.controls.selected, again))

    def select(self, index: int | None) -> None:
        """Select object `index` of the scene (None: nothing): outlined, and
        the panel opens its node and material (now, or when it is shown)."""
        if index is not None and not 0 <= index < len(self.scene.objects):
            index = None
        self._set_selected(index)
        self.ui_frames = max(self.ui_frames, 2)
        # on stdout too, as the viewer says what it saved, opened or reloaded
        if index is None:
            print("nothing selected", flush=True)
            self.say("nothing selected")
        else:
            print(f"selected {describe(self.scene, index)}", flush=True)
            self.say(f"selected {describe(self.scene, index)}: arrows, PageUp/PageDown or ctrl+drag move it")

    def _apply_move(self) -> None:
        """The move of the selected object that keys or a drag asked for,
        as an edit of its own in the undo history: a drag is one edit from
        press to release, a key press one each."""
        move = self.controls.take_move()
        dragging = self.controls.dragging == "move"
        i = self.controls.selected
        if move is not None and i is not None and i < len(self.scene.objects):
            self.history.at_rest(self.scene)
            if translate(self.scene.objects[i], move):
                self.history.after_panel(self.scene, changed=True, active=dragging)
                self.controls.changed = True
        if not self.show_panel:      # else the panel's turn ends the edit (app.py, _ui_new_frame)
            self.history.after_panel(self.scene, changed=False, active=dragging)

    def _keep_selection_valid(self) -> None:
        """An object removed (the panel, an undo) can take the selected
        index with it: then nothing is selected."""
        i = self.controls.selected
        if i is not None and i >= len(self.scene.objects):
            self._set_selected(None)

    def _set_selected(self, index: int | None) -> None:
        """The one place the selection changes: the panel told, the outline redrawn."""
        self.controls.selected = index
        if index is None:
            self._last_click = None
        if self.panel is not None:
            self.panel.select(index)
        self.needs_display = True

    def _selection_hud(self) -> list[str]:
        i = self.controls.selected
        return [] if i is None or i >= len(self.scene.objects) else [f"selected {describe(self.scene, i)}"]
