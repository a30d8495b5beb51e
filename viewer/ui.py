"""The viewer's Dear ImGui widgets (imgui-bundle): the settings panel, the
HUD and the help overlay.  Widgets only: the window module owns GLFW and the
ImGui backends and calls these between ``imgui.new_frame()`` and
``imgui.render()``.

The panel edits the scene in place and returns True when it changed
something that alters the picture.  Every value is kept inside the range the
scene format allows, so an edited scene is always a valid one (and "Save
scene" writes a file that loads back to it).
"""

from __future__ import annotations

import copy
import math
from dataclasses import dataclass
from pathlib import Path

from imgui_bundle import imgui

from .controls import HELP_ALL as HELP, VIEWS, first_point_light
from .scene import Light, Scene, save_scene

_CLAMP = imgui.SliderFlags_.always_clamp
_HDR = imgui.ColorEditFlags_.hdr | imgui.ColorEditFlags_.float
_BIG = 1e6


def _color(label: str, value) -> tuple[bool, tuple[float, float, float]]:
    changed, col = imgui.color_edit3(label, [float(v) for v in value], _HDR)
    col = tuple(max(0.0, float(c)) if math.isfinite(c) else 0.0 for c in col)
    return changed and col != tuple(value), col  # type: ignore[return-value]


def _vec3(label: str, value, speed: float = 0.01, lo: float = -_BIG, hi: float = _BIG):
    changed, v = imgui.drag_float3(label, [float(x) for x in value], speed, lo, hi, "%.3f", _CLAMP)
    v = tuple(float(x) if math.isfinite(x) else float(o) for x, o in zip(v, value))
    return changed and v != tuple(value), v


def _float(label: str, value: float, speed: float, lo: float, hi: float, fmt: str = "%.3f", flags: int = 0):
    changed, v = imgui.drag_float(label, float(value), speed, lo, hi, fmt, _CLAMP | flags)
    v = min(max(float(v), lo), hi) if math.isfinite(v) else float(value)
    return changed and v != value, v


@dataclass
class PanelResult:
    changed: bool = False  # the picture changes (renderer must get the scene)
    camera_changed: bool = False  # the camera was edited (the orbit camera must follow)
    target_ms_changed: bool = False
    view_changed: bool = False  # the view combo picked another view (Panel.view)
    quality_changed: bool = False  # "max error" switched or its value changed
    remeasure: bool = False  # "measure again" pressed
    adaptive_changed: bool = False  # "adaptive" switched (Panel.adaptive)


