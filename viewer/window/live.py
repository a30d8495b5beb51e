"""The viewer's scene on disk: reload it (F5, or a watched file saved), open
another one (dropped on the window, or typed in the panel), and keep a
failed reload's message in the HUD until a good one.

A reload or an open builds what it needs first (the scene, and for F5 or a
saved shader a new renderer) and only then hands it to the viewer
(Viewer.adopt_scene): whatever fails leaves the picture as it was.
"""

from __future__ import annotations

import copy
import re
import tomllib
from pathlib import Path

from ..gpu.renderer import Renderer
from ..gpu.shaders import shader_root, shaders_editable
from ..scene.model import Scene, SceneError
from .controls import merge_reloaded
from .watch import FileWatcher, shader_files

#: An idle viewer wakes this often (s), so that Ctrl-C in its terminal ends it ...
IDLE_WAKE_S = 0.5
#: ... and this often while it watches files: a save is seen within about this long.
WATCH_WAKE_S = 0.2
#: The files whose change is a change of the shaders (a new renderer).
SHADER_SUFFIXES = (".frag", ".vert", ".glsl")


def has_camera_table(scene: Scene) -> bool:
    """Whether the file a scene came from has its own [camera] table (a
    scene not from a file counts as having one)."""
    if scene.path is None:
        return True
    try:
        return "camera" in tomllib.loads(Path(scene.path).read_text(encoding="utf-8").removeprefix("\ufeff"))
    except (OSError, ValueError):
        return True


def located_line(text: str) -> str:
    """A failure's first line, and the first later line naming a file:line
    (a shader compiler's message has the location on a line of its own)."""
    lines = [ln.strip() for ln in text.splitlines() if ln.strip()]
    if not lines:
        return text
    located = next((ln for ln in lines[1:] if re.search(r"\.(frag|vert|glsl|toml):\d+", ln)), None)
    return lines[0] + (f" | {located}" if located else "")


class LiveScene:
    def __init__(self, viewer, watch: bool = True):
        self.viewer = viewer
        self.error = ""             # the last failed reload, shown in the HUD until a good one
        self.watcher = FileWatcher(self.watched_files()) if watch else None

    # -- watching

    def watched_files(self) -> list[Path]:
        """The scene file, its sky picture, and the shaders when they come
        from a folder someone edits (not an installed wheel's copy)."""
        scene = self.viewer.scene
        files = []
        if scene.path is not None:
            files.append(Path(scene.path))
        if scene.sky.type == "image" and scene.sky.image_path is not None:
            files.append(Path(scene.sky.image_path))
        if shaders_editable():
            files += shader_files(shader_root())
        return files

    def idle_wake_s(self) -> float:
        """How long an idle loop may sleep."""
        if self.watcher is None:
            return IDLE_WAKE_S
        return self.watcher.debounce_s if self.watcher.pending() else WATCH_WAKE_S

    def step(self) -> None:
        """From the loop: a watched file was saved (and held still): reload
        it, the shaders too when one of them changed."""
        if self.watcher is None:
            return
        changed = self.watcher.poll()
        if changed:
            self.reload(shaders=any(p.suffix in SHADER_SUFFIXES for p in changed))

    def _rewatch(self) -> None:
        """The files as they are now are the loaded ones (after a reload, good
        or not: a failed one waits for the next save; or another scene)."""
        if self.watcher is not None:
            self.watcher.watch(self.watched_files())

    # -- reloading

    def reload(self, shaders: bool = True) -> None:
        """F5, or a watched file saved: the scene file (the command line's
        overrides applied again) and, with `shaders`, the shaders from disk.
        Each part of the scene that changed in the file since it was read
        replaces the viewer's (merge_reloaded); on an error the last good
        scene and shaders keep running."""
        try:
            self._reload(shaders)
        finally:
            self._rewatch()

    def _reload(self, shaders: bool) -> None:
        v = self.viewer
        try:
            fresh = v.loader(v.args)
        except SceneError as e:
            self.failed(f"reload failed, keeping the last good scene: {e}")
            return
        merged = merge_reloaded(v.file_scene, fresh, v.scene)
        if shaders:
            try:
                renderer = Renderer(v.ctx, merged)  # compiles shaders/ from disk
            except Exception as e:
                # the shaders or the new scene's shader (a driver may reject it):
                # both stay as they were
                self.failed(f"reload failed, keeping the last good scene and shaders: {e}")
                return
            try:
                v.prog.reload_program()
            except Exception as e:
                renderer.release()
                self.failed(f"reload failed, keeping the last good shaders: {e}")
                return
            v.renderer.release()
            v.renderer = renderer
            v.prog.set_renderer(renderer)
        else:
            # only the scene file changed: the programs stay, and a change of
            # values compiles nothing (as an edit in the panel)
            try:
                v.renderer.set_scene(merged)
            except Exception as e:      # a scene the driver's shader rejects
                v.renderer.set_scene(v.scene)
                self.failed(f"reload failed, keeping the last good scene: {e}")
                return
            v.prog.restart()
        v.adopt_scene(merged, fresh, start=fresh)
        self.error = ""
        v.say("reloaded scene and shaders" if shaders else "reloaded the scene")
        print("reloaded", flush=True)

    def failed(self, text: str) -> None:
        """Say why (stderr, the panel), and keep it in the HUD until a reload
        succeeds."""
        self.viewer.error(text)
        self.error = located_line(text)
        self.viewer.needs_display = True

    # -- opening

    def open(self, spec: str) -> bool:
        """Show another scene: a file (dropped on the window, or typed in the
        panel) or a built-in scene's name, with the command line's overrides.
        Its camera is its file's when the file has a [camera] table; without
        one the view stays where it is.  From then on F5 and the watcher
        follow that file.  A scene that cannot be opened leaves the shown one
        as it was, and says why."""
        v = self.viewer
        args = copy.copy(v.args)
        args.scene = spec
        try:
            fresh = v.loader(args)
        except SceneError as e:
            v.error(f"cannot open {spec}: {e}")
            return False
        scene = copy.deepcopy(fresh)
        if not has_camera_table(fresh):
            scene.camera = copy.deepcopy(v.scene.camera)
        try:
            v.renderer.set_scene(scene)      # compiles when its features differ
        except Exception as e:
            v.renderer.set_scene(v.scene)
            v.error(f"cannot open {spec}: {e}")
            return False
        v.args = args
        v.prog.restart()
        v.adopt_scene(scene, fresh, start=scene)
        if v.panel is not None:
            v.panel.scene_opened(scene)
        self.error = ""
        self._rewatch()
        v.say(f"opened {scene.name}")
        print(f"opened {scene.path or spec}", flush=True)
        return True
