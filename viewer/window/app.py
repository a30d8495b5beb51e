"""The interactive viewer: its loop and its events.

It opens a window from viewer/window/backend.py (OpenGL 3.3 core or newer), turns GLFW's events into
calls on :class:`viewer.controls.Controls`, runs the loop and draws with the
shared renderer through :class:`viewer.progressive.Progressive` (previews at
a reduced resolution while something moves, accumulation at full
resolution when it stops -- with `--adaptive` (or the panel) only the pixels
that still need samples get more after the first full sample -- and nothing at
all once the scene's ``samples`` are reached: the loop then sleeps in
``glfw.wait_events``).  The settings panel,
the HUD and the help overlay are Dear ImGui (imgui-bundle) widgets from
viewer/window/panel.py; without imgui-bundle the viewer still runs, with the HUD in
the window title and the help on stdout.
"""

from __future__ import annotations

import copy
import ctypes
import math
import os
import sys
import time
import traceback
from dataclasses import fields

from . import backend  # first: it imports imgui-bundle before glfw (backend.py says why)
from .backend import WindowError, create_window, gl_object_counts, init_glfw, no_window_message, rss_kb

import glfw  # noqa: E402  (after backend)
import moderngl
import numpy as np

from ..base import interrupt
from ..base.errors import Failure
from ..base.views import raw_view
from ..gpu.context import size_failure
from ..gpu.renderer import Renderer
from ..scene.model import Scene
from ..scene.save import overrides_of_file
from .controls import Controls
from .history import EditHistory
from .hud import DEPTH, HINT, NOTE, RESOLUTION, STATUS, VIEW_NAMES, help_text, window_picture
from .events import InputEvents
from .picking import ObjectPicking
from .selection import Selection
from .max_error import MaxError
from .progressive import Progressive
from .screenshot import save_linear, save_rgb8
from .soak import soak_step
from .live import LiveScene

#: After the last change, the view counts as still (full resolution) after this long.
SETTLE_S = 0.12
#: Frame time the previews aim for, ms.
DEFAULT_TARGET_MS = 33.0
#: While samples accumulate, the window shows the progress this often (s).
ACCUMULATE_DISPLAY_S = 0.25
#: The HUD's fps and frame time are means over this long (s).
FPS_WINDOW_S = 0.5
#: How long a HUD message that says what was done stays (s).  One that
#: says something went wrong stays until read: until a key or a button is
#: pressed at least READ_S after it appeared (the key that caused it, held,
#: does not take it away).
MESSAGE_S = 6.0
READ_S = 1.0


def run(args, load) -> int:
    """Open the viewer on `load(args)` and run it until the window closes.

    `load` (args -> Scene: the scene file plus the command line's overrides)
    is handed in by the caller, the CLI, so that F5 reloads exactly what the
    command line asked for without the window layer importing the CLI."""
    scene = load(args)
    try:
        viewer = Viewer(args, scene, load)
    except WindowError as e:
        raise Failure(str(e)) from None
    try:
        return viewer.run()
    except Exception as e:
        # a window larger than the driver can back with framebuffers fails
        # at its first frame (Progressive.resize, which set the size it tried)
        too_large = size_failure(e, *viewer.prog.size) if viewer.prog is not None else None
        if too_large is None:
            raise
        raise too_large from e
    finally:
        viewer.close()