class Panel:
    """The settings panel (Tab)."""

    def __init__(self, scene: Scene, target_ms: float = 33.0):
        self.save_path = self.default_save_path(scene)
        self.status = ""  # last save result
        self.error = ""  # last reload / shader error
        self.target_ms = float(target_ms)
        self.open_all = False  # open every section and node (tests, soak)
        self.view = VIEWS[0]  # what the window shows (the app keeps it in step with V)
        self.max_error_on = False  # "max error": render settings picked by viewer.quality
        self.max_error = 0.02
        self.quality_status = ""  # "measuring ...", the pick, set by the app
        # the user's (samples, max_depth, min_weight) while "max error" has
        # replaced them with its pick (set by the app): "Save scene" writes
        # these, not a pick measured for this machine and window
        self.user_render: tuple[int, int, float] | None = None
        self.adaptive = True  # adaptive accumulation (the app keeps it in step with Progressive)
        self._drawn_size: tuple[float, float] | None = None  # the window size it was last drawn for
        self.rect = (0.0, 0.0, 0.0, 0.0)  # the panel's window: x0, y0, x1, y1

    def _open(self) -> None:
        if self.open_all:
            imgui.set_next_item_open(True, imgui.Cond_.always)

    @staticmethod
    def default_save_path(scene: Scene) -> str:
        p = scene.path
        try:
            from importlib import resources

            builtin = Path(str(resources.files("viewer.scenes"))).resolve()
            if p is not None and Path(p).resolve().parent != builtin:
                return str(p)
        except Exception:
            if p is not None:
                return str(p)
        stem = Path(p).stem if p is not None else "scene"
        return f"{stem}.toml"

    # ------------------------------------------------------------ drawing

    def draw(self, scene: Scene, size: tuple[int, int]) -> PanelResult:
        res = PanelResult()
        w, h = size
        pw = min(440.0, max(200.0, w * 0.45))
        # placed at the right edge when first shown and again whenever the
        # window's size changed since the panel was last drawn: left where it
        # was, a panel of a larger window ended up outside a smaller one (and
        # one squeezed through a tiny window, title bar and all, above and
        # left of it, where it could not even be dragged back)
        size_changed = (float(w), float(h)) != self._drawn_size
        self._drawn_size = (float(w), float(h))
        cond = imgui.Cond_.always if size_changed else imgui.Cond_.first_use_ever
        imgui.set_next_window_pos(imgui.ImVec2(w - 8.0, 8.0), cond, imgui.ImVec2(1.0, 0.0))
        imgui.set_next_window_size(imgui.ImVec2(pw, max(100.0, h - 16.0)), cond)
        visible, _ = imgui.begin("Settings", None, imgui.WindowFlags_.no_saved_settings)
        try:
            pos, wsize = imgui.get_window_pos(), imgui.get_window_size()
            self.rect = (pos.x, pos.y, pos.x + wsize.x, pos.y + wsize.y)  # where the panel is (tests)
            if visible:
                # widgets take the width the labels leave
                imgui.push_item_width(-imgui.calc_text_size("preview target (ms)").x - 8.0)
                try:
                    self._draw_contents(scene, res)
                finally:
                    imgui.pop_item_width()
        finally:
            imgui.end()
        return res

    def _draw_contents(self, scene: Scene, res: PanelResult) -> None:
        if self.error:
            imgui.push_text_wrap_pos(0.0)
            imgui.text_colored(imgui.ImVec4(1.0, 0.35, 0.3, 1.0), self.error)
            imgui.pop_text_wrap_pos()
            if imgui.small_button("dismiss"):
                self.error = ""
            imgui.separator()

        imgui.text(f"scene: {scene.name}")
        changed, self.save_path = imgui.input_text("##savepath", self.save_path)
        imgui.same_line()
        if imgui.button("Save scene"):
            self.save(scene)
        if self.status:
            imgui.text_wrapped(self.status)

        self._open()

        c, idx = imgui.combo("view (V)", VIEWS.index(self.view) if self.view in VIEWS else 0, list(VIEWS))
        lo, hi = imgui.get_item_rect_min(), imgui.get_item_rect_max()
        self.view_rect = (lo.x, lo.y, hi.x, hi.y)  # where the combo is (tests click it)
        if c and VIEWS[idx] != self.view:
            self.view, res.view_changed = VIEWS[idx], True

        if imgui.collapsing_header("Render", imgui.TreeNodeFlags_.default_open):
            r = scene.render
            c, on = imgui.checkbox("max error", self.max_error_on)
            if c:
                self.max_error_on, res.quality_changed = bool(on), True
            imgui.same_line()
            imgui.begin_disabled(not self.max_error_on)
            # no label of its own: the rest of the line (the panel's item
            # width keeps room for a label and left it a sliver in a narrow panel)
            imgui.set_next_item_width(imgui.get_content_region_avail().x)
            c, v = _float("##maxerror", self.max_error, 0.0005, 1e-4, 1.0, "RMSE %.4f", imgui.SliderFlags_.logarithmic)
            if c:
                self.max_error, res.quality_changed = v, True
            if self.max_error_on:
                if self.quality_status:
                    imgui.text_wrapped(_plain(self.quality_status))
                if imgui.small_button("measure again"):
                    res.remeasure = True
            imgui.end_disabled()
            imgui.begin_disabled(self.max_error_on)  # the pick sets these
            c, v = imgui.slider_int("max depth", r.max_depth, 1, 64, "%d", _CLAMP)
            if c and v != r.max_depth:
                r.max_depth, res.changed = int(v), True
            c, v = imgui.drag_int("samples", r.samples, 0.2, 1, 65536, "%d", _CLAMP)
            if c and v != r.samples:
                r.samples, res.changed = int(min(max(v, 1), 65536)), True
            c, v = _float("min weight", r.min_weight, 0.0005, 0.0, 1.0, "%.4f")
            if c:
                r.min_weight, res.changed = v, True
            imgui.end_disabled()
            c, on = imgui.checkbox("adaptive", self.adaptive)
            if c and bool(on) != self.adaptive:
                self.adaptive, res.adaptive_changed = bool(on), True
            if imgui.is_item_hovered():
                imgui.set_tooltip("samples only where pixels still need them (samples = the mean per pixel)")
            c, v = _float("exposure", r.exposure, 0.01, 1e-4, 1e4, "%.3f", imgui.SliderFlags_.logarithmic)
            if c:
                r.exposure, res.changed = v, True
            c, v = _float("preview target (ms)", self.target_ms, 0.5, 5.0, 1000.0, "%.0f")
            if c:
                self.target_ms, res.target_ms_changed = v, True

        self._open()

        if imgui.collapsing_header("Camera"):
            cam = scene.camera
            c1, pos = _vec3("position", cam.position)
            c2, tgt = _vec3("target", cam.target)
            c3, fov = _float("fov", cam.fov, 0.2, 1.0, 179.0, "%.1f")
            if (c1 or c2) and _camera_ok(pos, tgt):
                cam.position, cam.target = pos, tgt
                res.changed = res.camera_changed = True
            if c3:
                cam.fov = fov
                res.changed = res.camera_changed = True

        self._open()

        if imgui.collapsing_header("Lights", imgui.TreeNodeFlags_.default_open):
            if not scene.lights:
                imgui.text_disabled("(no lights)")
            moved = first_point_light(scene)
            for i, lt in enumerate(scene.lights):
                imgui.push_id(f"light{i}")
                label = f"light {i}" + (" (W/S/A/D/Q/E)" if i == moved else "")
                self._open()
                if imgui.tree_node_ex(label, imgui.TreeNodeFlags_.default_open):
                    if self._light(lt, scene):
                        res.changed = True
                    imgui.tree_pop()
                imgui.pop_id()
            c, v = _color("ambient", scene.ambient)
            if c:
                scene.ambient, res.changed = v, True

        self._open()

        if imgui.collapsing_header("Sky"):
            s = scene.sky
            types = ["color", "gradient"] + (["image"] if s.image_path is not None else [])
            idx = types.index(s.type) if s.type in types else 0
            c, idx = imgui.combo("type", idx, types)
            if c and types[idx] != s.type:
                s.type, res.changed = types[idx], True
            if s.type == "color":
                c, v = _color("color", s.color)
                if c:
                    s.color, res.changed = v, True
            elif s.type == "gradient":
                c, v = _color("horizon", s.horizon)
                if c:
                    s.horizon, res.changed = v, True
                c, v = _color("zenith", s.zenith)
                if c:
                    s.zenith, res.changed = v, True
            else:
                imgui.text_wrapped(f"image: {s.image}")

        self._open()

        if imgui.collapsing_header("Materials", imgui.TreeNodeFlags_.default_open):
            for name, m in scene.materials.items():
                imgui.push_id(f"mat-{name}")
                self._open()
                if imgui.tree_node(name):
                    if self._material(m):
                        res.changed = True
                    imgui.tree_pop()
                imgui.pop_id()

    def _light(self, lt: Light, scene: Scene) -> bool:
        changed = False
        types = ["point", "directional"]
        c, idx = imgui.combo("type", types.index(lt.type), types)
        if c and types[idx] != lt.type:
            changed = True
            if types[idx] == "directional":
                if lt.direction is None:
                    p = lt.position or (0.0, 1.0, 0.0)
                    t = scene.camera.target
                    d = tuple(t[k] - p[k] for k in range(3))
                    lt.direction = d if any(abs(x) > 0 for x in d) else (0.0, -1.0, 0.0)
                lt.type, lt.position = "directional", None
            else:
                if lt.position is None:
                    d = lt.direction or (0.0, -1.0, 0.0)
                    t = scene.camera.target
                    lt.position = tuple(t[k] - 5.0 * d[k] for k in range(3))
                lt.type, lt.direction = "point", None
        if lt.type == "point":
            c, v = _vec3("position", lt.position, 0.02)
            if c:
                lt.position, changed = v, True
        else:
            c, v = _vec3("direction", lt.direction, 0.01)
            if c and any(x != 0.0 for x in v):
                lt.direction, changed = v, True
        c, v = _color("color", lt.color)
        if c:
            lt.color, changed = v, True
        c, v = _float("intensity", lt.intensity, 0.01, 0.0, _BIG)
        if c:
            lt.intensity, changed = v, True
        return changed

    def _material(self, m) -> bool:
        changed = False
        c, v = _color("color", m.color)
        if c:
            m.color, changed = v, True
        for key, speed, lo, hi in (("ambient", 0.005, 0.0, _BIG), ("diffuse", 0.005, 0.0, _BIG),
                                   ("specular", 0.005, 0.0, _BIG), ("shininess", 0.5, 1.0, _BIG)):
            c, v = _float(key, getattr(m, key), speed, lo, hi)
            if c:
                setattr(m, key, v)
                changed = True
        dielectric = m.transparency > 0
        imgui.begin_disabled(dielectric)
        c, v = _float("reflectivity", m.reflectivity, 0.005, 0.0, 1.0)
        imgui.end_disabled()
        if c and not dielectric:
            m.reflectivity, changed = v, True
        c, v = _float("transparency", m.transparency, 0.005, 0.0, 1.0)
        if c:
            m.transparency, changed = v, True
            if v > 0 and m.reflectivity > 0:
                m.reflectivity = 0.0  # a dielectric's reflection is Fresnel's (scene format)
        c, v = _float("ior", m.ior, 0.002, 1.0, 10.0)
        if c:
            m.ior, changed = v, True
        c, v = _vec3("absorption", m.absorption, 0.005, 0.0, _BIG)
        if c:
            m.absorption, changed = v, True
        c, v = _color("emission", m.emission)
        if c:
            m.emission, changed = v, True
        if m.checker is not None:
            c, v = _color("checker color", m.checker.color)
            if c:
                m.checker.color, changed = v, True
            c, v = _float("checker size", m.checker.size, 0.005, 1e-4, _BIG)
            if c:
                m.checker.size, changed = v, True
        return changed

    # ------------------------------------------------------------ saving

    def save(self, scene: Scene) -> bool:
        path = Path(self.save_path.strip() or "scene.toml")
        if self.user_render is not None:
            scene = copy.deepcopy(scene)
            r = scene.render
            r.samples, r.max_depth, r.min_weight = self.user_render
        try:
            save_scene(scene, path)
        except (OSError, ValueError) as e:
            self.status = f"could not save {path}: {getattr(e, 'strerror', None) or e}"
            import sys

            print(f"glassray: {self.status}", file=sys.stderr)
            return False
        self.status = f"saved {path}"
        print(f"saved scene {path.resolve()}", flush=True)
        return True


