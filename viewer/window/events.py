"""The viewer's input: GLFW's events, each given to Dear ImGui (when the
panel runs) and then, unless ImGui wants it, to the window's Controls as a
key or button name (backend.KEYS, BUTTONS).  Actions the keys ask for
(quit, screenshot, reload ...) are queued on `actions` for the next frame.

InputEvents is a part of Viewer (window/app.py), kept here because it is
one job: it reads and sets the viewer's `window`, `controls`, `actions`,
`ui_frames`, `needs_display`, `imgui` / `_imgui_ready` / `_addr`,
`_deferred_keys`, `_cursor`, `max_error` and `open_request`.
"""

from __future__ import annotations

from pathlib import Path

from .backend import BUTTONS, KEYS  # first: backend imports imgui-bundle before glfw

import glfw  # noqa: E402  (after backend)


class InputEvents:
    def _install_callbacks(self) -> None:
        win = self.window
        glfw.set_key_callback(win, self._on_key)
        glfw.set_char_callback(win, self._on_char)
        glfw.set_mouse_button_callback(win, self._on_mouse_button)
        glfw.set_cursor_pos_callback(win, self._on_cursor_pos)
        glfw.set_scroll_callback(win, self._on_scroll)
        glfw.set_window_size_callback(win, self._on_window_size)
        glfw.set_framebuffer_size_callback(win, self._on_framebuffer_size)
        glfw.set_window_refresh_callback(win, self._on_refresh)
        glfw.set_window_focus_callback(win, self._on_focus)
        glfw.set_cursor_enter_callback(win, self._on_cursor_enter)
        glfw.set_drop_callback(win, self._on_drop)

    # ------------------------------------------------------------ callbacks

    def _ui_wants_mouse(self, at: tuple[float, float] | None = None) -> bool:
        """Whether ImGui takes the mouse (a press or a scroll `at` a window
        point).  ImGui says so from where the pointer was at its last frame:
        moved off the panel and pressed before the next one, the press was
        still the panel's, and a quick click in the view did nothing.  So a
        press `at` a point outside ImGui's windows is the view's, unless a
        widget is held (a slider dragged past the panel's edge) or a popup
        is open (a combo's list can reach outside the panel)."""
        if not (self._imgui_ready and self.imgui.get_io().want_capture_mouse):
            return False
        if at is None or self.imgui.is_any_item_active() or self.imgui.is_popup_open(
                "", self.imgui.PopupFlags_.any_popup_id | self.imgui.PopupFlags_.any_popup_level):
            return True
        return self._on_ui(at)

    def _on_ui(self, at: tuple[float, float]) -> bool:
        """Whether window point `at` lies on one of ImGui's windows that take
        the mouse (the panel, the help: _ui_rects), whatever ImGui last saw."""
        return any(x0 <= at[0] < x1 and y0 <= at[1] < y1 for x0, y0, x1, y1 in self._ui_rects())

    def _ui_wants_keys(self) -> bool:
        return self._imgui_ready and self.imgui.get_io().want_text_input

    def _on_key(self, win, key, scancode, action, mods):
        self.ui_frames = max(self.ui_frames, 2)
        if action == glfw.PRESS:
            self.message_read()
        if key == glfw.KEY_TAB:
            # Tab is ours (show / hide the panel), never ImGui's: ImGui moves
            # keyboard focus with it, and a Tab that reached a panel just
            # opened (several pressed within a frame) put a text field in
            # edit mode, which then took every key, Tab and 1..9 included
            act = self.controls.key("tab") if action == glfw.PRESS else None
            if act is not None:
                self.actions.append(act)
            return
        backlog = self._imgui_backlog()      # ImGui's events not taken yet, before this one
        if self._imgui_ready:
            self.imgui.backends.glfw_key_callback(self._addr, key, scancode, action, mods)
        name = KEYS.get(key)
        if action == glfw.RELEASE or name is None:
            return
        if backlog or self._deferred_keys:
            # typed fast into a text field, a Return then P: the field was
            # still active for ImGui (which had not taken the Return yet), so
            # P was given to it as text, and dropped when it took the Return
            event_id = self.imgui.get_current_context().input_events_next_event_id - 1
            self._deferred_keys.append((event_id, name, mods, action))
            return
        if not self._ui_wants_keys():
            self._shortcut(name, mods, action)

    def _shortcut(self, name: str, mods: int, action: int) -> None:
        if name in "123456789" and action == glfw.PRESS and self.max_error.on:
            self.max_error.off("max error off: max depth set by key")
        act = self.controls.key(name, shift=bool(mods & glfw.MOD_SHIFT), repeat=action == glfw.REPEAT,
                                ctrl=bool(mods & glfw.MOD_CONTROL))
        if act is not None:
            self.actions.append(act)

    def _imgui_backlog(self) -> int:
        """Input events ImGui has been given and not taken yet: with its
        trickling queue it takes a key's down and up, and the text typed,
        over several frames when they come faster than frames."""
        if not self._imgui_ready:
            return 0
        return len(self.imgui.get_current_context().input_events_queue)

    def _on_char(self, win, codepoint):
        if self._imgui_ready:
            self.imgui.backends.glfw_char_callback(self._addr, codepoint)
        self.ui_frames = max(self.ui_frames, 2)

    def _on_mouse_button(self, win, button, action, mods):
        if self._imgui_ready:
            self.imgui.backends.glfw_mouse_button_callback(self._addr, button, action, mods)
        self.ui_frames = max(self.ui_frames, 2)
        if action == glfw.PRESS:
            self.message_read()
        name = BUTTONS.get(button)
        if name is None:
            return
        # the position of the latest motion event (in event order: querying the
        # pointer now could already see a later position)
        x, y = self._cursor if self._cursor is not None else glfw.get_cursor_pos(win)
        if action == glfw.PRESS:
            if not self._ui_wants_mouse((x, y)):
                self.controls.press(name, x, y, shift=bool(mods & glfw.MOD_SHIFT), ctrl=bool(mods & glfw.MOD_CONTROL))
        elif action == glfw.RELEASE:
            self.controls.release(name, x, y)

    def _on_cursor_pos(self, win, x, y):
        self._cursor = (x, y)
        if self._imgui_ready:
            self.imgui.backends.glfw_cursor_pos_callback(self._addr, x, y)
            self.ui_frames = max(self.ui_frames, 2)
        self.controls.move(x, y)

    def _on_scroll(self, win, dx, dy):
        if self._imgui_ready:
            self.imgui.backends.glfw_scroll_callback(self._addr, dx, dy)
        self.ui_frames = max(self.ui_frames, 2)
        if not self._ui_wants_mouse():
            self.controls.scroll(dx, dy)

    def _on_window_size(self, win, w, h):
        if w > 0 and h > 0:
            self.controls.set_window_size(w, h)
        self.needs_display = True

    def _on_framebuffer_size(self, win, w, h):
        self.needs_display = True

    def _on_refresh(self, win):
        self.needs_display = True

    def _on_focus(self, win, focused):
        if self._imgui_ready:
            self.imgui.backends.glfw_window_focus_callback(self._addr, int(focused))
        self.ui_frames = max(self.ui_frames, 1)

    def _on_drop(self, win, paths):
        """Files dropped on the window: the first .toml is opened (next frame)."""
        scenes = [p for p in paths if str(p).lower().endswith(".toml")]
        if scenes:
            self.open_request = str(scenes[0])
        else:
            self.say(f"not a scene file (.toml): {Path(paths[0]).name}" if paths else "nothing dropped", error=True)
        self.ui_frames = max(self.ui_frames, 1)

    def _on_cursor_enter(self, win, entered):
        if self._imgui_ready:
            self.imgui.backends.glfw_cursor_enter_callback(self._addr, int(entered))
        self.ui_frames = max(self.ui_frames, 1)