class Viewer(InputEvents, ObjectPicking):
    def __init__(self, args, scene: Scene, loader):
        self.args = args
        self.loader = loader  # args -> scene (scene file plus overrides), for F5
        self.debug = bool(getattr(args, "debug", False))
        self.soak = int(getattr(args, "soak", 0) or 0)
        self.imgui = backend.imgui
        self.imgui_error = backend.IMGUI_ERROR    # why there is no panel (None: there is one)
        self.window = None
        self.ctx = None
        self.renderer = None
        self.prog = None
        self._imgui_ready = False
        # what close() releases, set before _open can fail (a shader that does
        # not compile, a sky picture too large for the driver): close() then
        # met none of them and raised AttributeError, which hid the error
        self.max_error = MaxError(self)     # the panel's "max error" (window/max_error.py)
        self.live: LiveScene | None = None  # the scene's files: reload, watch, open (window/live.py)
        self.open_request: str | None = None    # a scene to open at the next frame (a drop)
        self.history = EditHistory()        # undo / redo of the panel's edits (window/history.py)
        self.debug_tex = self.debug_fbo = None
        self.selection: Selection | None = None   # the object a click selected (window/picking.py)
        self._last_click: tuple[float, float] | None = None
        self._errors = init_glfw()
        try:
            self._open(scene)
        except BaseException:
            self.close()
            raise

    # ------------------------------------------------------------ setup

    def _open(self, scene: Scene) -> None:
        w, h = self.args.size
        self.window = win = create_window(w, h, self._title(scene), True, self._errors)
        glfw.make_context_current(win)
        glfw.swap_interval(1 if getattr(self.args, "vsync", True) else 0)
        try:
            self.ctx = moderngl.create_context(require=330)
        except Exception as e:
            raise WindowError(no_window_message(f"no OpenGL 3.3 context ({e})")) from None

        self.scene = scene
        self.file_scene = copy.deepcopy(scene)  # as loaded: F5 takes what changed on disk since
        self.good_scene = copy.deepcopy(scene)  # the last scene the renderer accepted
        self.renderer = Renderer(self.ctx, scene)
        # adaptive accumulation with `view --adaptive` or the panel's "adaptive"
        # checkbox; off by default: it reaches a given error sooner, but a
        # still view then goes on tracing several times as long (README, "Viewer")
        self.prog = Progressive(self.ctx, self.renderer, DEFAULT_TARGET_MS,
                                adaptive=bool(getattr(self.args, "adaptive", False)))
        self.controls = Controls(scene, glfw.get_window_size(win))
        self.selection = Selection(self.ctx)

        self.show_panel = False
        self.show_help = False
        self._help_rect = None  # where the help was last drawn (_ui_rects)
        self.actions: list[str] = []
        # keys that came while ImGui still had earlier input to take (it takes
        # a few events a frame): (its event id, name, mods, action); shortcut
        # or typed text is decided in the frame ImGui takes the key
        self._deferred_keys: list[tuple[int, str, int, int]] = []
        self.need_preview = True
        self.needs_display = True
        self.ui_frames = 2
        self.last_change = time.perf_counter()
        self.message = ""
        self.message_until = 0.0
        self.message_kind = "info"   # or "error": kept until read (say)
        self.message_t0 = 0.0
        self._one_draw_warned = None
        self._warn_one_draw()
        self.frame_ms = 0.0
        self.fps = 0.0
        self.work_ms = 0.0      # a drawn frame's mean time in the loop, over the same window as fps
        self._fps_count = 0
        self._work_sum_ms = 0.0
        self._fps_t0 = time.perf_counter()
        self.overhead_ms = 3.0
        self._title_t = 0.0
        self._last_display = 0.0
        self._overlay_layout = None
        self._preview_frames: list[float] = []
        self._cursor: tuple[float, float] | None = None
        self._want_window_shot = 0  # frames to draw before F12 reads the window back
        self._window_shots = 0  # F12 presses waiting for it (one file each)
        self.frames = 0
        self.panel = None
        # debug views (V): the picture at debug_res, shown from debug_fbo
        self.debug_tex = self.debug_fbo = None
        self.debug_pic = None  # uint8 (H, W, 3), the window's picture
        self.debug_res: tuple[int, int] | None = None
        self.debug_dirty = True

        self._setup_imgui()
        self._install_callbacks()
        self.live = LiveScene(self, watch=getattr(self.args, "watch", True))
        if self.imgui is None:
            print(f"glassray: the settings panel is not available ({self.imgui_error}); "
                  "install imgui-bundle for it. The HUD is in the window title.", file=sys.stderr)

    def _setup_imgui(self) -> None:
        if self.imgui is None:
            return
        imgui = self.imgui
        try:
            from .panel import Panel  # imports imgui_bundle: only when it loaded (backend.IMGUI_ERROR)

            imgui.create_context()
            imgui.get_io().set_ini_filename(None)
            imgui.style_colors_dark()
            addr = ctypes.cast(self.window, ctypes.c_void_p).value
            if not imgui.backends.glfw_init_for_opengl(addr, False):
                raise RuntimeError("the ImGui GLFW backend did not start")
            if not imgui.backends.opengl3_init("#version 330 core"):
                imgui.backends.glfw_shutdown()
                raise RuntimeError("the ImGui OpenGL 3 backend did not start")
            self._addr = addr
            self._imgui_ready = True
            self.panel = Panel(self.scene, DEFAULT_TARGET_MS)
            self.panel.adaptive = self.prog.adaptive
            self.panel.overrides = overrides_of_file(self.file_scene)
        except Exception as e:
            self.imgui_error = f"{type(e).__name__}: {e}"
            try:
                imgui.destroy_context()
            except Exception:
                pass
            self.imgui = None
            self.panel = None

    def _title(self, scene: Scene) -> str:
        return f"glassray - {scene.name}"

    # ------------------------------------------------------------ loop

    def run(self) -> int:
        gl_start = rss_start = None
        # the GL objects and memory are counted after the warm-up (caches
        # filled) and at the end; a short soak (a smoke run) warms up for
        # half its frames, so that both counts are taken and some frames
        # lie between them
        warm = min(max(50, self.soak // 5), self.soak // 2)
        while not glfw.window_should_close(self.window):
            self._wait()
            interrupt.check()         # Ctrl-C in the terminal (deferred: viewer/base/interrupt.py)
            self.live.step()
            if self.soak:
                soak_step(self)
                if self.frames == warm:
                    # an adaptive render in flight holds a few GL objects of
                    # its own: counted with none in flight, at both ends; and
                    # its shader variants (cached per scene features) are
                    # compiled by now, even those its first rounds have not
                    # needed yet (with samples 1 it traces no pixel lists)
                    self.prog.restart()
                    self.prog.compile_adaptive()
                    gl_start, rss_start = gl_object_counts(self.ctx, self.prog), rss_kb()
                    variants_start = len(self.renderer._subset_programs)
                if self.frames >= self.soak:
                    break
            self._frame()
        if self.soak:
            self.prog.restart()
            self.ctx.finish()
            gl_end, rss_end = gl_object_counts(self.ctx, self.prog), rss_kb()
            variants_end = len(self.renderer._subset_programs)
            moving = sorted(self._preview_frames)      # none in a soak of 11 frames or fewer
            moving_ms = f"{moving[len(moving) // 2]:.1f}" if moving else "n/a"
            print(f"soak: frames={self.frames} warmup={warm} rss_kb={rss_start}->{rss_end} "
                  f"gl_objects={sum(gl_start.values())}->{sum(gl_end.values())} "
                  f"culling_variants={variants_start}->{variants_end}/{self.renderer.SUBSET_PROGRAMS} "
                  f"moving_frame_ms_median={moving_ms} "
                  f"preview={self.prog.preview_size} detail={gl_start}->{gl_end}", flush=True)
        return 0

    def _busy(self) -> bool:
        return bool((self.need_preview and self.controls.view == "image") or self.controls.changed or self.actions or self.ui_frames > 0
                    or self.needs_display or self._want_window_shot or self.max_error.job is not None
                    or (self.controls.view != "image" and self.debug_dirty))

    def _wait(self) -> None:
        if self.soak:
            glfw.poll_events()
            return
        fbw, fbh = glfw.get_framebuffer_size(self.window)
        if fbw <= 0 or fbh <= 0:  # minimised: nothing to draw until it comes back
            glfw.wait_events_timeout(self.live.idle_wake_s())
            return
        if self._busy():
            glfw.poll_events()
            return
        if self._pending(fbw, fbh):
            left = self.last_change + SETTLE_S - time.perf_counter()
            if left > 0:
                glfw.wait_events_timeout(left)
            else:
                glfw.poll_events()
            return
        if self.message and self.message_until > time.perf_counter():
            # idle, but a HUD message is to disappear: wake up then (or to
            # look at the watched files, sooner)
            glfw.wait_events_timeout(min(self.message_until - time.perf_counter() + 0.01, self.live.idle_wake_s()))
            if time.perf_counter() >= self.message_until:
                self.message = ""
                self.needs_display = True
            return
        # idle: all samples done, nothing changed.  Sleep until an event (the
        # timeout lets Python see a Ctrl-C now and then, and a watched file's save)
        glfw.wait_events_timeout(self.live.idle_wake_s())

    def _pending(self, fbw: int, fbh: int) -> bool:
        """Work left once the view is still: samples to accumulate, or the
        debug view at full resolution."""
        if self.controls.view == "image":
            return not self.prog.done
        return self.debug_dirty or self.debug_res != (fbw, fbh)

    def _warn_one_draw(self) -> None:
        """Say (stderr and HUD) where the scene's trees may be more than the
        one draw a sample the viewer gives them (Renderer.one_draw_warning):
        at the start, and again whenever a change of settings makes it so."""
        warning = self.renderer.one_draw_warning("the viewer")
        if warning and warning != self._one_draw_warned:
            print(warning, file=sys.stderr, flush=True)
            self.say("trees this deep may be cut short here; 'glassray render' traces them whole")
        self._one_draw_warned = warning

    def framebuffer_size(self) -> tuple[int, int]:
        """The window's size in pixels (0 x 0 while minimised)."""
        return glfw.get_framebuffer_size(self.window)

    def say(self, text: str, error: bool = False, keep: bool = False) -> None:
        """Show `text` in the HUD: for MESSAGE_S, or, when `error` or `keep`,
        in the error colour until read (message_read); an `error` goes to
        stderr too."""
        now = time.perf_counter()
        self.message, self.message_t0 = text, now
        self.message_kind = "error" if (error or keep) else "info"
        self.message_until = math.inf if (error or keep) else now + MESSAGE_S
        self.needs_display = True
        if error:
            print(f"glassray: {text}", file=sys.stderr, flush=True)

    def message_read(self) -> None:
        """A key or a mouse button pressed: a kept message has been read,
        once it has been up for READ_S."""
        if self.message and self.message_kind == "error" and time.perf_counter() - self.message_t0 >= READ_S:
            self.message, self.message_until = "", 0.0
            self.needs_display = True

    def _frame(self) -> None:
        """One turn of the loop: take the input, update the scene, trace
        (a preview, accumulation, or a debug view), draw what changed."""
        t0 = time.perf_counter()
        win = self.window
        fbw, fbh = glfw.get_framebuffer_size(win)
        if fbw <= 0 or fbh <= 0:  # minimised: only quitting makes sense
            if "quit" in self.actions:
                glfw.set_window_should_close(win, True)
            self.needs_display = False
            self.ui_frames = 0
            self.actions.clear()
            return
        if (fbw, fbh) != self.prog.size:
            self.prog.resize(fbw, fbh)
            self.need_preview = True
            self.last_change = t0

        actions, self.actions = self.actions, []
        want_shot = self._take_actions(actions)
        if self.open_request is not None:
            request, self.open_request = self.open_request, None
            self.open_scene(request)
        ui = self._imgui_ready
        self._take_pick(fbw, fbh)
        self._apply_move()
        if ui:
            self._ui_new_frame()
        self._keep_selection_valid()
        if self.controls.take_changed():
            self._apply_scene()
            self.need_preview = True
            self.debug_dirty = True
            self.selection.stale = True
            self.last_change = t0
        if self.max_error.job is not None:
            self.max_error.step()

        traced, previewed, show_trace = self._trace(t0, fbw, fbh)
        trace_ms = self.prog.last_trace_ms if traced else 0.0
        for _ in range(want_shot):
            self.screenshot()
        draw = bool(show_trace or self.needs_display or self.ui_frames > 0 or self._want_window_shot)
        self._present(draw, ui, t0, fbw, fbh)
        if draw:
            self._count_frame(t0, traced, previewed, trace_ms)

    def _take_actions(self, actions: list[str]) -> int:
        """Do what the keys asked since the last frame; the number of
        screenshots asked for (P pressed three times quickly: three files)."""
        want_shot = 0
        for act in actions:
            if act == "quit":
                glfw.set_window_should_close(self.window, True)
            elif act == "toggle_panel":
                if self.panel is not None:
                    self.show_panel = not self.show_panel
                else:
                    self.say(f"no settings panel: imgui-bundle is not available ({self.imgui_error})", error=True)
            elif act == "help":
                self.show_help = not self.show_help
                if self.imgui is None and self.show_help:
                    print(help_text(), flush=True)
            elif act == "reload":
                self.reload()
            elif act == "screenshot":
                want_shot += 1
            elif act == "view":
                self._view_changed()
            elif act == "deselect":
                self.select(None)
            elif act in ("undo", "redo"):
                self.undo(redo=act == "redo")
            elif act == "save_scene":
                self.save_scene()
            elif act == "screenshot_window":
                # ImGui shows a window that just opened one frame later: let the
                # overlays settle for a frame, then read the window back
                self._want_window_shot = 2
                self._window_shots += 1
        if self.controls.message:
            self.say(self.controls.message)
            self.controls.message = ""
        return want_shot

    def _ui_new_frame(self) -> None:
        """Start ImGui's frame: the shortcuts it held back, then the panel and
        what its edits change."""
        imgui = self.imgui
        imgui.backends.opengl3_new_frame()
        imgui.backends.glfw_new_frame()
        imgui.new_frame()
        if self._deferred_keys:
            # the keys this new_frame took: want_text_input, which it has
            # just set from the last frame's widgets, says whether a text
            # field had the keyboard when ImGui took each (trickling, it
            # takes a key's press and the text typed in different frames)
            ctx = imgui.get_current_context()
            queue = ctx.input_events_queue
            left = queue[0].event_id if len(queue) else ctx.input_events_next_event_id
            taken = [k for k in self._deferred_keys if k[0] < left]
            self._deferred_keys = [k for k in self._deferred_keys if k[0] >= left]
            for _, name, mods, action in taken:
                if not self._ui_wants_keys():
                    self._shortcut(name, mods, action)
        if not self.show_panel:
            return
        ds = imgui.get_io().display_size
        self.panel.view = self.controls.view
        self.panel.quality_status = self.max_error.status
        self.history.at_rest(self.scene)
        # a window with no room for the HUD beside the panel: the panel shows it
        self.panel.hud = self._overlay_hud() if self.panel.hud_inside((ds.x, ds.y)) else None
        res = self.panel.draw(self.scene, (ds.x, ds.y))
        self.history.after_panel(self.scene, changed=res.changed or res.camera_changed,
                                 active=imgui.is_any_item_active() or self.controls.dragging == "move")
        if self.panel.selected != self.controls.selected:   # a node of the panel's objects clicked
            self.select(self.panel.selected)
        if res.view_changed:
            self.controls.set_view(self.panel.view)
            self._view_changed()
        if res.quality_changed or res.remeasure:
            self.max_error.update(remeasure=res.remeasure)
        if res.camera_changed:
            self.controls.camera_edited()
        if res.changed:
            self.controls.changed = True
        if res.target_ms_changed:
            self.prog.target_ms = self.panel.target_ms
        if res.adaptive_changed:
            self._set_adaptive(self.panel.adaptive)
        if res.open_path:
            self.open_scene(res.open_path)

    def _trace(self, t0: float, fbw: int, fbh: int) -> tuple[bool, bool, bool]:
        """Trace this frame's share: a preview right after a change,
        full-resolution samples once still (a debug view instead: its
        picture, reduced while things move).  (traced, previewed, whether
        the window should show the result now)."""
        if self.controls.view != "image":
            return False, False, self._debug_frame(t0, fbw, fbh)
        if self.need_preview:
            self.prog.render_preview(max(5.0, self.prog.target_ms - self.overhead_ms))
            self.need_preview = False
            return True, True, True
        if not self.prog.done and (self.soak or t0 - self.last_change >= SETTLE_S) and self.max_error.job is None:
            landed = (self.prog.passes_done, self.prog.uploads)
            try:
                self.prog.accumulate(self.prog.target_ms)
            except Exception as e:  # an adaptive shader variant that does not compile
                if not self.prog.adaptive:
                    raise
                self._set_adaptive(False)
                self.error(f"adaptive accumulation failed, accumulating uniformly: {e}")
            # progress is shown a few times a second (the display pass and the
            # buffer swap are not free on a software renderer), and at once
            # when a sample completes (adaptive: when new sums land)
            show = bool((self.prog.passes_done, self.prog.uploads) != landed or self.soak
                        or t0 - self._last_display >= ACCUMULATE_DISPLAY_S)
            return True, False, show
        return False, False, False

    def _present(self, draw: bool, ui: bool, t0: float, fbw: int, fbh: int) -> None:
        """Put the picture and the overlays on screen when `draw` (the HUD in
        the title without ImGui), take a window screenshot when asked, swap."""
        win = self.window
        if draw:
            if self.controls.view == "image" or self.debug_fbo is None:
                self.prog.display(self.ctx.screen, (0, 0, fbw, fbh))
            else:
                self.ctx.copy_framebuffer(self.ctx.screen, self.debug_fbo)
                # copy_framebuffer leaves the last framebuffer used bound (the
                # renderer's target, where the view was traced): the overlays
                # below must go to the window
                self.ctx.screen.use()
            self._outline(t0, fbw, fbh)
        if ui:
            imgui = self.imgui
            if draw:
                self._draw_overlays()
            imgui.render()
            if draw:
                imgui.backends.opengl3_render_draw_data(imgui.get_draw_data())
        elif draw and (t0 - self._title_t > 0.25 or not self._pending(fbw, fbh)):
            glfw.set_window_title(win, self._title(self.scene) + "  |  " + "  |  ".join(self._hud_lines()))
            self._title_t = t0
        if self._want_window_shot and draw:
            self._want_window_shot -= 1
            if self._want_window_shot == 0:
                shots, self._window_shots = max(1, self._window_shots), 0
                for _ in range(shots):
                    self._window_screenshot(fbw, fbh)
        if draw:
            glfw.swap_buffers(win)
            self.frames += 1
            self._last_display = time.perf_counter()
        self.needs_display = False
        self.ui_frames = max(0, self.ui_frames - 1)
        if ui and (self._deferred_keys or self._imgui_backlog()):
            # ImGui takes fast input over several frames: draw until it has
            # all of it (it waited for the next mouse move), then the keys
            self.ui_frames = max(self.ui_frames, 1)

    def _outline(self, t0: float, fbw: int, fbh: int) -> None:
        """The selection's outline over the picture: its id map made again
        once the view is still (while things move the outline waits)."""
        if self.controls.selected is None:
            return
        if self.selection.stale and (self.soak or t0 - self.last_change >= SETTLE_S) and not self.need_preview:
            self.selection.update(self.renderer, fbw, fbh)
        self.selection.draw(self.ctx.screen, (0, 0, fbw, fbh), self.controls.selected)

    def _count_frame(self, t0: float, traced: bool, previewed: bool, trace_ms: float) -> None:
        """The HUD's frame time and rate, and the overhead the next preview
        leaves room for, after a frame that was drawn."""
        t1 = time.perf_counter()
        self.frame_ms = (t1 - t0) * 1000.0
        if self.soak and previewed and self.frames > 10:
            self._preview_frames.append(self.frame_ms)
        if traced:
            self.overhead_ms = 0.8 * self.overhead_ms + 0.2 * max(0.0, self.frame_ms - trace_ms)
        self._fps_count += 1
        self._work_sum_ms += self.frame_ms
        if t1 - self._fps_t0 >= FPS_WINDOW_S:
            # both numbers of the HUD's line over the same frames: the rate
            # frames were drawn at, and what each took on average
            self.fps = self._fps_count / (t1 - self._fps_t0)
            self.work_ms = self._work_sum_ms / self._fps_count
            self._fps_count, self._work_sum_ms, self._fps_t0 = 0, 0.0, t1

    def _rate_line(self) -> str:
        """The HUD's timing: frames drawn per second and a frame's mean time,
        both over the last FPS_WINDOW_S (before the first window closes,
        the last frame's time)."""
        work = self.work_ms if self.fps > 0 else self.frame_ms
        return f"{self.fps:.0f} fps, {work:.1f} ms a frame"

    def _hud_lines(self) -> list[str]:
        """The HUD's lines as text (the window title's, without ImGui)."""
        return [text for text, _ in self._hud()]

    def _hud(self) -> list[tuple[str, int]]:
        """The HUD's lines, each with how readily it is left out of a small
        window (hud.py's ranks)."""
        q = [self.max_error.status] if self.max_error.on and self.max_error.status else []
        if self.live is not None and self.live.error:
            q.append(self.live.error)
        q += self._selection_hud()
        if self.controls.view != "image":
            rw, rh = self.debug_res or self.prog.size
            return [(self._rate_line(), STATUS),
                    (f"view: {VIEW_NAMES.get(self.controls.view, self.controls.view)}  (V: next)", STATUS),
                    (f"{rw}x{rh}" + (" (preview)" if (rw, rh) != self.prog.size else ""), RESOLUTION),
                    (f"max depth {self.scene.render.max_depth}", DEPTH), *((t, NOTE) for t in q)]
        rw, rh = self.prog.active_resolution
        preview = (rw, rh) != self.prog.size
        total = self.prog.samples
        if self.prog.adaptive:
            samples = (f"samples {self.prog.mean_spp:.1f}/{total} mean per pixel (adaptive)"
                       + ("" if self.prog.done else " ..."))
        else:
            done = self.prog.passes_done
            samples = f"samples {done}/{total}" + ("" if done >= total else " ...")
        # once every sample is in, the viewer draws nothing more: a rate of
        # frames would stay on screen, stale (it read 22 fps long after)
        timing = (f"idle (last frame {self.frame_ms:.1f} ms)" if self.prog.done and not preview
                  else self._rate_line())
        return [(timing, STATUS),
                (f"{rw}x{rh}" + (" (preview)" if preview else ""), RESOLUTION),
                (samples, STATUS),
                (f"max depth {self.scene.render.max_depth}", DEPTH), *((t, NOTE) for t in q)]

    def _overlay_hud(self) -> tuple[list[tuple[str, int]], str, str]:
        """What the HUD says this frame: its lines, the message, its kind."""
        msg = self.message if time.perf_counter() < self.message_until else ""
        lines = self._hud()
        if not self.show_panel:
            lines.append(("Tab: settings  H: help", HINT))
        return lines, msg, self.message_kind

    def _draw_overlays(self) -> None:
        from . import overlays  # imgui_bundle, present once _setup_imgui ran

        ds = self.imgui.get_io().display_size
        lines, msg, kind = self._overlay_hud()
        inside = self.show_panel and self.panel.hud_inside((ds.x, ds.y))
        right = self.panel.left_edge((ds.x, ds.y)) if self.show_panel else ds.x
        if not inside:            # else the panel drew it (_ui_new_frame)
            overlays.draw_hud(lines, msg, kind, right=right)
        # an auto-sized ImGui window takes its new size one frame late: draw
        # again when the overlays' layout changes
        layout = (len(lines), msg, self.show_help, self.show_panel, inside, right, ds.y)
        if layout != self._overlay_layout:
            self._overlay_layout = layout
            self.ui_frames = max(self.ui_frames, 2)
        if self.show_help:
            self.show_help = overlays.draw_help((ds.x, ds.y))
        self._help_rect = overlays.help_rect if self.show_help else None

    def _ui_rects(self) -> list[tuple[float, float, float, float]]:
        """Where ImGui's windows that take the mouse were last drawn (window
        coordinates): the panel and the help, when shown."""
        rects = [self.panel.rect] if self.show_panel and self.panel is not None else []
        return rects + ([self._help_rect] if self.show_help and self._help_rect else [])

    # ------------------------------------------------------------ debug views (V)

    def _view_changed(self) -> None:
        self.debug_dirty = True
        self.needs_display = True
        if self.controls.view == "image":
            self.need_preview = not self.prog.started
        self.say(f"view: {self.controls.view}")

    def _debug_frame(self, t0: float, fbw: int, fbh: int, force_full: bool = False) -> bool:
        """Compute the debug view's picture when it is out of date: at a
        reduced resolution while things move, at full resolution once still.
        True when a new picture is ready."""
        settled = force_full or bool(self.soak) or t0 - self.last_change >= SETTLE_S
        if not self.debug_dirty and (self.debug_res == (fbw, fbh) or not settled):
            return False
        if settled:
            size = (fbw, fbh)
        else:
            sc = self.prog.preview_scale(max(5.0, self.prog.target_ms - self.overhead_ms))
            size = (max(1, round(fbw * sc)), max(1, round(fbh * sc)))
        raw = raw_view(self.renderer, self.controls.view, *size)   # into the renderer's kept target
        pic = window_picture(self.controls.view, raw, fbw, fbh)
        if self.debug_tex is None or self.debug_tex.size != (fbw, fbh):
            self._release_debug()
            self.debug_tex = self.ctx.texture((fbw, fbh), 3, alignment=1)
            self.debug_fbo = self.ctx.framebuffer(color_attachments=[self.debug_tex])
        self.debug_tex.write(np.ascontiguousarray(pic[::-1]).tobytes(), alignment=1)
        self.debug_pic = pic
        self.debug_res = size
        self.debug_dirty = False
        return True

    def _release_debug(self) -> None:
        for obj in (self.debug_fbo, self.debug_tex):
            if obj is not None:
                obj.release()
        self.debug_fbo = self.debug_tex = None
        self.debug_res = None
        self.debug_dirty = True

    # ------------------------------------------------------------ scene changes

    def _apply_scene(self) -> None:
        try:
            self.renderer.set_scene(self.scene)
            self.good_scene = copy.deepcopy(self.scene)
        except Exception as e:  # ShaderError, a scene the packer rejects
            if self.debug:
                traceback.print_exc()
            self.error(f"change not applied: {e}")
            for f in fields(Scene):
                setattr(self.scene, f.name, copy.deepcopy(getattr(self.good_scene, f.name)))
            self.controls.camera_edited()
            self.controls.changed = False
            self.renderer.set_scene(self.scene)
        self._warn_one_draw()
        self.prog.restart()

    def _set_adaptive(self, on: bool) -> None:
        """Adaptive or uniform accumulation (the panel's "adaptive"): starts over."""
        if self.prog.adaptive != bool(on):
            self.prog.adaptive = on
            self.needs_display = True
        if self.panel is not None:
            self.panel.adaptive = self.prog.adaptive

    def error(self, text: str) -> None:
        """Something the user asked for failed: its first line kept in the
        HUD until read, the whole text on stderr and in the panel."""
        self.say(text.splitlines()[0] if text else text, keep=True)
        print(f"glassray: {text}", file=sys.stderr, flush=True)
        if self.panel is not None:
            self.panel.error = text

    def reload(self, shaders: bool = True) -> None:
        """F5 (window/live.py, LiveScene.reload)."""
        self.live.reload(shaders)

    def open_scene(self, spec: str) -> bool:
        """Another scene, dropped or typed in the panel (LiveScene.open)."""
        return self.live.open(spec)

    def adopt_scene(self, scene: Scene, fresh: Scene, start: Scene) -> None:
        """Show `scene`, already on the renderer: a reload or another scene
        opened.  `fresh` is the file as read (what the next reload compares
        against), `start` what R goes back to.  The panel's edits were of
        the scene before: the undo history is cleared.  A selection stays
        through a reload of the same file while its object is still there."""
        same_file = scene.path is not None and scene.path == self.scene.path
        self.scene = scene
        self.file_scene = copy.deepcopy(fresh)
        self.good_scene = copy.deepcopy(scene)
        self._warn_one_draw()
        self.controls.rebase(scene, start=start)
        if self.panel is not None:
            self.panel.error = ""
            self.panel.overrides = overrides_of_file(fresh)
        glfw.set_window_title(self.window, self._title(scene))
        self.debug_dirty = True
        if self.max_error.on:
            # measured again unless the cache has it (its key holds the
            # scene and the shaders, so an unchanged file is a hit)
            self.max_error.close()
            self.max_error.parts = None
            self.max_error.update()
        self.need_preview = True
        self.last_change = time.perf_counter()
        self.history.clear()
        self.selection.stale = True
        i = self.controls.selected
        if i is not None and not (same_file and i < len(scene.objects)):
            self._set_selected(None)

    def save_scene(self) -> bool:
        """Ctrl+S: the panel's "Save scene" (its path box, the command line's
        values as the file had them), said in the HUD."""
        if self.panel is None:
            self.say(f"cannot save: there is no settings panel ({self.imgui_error})", error=True)
            return False
        ok = self.panel.save(self.scene)
        self.say(self.panel.status, keep=not ok)
        return ok

    def undo(self, redo: bool = False) -> bool:
        """Ctrl+Z (redo: Ctrl+Shift+Z, Ctrl+Y): put back the parts of the
        scene the last panel edit changed (window/history.py)."""
        edit = self.history.redo(self.scene) if redo else self.history.undo(self.scene)
        if edit is None:
            self.say("nothing to redo" if redo else "nothing to undo")
            return False
        if "camera" in edit.parts:
            self.controls.camera_edited()
        self.controls.changed = True
        self.say(f"{'redone' if redo else 'undone'}: {', '.join(edit.parts)}")
        return True

    # ------------------------------------------------------------ screenshots

    def screenshot(self) -> None:
        """P: the accumulated image (at least one full sample), no HUD or panel;
        in a debug view its picture at full resolution."""
        if self.controls.view != "image":
            fbw, fbh = glfw.get_framebuffer_size(self.window)
            if self.debug_res != (fbw, fbh) or self.debug_dirty:
                self._debug_frame(time.perf_counter(), fbw, fbh, force_full=True)
            self._save_screenshot(save_rgb8, self.debug_pic)
            return
        self.prog.finish_pass()
        self._save_screenshot(save_linear, self.prog.image())

    def _save_screenshot(self, save, pixels) -> None:
        """Save under the next free name in the current folder; the path on
        stdout, or what went wrong, and in which folder, on stderr and the HUD."""
        try:
            path = save(pixels)
        except OSError as e:
            try:
                folder = os.getcwd()
            except OSError:             # the folder the viewer runs in was removed
                folder = "the current folder, which no longer exists"
            self.say(f"screenshot not saved in {folder}: {e.strerror or e}", error=True)
            return
        print(os.path.abspath(path), flush=True)
        self.say(f"saved {path.name}")

    def _window_screenshot(self, fbw: int, fbh: int) -> None:
        raw = self.ctx.screen.read(viewport=(0, 0, fbw, fbh), components=3, alignment=1)
        rgb = np.frombuffer(raw, dtype=np.uint8).reshape(fbh, fbw, 3)[::-1]
        self._save_screenshot(save_rgb8, rgb)

    # ------------------------------------------------------------ soak (debug)

    # ------------------------------------------------------------ shutdown

    def close(self) -> None:
        if self._imgui_ready:
            try:
                self.imgui.backends.opengl3_shutdown()
                self.imgui.backends.glfw_shutdown()
                self.imgui.destroy_context()
            except Exception:
                pass
            self._imgui_ready = False
        try:
            self.max_error.close()
        except Exception:
            pass
        self._release_debug()
        for obj in (self.selection, self.prog, self.renderer):
            if obj is not None:
                try:
                    obj.release()
                except Exception:
                    pass
        self.selection = self.prog = self.renderer = None
        if self.ctx is not None:
            try:
                self.ctx.release()
            except Exception:
                pass
            self.ctx = None
        if self.window is not None:
            glfw.destroy_window(self.window)
            self.window = None
        glfw.terminate()