def _camera_ok(pos, tgt) -> bool:
    from .scene import Camera, SceneError, validate_camera

    try:
        validate_camera(Camera(tuple(pos), tuple(tgt)))
    except SceneError:
        return False
    return True


# ------------------------------------------------------------ HUD and help


def draw_hud(lines: list[str], message: str = "") -> None:
    flags = (imgui.WindowFlags_.no_decoration | imgui.WindowFlags_.always_auto_resize
             | imgui.WindowFlags_.no_saved_settings | imgui.WindowFlags_.no_focus_on_appearing
             | imgui.WindowFlags_.no_nav | imgui.WindowFlags_.no_inputs | imgui.WindowFlags_.no_move)
    imgui.set_next_window_pos(imgui.ImVec2(6.0, 6.0), imgui.Cond_.always)
    imgui.set_next_window_bg_alpha(0.55)
    imgui.begin("##hud", None, flags)
    for line in lines:
        imgui.text(_plain(line))  # "max error ...: measuring…" showed "measuring?"
    if message:
        imgui.text_colored(imgui.ImVec4(1.0, 0.8, 0.3, 1.0), _plain(message))
    imgui.end()


def _plain(text: str) -> str:
    return text.replace("`", "").replace("\u2026", "...")  # the default font has no ellipsis


