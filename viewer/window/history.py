"""Undo and redo of the settings panel's edits, without GLFW or ImGui.

An edit is what the panel changed between two moments of rest: one drag of
a slider, one click of a checkbox, one value typed.  It is kept as the
parts of the scene it changed (the top-level fields of Scene: camera,
render, sky, ambient, lights, materials, objects, name), before and after,
so that undoing a material's colour does not also undo an orbit of the
camera made since.  Undo puts those parts back as they were before the
edit, redo as they were after it.  A reload from disk or another scene
opened clears the history (its edits were of another scene).
"""

from __future__ import annotations

import copy
from dataclasses import dataclass, fields

from ..scene.model import Scene

#: Edits kept; the oldest go first.
LIMIT = 200
#: The parts of a scene an edit can change.
PARTS = tuple(f.name for f in fields(Scene) if f.name not in ("path", "source", "name_from_file"))


@dataclass
class Edit:
    before: dict        # part name -> its value before the edit
    after: dict         # ... and after it

    @property
    def parts(self) -> list[str]:
        return sorted(self.before)


def _parts(scene: Scene) -> dict:
    return {name: copy.deepcopy(getattr(scene, name)) for name in PARTS}


class EditHistory:
    def __init__(self, limit: int = LIMIT):
        self.limit = limit
        self.undo_stack: list[Edit] = []
        self.redo_stack: list[Edit] = []
        self._rest: dict | None = None       # the scene's parts at the last moment of rest
        self._editing = False                # an edit is under way (a drag not released yet)

    def clear(self) -> None:
        self.undo_stack.clear()
        self.redo_stack.clear()
        self._rest, self._editing = None, False

    def at_rest(self, scene: Scene) -> None:
        """Before the panel draws: the scene as it is now is what an edit
        starting in this frame changes (camera moves and light keys since
        the last edit included, so that they are no part of it)."""
        if not self._editing:
            self._rest = _parts(scene)

    def after_panel(self, scene: Scene, changed: bool, active: bool) -> Edit | None:
        """After the panel drew: `changed` whether it changed the scene this
        frame, `active` whether a widget is still held (a slider being
        dragged, a field being typed in).  Returns the edit that has just
        ended, which is now undoable, or None."""
        if changed:
            self._editing = True
        if not self._editing or changed or active:
            return None
        self._editing = False
        now = _parts(scene)
        before = self._rest or now
        edit = Edit({k: v for k, v in before.items() if now[k] != v},
                    {k: now[k] for k, v in before.items() if now[k] != v})
        self._rest = now
        if not edit.before:
            return None                      # changed and changed back
        self.undo_stack.append(edit)
        del self.undo_stack[:-self.limit]
        self.redo_stack.clear()
        return edit

    def undo(self, scene: Scene) -> Edit | None:
        """Put back the parts the last edit changed; the edit, or None."""
        return self._move(scene, self.undo_stack, self.redo_stack, "before")

    def redo(self, scene: Scene) -> Edit | None:
        return self._move(scene, self.redo_stack, self.undo_stack, "after")

    def _move(self, scene: Scene, source: list[Edit], dest: list[Edit], side: str) -> Edit | None:
        if not source or self._editing:
            return None
        edit = source.pop()
        for name, value in getattr(edit, side).items():
            setattr(scene, name, copy.deepcopy(value))
        dest.append(edit)
        self._rest = _parts(scene)
        return edit