_help_drawn_size: tuple[int, int] | None = None  # the window size the help was last drawn for
help_rect = (0.0, 0.0, 0.0, 0.0)  # where the help window is: x0, y0, x1, y1 (tests)


def draw_help(size: tuple[int, int]) -> bool:
    """The help overlay; returns False when its close button was pressed."""
    global _help_drawn_size, help_rect
    w, h = size
    # centred when it opens, and again when the window's size changed (as
    # the panel: left where it was, it could end up outside a smaller window)
    cond = imgui.Cond_.always if (w, h) != _help_drawn_size else imgui.Cond_.appearing
    _help_drawn_size = (w, h)
    imgui.set_next_window_pos(imgui.ImVec2(w * 0.5, h * 0.5), cond, imgui.ImVec2(0.5, 0.5))
    imgui.set_next_window_size_constraints(imgui.ImVec2(100.0, 60.0), imgui.ImVec2(max(200.0, w - 20.0),
                                                                                   max(100.0, h - 20.0)))
    flags = imgui.WindowFlags_.no_saved_settings | imgui.WindowFlags_.no_collapse | \
        imgui.WindowFlags_.always_auto_resize
    visible, keep_open = imgui.begin("Controls (H / F1 to close)", True, flags)
    pos, wsize = imgui.get_window_pos(), imgui.get_window_size()
    help_rect = (pos.x, pos.y, pos.x + wsize.x, pos.y + wsize.y)
    if visible:
        key_w = max(imgui.calc_text_size(k).x for k, _ in HELP)
        wrap = min(520.0, w - key_w - 60.0)
        if wrap >= 160.0:  # a table: input | effect
            if imgui.begin_table("controls", 2, imgui.TableFlags_.borders | imgui.TableFlags_.sizing_fixed_fit):
                imgui.table_setup_column("input")
                imgui.table_setup_column("effect", imgui.TableColumnFlags_.width_fixed, wrap)
                imgui.table_headers_row()
                for key, what in HELP:
                    imgui.table_next_row()
                    imgui.table_next_column()
                    imgui.text(key)
                    imgui.table_next_column()
                    imgui.text_wrapped(_plain(what))
                imgui.end_table()
        else:  # a narrow window: each input above its effect
            # the wrap position is window-local: the window is at most
            # w - 20 wide, less its padding and the scrollbar at the right
            imgui.push_text_wrap_pos(max(100.0, w - 56.0))
            for key, what in HELP:
                imgui.text_colored(imgui.ImVec4(1.0, 0.85, 0.4, 1.0), key)
                imgui.indent(12.0)                  # every wrapped line of the effect, not just its first
                imgui.text_wrapped(_plain(what))
                imgui.unindent(12.0)
            imgui.pop_text_wrap_pos()
    imgui.end()
    return bool(keep_open) if keep_open is not None else True
