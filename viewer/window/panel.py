"""The viewer's settings panel, in Dear ImGui (imgui-bundle); the HUD and
the help overlay are window/overlays.py's.  Widgets only: the window module
owns GLFW and the ImGui backends and calls these between
``imgui.new_frame()`` and ``imgui.render()``.

The panel edits the scene in place and returns True when it changed
something that alters the picture.  Every value is kept inside the range the
scene format allows, so an edited scene is always a valid one (and "Save
scene" writes a file that loads back to it).
"""

from __future__ import annotations

import copy
import math
import sys
from dataclasses import dataclass
from importlib import resources
from pathlib import Path

import numpy as np
from imgui_bundle import imgui

from .controls import VIEWS, first_point_light
from .overlays import HUD_MIN_WIDTH, hud_body, plain
from ..scene.model import (MAX_LIGHTS, MAX_OBJECTS, MAX_TRANSPARENT_OBJECTS, Camera, Checker, Light, Material, Scene,
                           SceneError, SceneObject)
from ..scene.save import as_the_file_had, save_scene
from ..scene.load import scene_from_dict, validate_camera

_CLAMP = imgui.SliderFlags_.always_clamp
_HDR = imgui.ColorEditFlags_.hdr | imgui.ColorEditFlags_.float
_BIG = 1e6
_SHAPES = ("sphere", "box", "cylinder", "plane")


def _from_widget(x: float, old: float, lo: float = -math.inf, hi: float = math.inf) -> float:
    """A value as an ImGui widget gave it back (a float32) turned into the
    scene's: the old value where the widget left it as it was (ImGui holds
    floats as float32: 3.2 came back 3.200000047683716, and "Save scene"
    wrote that for values nobody touched), else the shortest decimal of the
    float32 (0.002, not 0.0020000000949949026), inside [lo, hi]; a
    non-finite one (typed "nan") is the old value."""
    x = float(x)
    if not math.isfinite(x):
        return float(old)
    if np.float32(x) == np.float32(old):
        return float(old)
    return min(max(float(str(np.float32(x))), lo), hi)


def _color(label: str, value) -> tuple[bool, tuple[float, float, float]]:
    changed, col = imgui.color_edit3(label, [float(v) for v in value], _HDR)
    col = tuple(max(0.0, _from_widget(c, o, 0.0)) if math.isfinite(c) else float(o) for c, o in zip(col, value))
    return changed and col != tuple(value), col  # type: ignore[return-value]


def _vec3(label: str, value, speed: float = 0.01, lo: float = -_BIG, hi: float = _BIG):
    changed, v = imgui.drag_float3(label, [float(x) for x in value], speed, lo, hi, "%.3f", _CLAMP)
    v = tuple(_from_widget(x, o, lo, hi) for x, o in zip(v, value))
    return changed and v != tuple(value), v


def _float(label: str, value: float, speed: float, lo: float, hi: float, fmt: str = "%.3f", flags: int = 0):
    changed, v = imgui.drag_float(label, float(value), speed, lo, hi, fmt, _CLAMP | flags)
    v = _from_widget(v, value, lo, hi)
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
    open_path: str | None = None  # "Open" pressed: the scene file or built-in name typed


class Panel:
    """The settings panel (Tab)."""

    def __init__(self, scene: Scene, target_ms: float = 33.0):
        self.save_path = self.default_save_path(scene)
        self.open_path = ""  # the "Open" field: a scene file or a built-in scene's name
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
        # the values the command line set ({path: (its value, the file's)},
        # scene.save.overrides_of; the app sets it): saved as the file had them
        self.overrides: dict = {}
        self.adaptive = True  # adaptive accumulation (the app keeps it in step with Progressive)
        self._drawn_size: tuple[float, float] | None = None  # the window size it was last drawn for
        self.edit_note = ""  # why the last edit of objects, lights or materials was refused
        self._reflectivity_kept: dict = {}   # a material's, while it is transparent
        self.sky_image = scene.sky.image or ""  # the sky picture's box
        self.sky_note = ""  # why the picture in that box was refused
        self.rect = (0.0, 0.0, 0.0, 0.0)  # the panel's window: x0, y0, x1, y1
        self.selected: int | None = None  # the selected object (clicked in the view or a node here)
        self._jump = False  # open and scroll to the selection's node and material when next drawn
        # (lines, message, kind): the HUD, shown at the panel's top when the
        # window leaves it no room beside the panel (the app sets it; None: not here)
        self.hud: tuple | None = None

    def _open(self) -> None:
        if self.open_all:
            imgui.set_next_item_open(True, imgui.Cond_.always)

    def select(self, index: int | None) -> None:
        """The selection changed (a click in the view): open its object's
        node and its material, and scroll to the node, when next drawn."""
        self.selected = index
        self._jump = index is not None

    def scene_opened(self, scene: Scene) -> None:
        """Another scene replaced the one shown (opened, or dropped on the
        window): its own save path and sky picture box."""
        self.save_path = self.default_save_path(scene)
        self.sky_image, self.sky_note, self.edit_note = scene.sky.image or "", "", ""
        self.status = f"opened {scene.name}"

    @staticmethod
    def default_save_path(scene: Scene) -> str:
        p = scene.path
        try:
            builtin = Path(str(resources.files("viewer.scene.builtin"))).resolve()
            if p is not None and Path(p).resolve().parent != builtin:
                return str(p)
        except Exception:
            if p is not None:
                return str(p)
        stem = Path(p).stem if p is not None else "scene"
        return f"{stem}.toml"

    # ------------------------------------------------------------ drawing

    @staticmethod
    def _width(w: float) -> float:
        return min(440.0, max(200.0, w * 0.45))

    def left_edge(self, size: tuple[float, float]) -> float:
        """Where the panel's left edge is in a window of `size`: where it was
        drawn, or, not yet drawn at this size, where it will be placed."""
        if self._drawn_size == (float(size[0]), float(size[1])):
            return self.rect[0]
        return size[0] - 8.0 - self._width(size[0])

    def hud_inside(self, size: tuple[float, float]) -> bool:
        """Whether the window leaves too little room beside the panel for
        the HUD (window/overlays.py): then the panel shows it at its top."""
        return self.left_edge(size) < HUD_MIN_WIDTH

    def draw(self, scene: Scene, size: tuple[int, int]) -> PanelResult:
        res = PanelResult()
        w, h = size
        pw = self._width(w)
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
        if self.hud is not None:
            hud_body(*self.hud)
            imgui.separator()
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
        _, self.open_path = imgui.input_text("##openpath", self.open_path)
        imgui.same_line()
        if imgui.button("Open scene") and self.open_path.strip():
            res.open_path = self.open_path.strip()
        if self.status:
            imgui.text_wrapped(self.status)
        if self.edit_note:  # an edit refused (it would make a scene the format rejects)
            imgui.push_text_wrap_pos(0.0)
            imgui.text_colored(imgui.ImVec4(1.0, 0.8, 0.3, 1.0), self.edit_note)
            imgui.pop_text_wrap_pos()
            imgui.same_line()
            if imgui.small_button("ok##note"):
                self.edit_note = ""

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
                    imgui.text_wrapped(plain(self.quality_status))
                if imgui.small_button("measure again"):
                    res.remeasure = True
            imgui.end_disabled()
            imgui.begin_disabled(self.max_error_on)  # the pick sets these
            c, v = imgui.slider_int("max depth", r.max_depth, 1, 64, "%d", _CLAMP)
            v = min(max(int(v), 1), 64)  # (ImGui clamps a typed value too; kept in range here as well)
            if c and v != r.max_depth:
                r.max_depth, res.changed = v, True
            c, v = imgui.drag_int("samples", r.samples, 0.2, 1, 65536, "%d", _CLAMP)
            v = min(max(int(v), 1), 65536)
            if c and v != r.samples:
                r.samples, res.changed = v, True
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
            problem = _camera_problem(pos, tgt) if (c1 or c2) else None
            if problem:
                self.edit_note = f"camera not moved: {problem}"
            elif c1 or c2:
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
            remove = None
            for i, lt in enumerate(scene.lights):
                imgui.push_id(f"light{i}")
                label = f"light {i}" + (" (W/S/A/D/Q/E)" if i == moved else "")
                self._open()
                if imgui.tree_node_ex(label, imgui.TreeNodeFlags_.default_open):
                    if self._light(lt, scene):
                        res.changed = True
                    if imgui.small_button("remove light"):
                        remove = i
                    imgui.tree_pop()
                imgui.pop_id()
            if remove is not None:
                del scene.lights[remove]
                res.changed = True
            imgui.begin_disabled(len(scene.lights) >= MAX_LIGHTS)
            kind = _button_row({"add point light": "point", "add directional light": "directional"})
            if kind is not None:
                scene.lights.append(_new_light(kind, scene))
                res.changed = True
            imgui.end_disabled()
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
            # a picture for the "image" sky: relative to the scene file's folder
            c, self.sky_image = imgui.input_text("##skyimage", self.sky_image)
            imgui.same_line()
            if imgui.small_button("use image"):
                if self._load_sky_image(scene):
                    res.changed = True
            if imgui.is_item_hovered():
                imgui.set_tooltip(f"PNG, JPEG or PFM, relative to {_base_dir(scene)}")
            if self.sky_note:
                imgui.text_wrapped(self.sky_note)

        self._open()

        picked = (scene.objects[self.selected].material
                  if self.selected is not None and self.selected < len(scene.objects) else None)
        if self._jump:
            imgui.set_next_item_open(True, imgui.Cond_.always)
        if imgui.collapsing_header("Materials", imgui.TreeNodeFlags_.default_open):
            for name, m in scene.materials.items():
                imgui.push_id(f"mat-{name}")
                self._open()
                if self._jump and name == picked:
                    imgui.set_next_item_open(True, imgui.Cond_.always)
                if imgui.tree_node_ex(name, imgui.TreeNodeFlags_.selected if name == picked else 0):
                    if self._material(m, name, scene):
                        res.changed = True
                    imgui.tree_pop()
                imgui.pop_id()

        self._open()

        if self._jump:
            imgui.set_next_item_open(True, imgui.Cond_.always)
        if imgui.collapsing_header("Objects"):
            if self._objects(scene):
                res.changed = True


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
            elif c:
                self.edit_note = "direction not taken: a directional light's direction cannot be zero"
        c, v = _color("color", lt.color)
        if c:
            lt.color, changed = v, True
        c, v = _float("intensity", lt.intensity, 0.01, 0.0, _BIG)
        if c:
            lt.intensity, changed = v, True
        return changed

    def _material(self, m: Material, name: str = "", scene: Scene | None = None) -> bool:
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
        if c and v > 0 and not dielectric and scene is not None and _transparent_after(scene, name, True) \
                > MAX_TRANSPARENT_OBJECTS:
            # the shader keeps the media a ray is in as a 32-bit mask: a scene
            # with more transparent objects is refused by the scene format
            self.edit_note = (f"{name} stays opaque: {_transparent_after(scene, name, True)} transparent "
                              f"objects, at most {MAX_TRANSPARENT_OBJECTS} are supported")
        elif c:
            m.transparency, changed = v, True
            if v > 0 and m.reflectivity > 0:
                # a dielectric's reflection is Fresnel's (scene format): said,
                # and given back if the material is made opaque again
                self._reflectivity_kept[name or id(m)] = m.reflectivity
                self.edit_note = (f"{name or 'material'}: reflectivity {m.reflectivity:g} set to 0 while it is "
                                  "transparent (a transparent material reflects by Fresnel's law only)")
                m.reflectivity = 0.0
            elif v == 0 and (name or id(m)) in self._reflectivity_kept:
                m.reflectivity = self._reflectivity_kept.pop(name or id(m))
        c, v = _float("ior", m.ior, 0.002, 1.0, 10.0)
        if c:
            m.ior, changed = v, True
        c, v = _vec3("absorption", m.absorption, 0.005, 0.0, _BIG)
        if c:
            m.absorption, changed = v, True
        c, v = _color("emission", m.emission)
        if c:
            m.emission, changed = v, True
        c, on = imgui.checkbox("checker", m.checker is not None)
        if c and on != (m.checker is not None):
            m.checker = Checker(color=_checker_color(m.color), size=0.5) if on else None
            changed = True
        if m.checker is not None:
            c, v = _color("checker color", m.checker.color)
            if c:
                m.checker.color, changed = v, True
            own = m.checker.emission
            c, v = _color("checker emission", m.emission if own is None else own)
            if c:
                m.checker.emission, changed = v, True
            c, v = _float("checker size", m.checker.size, 0.005, 1e-4, _BIG)
            if c:
                m.checker.size, changed = v, True
        return changed

    # ------------------------------------------------------------ objects

    def _objects(self, scene: Scene) -> bool:
        changed, remove = False, None
        for i, o in enumerate(scene.objects):
            imgui.push_id(f"obj{i}")
            self._open()
            mine = i == self.selected
            if mine and self._jump:
                imgui.set_next_item_open(True, imgui.Cond_.always)
            is_open = imgui.tree_node_ex(f"{i}: {o.name or o.type}" + (f" ({o.type})" if o.name else ""),
                                         imgui.TreeNodeFlags_.selected if mine else 0)
            if imgui.is_item_clicked() and not imgui.is_item_toggled_open():
                self.selected = i      # the node's label clicked: the app selects it
            if mine and self._jump:
                imgui.set_scroll_here_y(0.2)
                self._jump = False
            if is_open:
                if self._object(o, scene):
                    changed = True
                if imgui.small_button("own material"):
                    # a copy of its material for it alone (edit it without
                    # changing the other objects of that material)
                    new = _unique(scene.materials, o.material)
                    scene.materials[new] = copy.deepcopy(scene.materials[o.material])
                    o.material = new
                    changed = True
                imgui.same_line()
                if imgui.small_button("remove object"):
                    remove = i
                imgui.tree_pop()
            imgui.pop_id()
        if remove is not None:
            del scene.objects[remove]
            changed = True
        if not scene.objects:
            imgui.text_disabled("(no objects)")
        imgui.begin_disabled(len(scene.objects) >= MAX_OBJECTS)
        shape = _button_row({f"add {shape}": shape for shape in _SHAPES})
        if shape is not None:
            o = _new_object(shape, scene)
            if scene.is_transparent(o) and _transparent_count(scene) >= MAX_TRANSPARENT_OBJECTS:
                self.edit_note = f"not added: at most {MAX_TRANSPARENT_OBJECTS} transparent objects are supported"
            else:
                scene.objects.append(o)
                changed = True
        imgui.end_disabled()
        return changed

    def _object(self, o: SceneObject, scene: Scene) -> bool:
        changed = False
        names = list(scene.materials)
        c, idx = imgui.combo("material", names.index(o.material) if o.material in names else 0, names)
        if c and names[idx] != o.material:
            new = names[idx]
            if (scene.materials[new].is_dielectric and not scene.is_transparent(o)
                    and _transparent_count(scene) >= MAX_TRANSPARENT_OBJECTS):
                self.edit_note = (f"material {new} not taken: at most {MAX_TRANSPARENT_OBJECTS} "
                                  "transparent objects are supported")
            else:
                o.material, changed = new, True
        if o.type == "plane":
            c, v = _float("height", o.height, 0.01, -_BIG, _BIG)
            if c:
                o.height, changed = v, True
        elif o.type == "sphere":
            c, v = _vec3("center", o.center)
            if c:
                o.center, changed = v, True
            c, v = _float("radius", o.radius, 0.005, 1e-4, _BIG)
            if c:
                o.radius, changed = v, True
        elif o.type == "box":
            # each component of min below max's (scene format): an edit
            # that would cross them stops there
            c1, lo = _vec3("min", o.min)
            c2, hi = _vec3("max", o.max)
            if (c1 or c2) and all(a < b for a, b in zip(lo, hi)):
                o.min, o.max, changed = lo, hi, True
            elif c1 or c2:
                self.edit_note = f"{_what(o)}: not taken: min must stay below max in x, y and z"
            c, v = _vec3("rotate", o.rotate, 0.5)
            if c:
                o.rotate, changed = v, True
        else:
            axes = ["x", "y", "z"]
            c, idx = imgui.combo("axis", axes.index(o.axis), axes)
            if c and axes[idx] != o.axis:
                o.axis, changed = axes[idx], True
            c, v = _vec3("base", o.base)
            if c:
                o.base, changed = v, True
            # 0 < wall < radius and wall < height (scene format)
            wall = o.wall or 0.0
            for key in ("radius", "height"):
                c, v = _float(key, getattr(o, key), 0.005, 1e-4, _BIG)
                if c and v > wall:
                    setattr(o, key, v)
                    changed = True
                elif c:
                    self.edit_note = f"{_what(o)}: {key} not taken: it must stay above the wall ({wall:g})"
            c, on = imgui.checkbox("wall (a vessel)", o.wall is not None)
            if c and on != (o.wall is not None):
                o.wall = _round(0.1 * min(o.radius, o.height)) if on else None
                changed = True
            if o.wall is not None:
                c, v = _float("wall", o.wall, 0.001, 1e-5, _BIG, "%.4f")
                if c and v < o.radius and v < o.height:
                    o.wall, changed = v, True
                elif c:
                    self.edit_note = (f"{_what(o)}: wall not taken: it must stay thinner than the radius "
                                      f"({o.radius:g}) and the height ({o.height:g})")
        return changed

    def _load_sky_image(self, scene: Scene) -> bool:
        """The picture in the box as the sky (validated as a scene file's
        ``sky.image``: relative to the scene file's folder)."""
        text = self.sky_image.strip()
        try:
            sky = scene_from_dict({"sky": {"type": "image", "image": text}}, source="sky", base_dir=_base_dir(scene)).sky
        except SceneError as e:
            self.sky_note = str(e)
            return False
        self.sky_note = ""
        s = scene.sky
        s.type, s.image, s.image_path = "image", sky.image, sky.image_path
        return True

    # ------------------------------------------------------------ saving

    def save(self, scene: Scene) -> bool:
        path = Path(self.save_path.strip() or "scene.toml")
        if self.user_render is not None:
            scene = copy.deepcopy(scene)
            r = scene.render
            r.samples, r.max_depth, r.min_weight = self.user_render
        scene = as_the_file_had(scene, self.overrides)
        try:
            save_scene(scene, path)
        except (OSError, ValueError) as e:
            self.status = f"could not save {path}: {getattr(e, 'strerror', None) or e}"
            print(f"glassray: {self.status}", file=sys.stderr)
            return False
        self.status = f"saved {path}"
        print(f"saved scene {path.resolve()}", flush=True)
        return True


def _round(x: float) -> float:
    return float(f"{x:.4g}")


def _base_dir(scene: Scene) -> Path:
    """The folder a relative sky picture is read from: the scene file's (as
    when it is loaded); for a built-in scene (saved to the current folder)
    the current folder."""
    if scene.path is not None:
        folder = Path(scene.path).resolve().parent
        try:
            if folder != Path(str(resources.files("viewer.scene.builtin"))).resolve():
                return folder
        except Exception:
            return folder
    return Path.cwd()


def _transparent_count(scene: Scene) -> int:
    return sum(scene.is_transparent(o) for o in scene.objects)


def _transparent_after(scene: Scene, name: str, dielectric: bool) -> int:
    """The number of transparent objects once material `name` is (or is not) a dielectric."""
    return sum(dielectric if o.material == name else scene.is_transparent(o) for o in scene.objects)


def _unique(names, base: str) -> str:
    k = 2
    while f"{base}-{k}" in names:
        k += 1
    return f"{base}-{k}"


def _checker_color(color) -> tuple[float, float, float]:
    """The second colour of a new checker: the material's, darker (or lighter when it is dark)."""
    bright = max(color) > 0.3
    return tuple(_round(c * 0.3 if bright else min(1.0, c + 0.5)) for c in color)  # type: ignore[return-value]


def _scale(scene: Scene) -> float:
    """A size for new things: a tenth of the camera's distance to its target."""
    d = math.dist(scene.camera.position, scene.camera.target)
    return _round(max(1e-3, 0.1 * d))


def _new_light(kind: str, scene: Scene) -> Light:
    """A light that lights what the camera looks at: a point light above and
    behind the camera, or a directional one shining the way the camera looks
    and downward."""
    cam = scene.camera
    t, p = cam.target, cam.position
    if kind == "point":
        h = 5.0 * _scale(scene)
        return Light(type="point", position=tuple(_round(p[k] + (h if k == 1 else 0.0)) for k in range(3)))
    f = [t[k] - p[k] for k in range(3)]
    n = math.hypot(*f) or 1.0
    d = (_round(f[0] / n), _round(min(f[1] / n, 0.0) - 1.0), _round(f[2] / n))
    return Light(type="directional", direction=d)


def _new_object(shape: str, scene: Scene) -> SceneObject:
    """A new solid of `shape` at the camera's target, sized to the view, of
    the last object's material (an opaque one where there is one; a new
    material where the scene has none)."""
    if not scene.materials:
        scene.materials["material"] = Material()
    opaque = [o.material for o in scene.objects if not scene.is_transparent(o)]
    mat = opaque[-1] if opaque else next((n for n, m in scene.materials.items() if not m.is_dielectric),
                                         next(iter(scene.materials)))
    t = tuple(_round(x) for x in scene.camera.target)
    r = _scale(scene)
    o = SceneObject(type=shape, material=mat)
    if shape == "sphere":
        o.center, o.radius = t, r
    elif shape == "box":
        o.min = tuple(_round(x - r) for x in t)
        o.max = tuple(_round(x + r) for x in t)
        if not all(a < b for a, b in zip(o.min, o.max)):          # rounded together far from the origin
            o.min, o.max = tuple(x - r for x in t), tuple(x + r for x in t)
    elif shape == "cylinder":
        o.base, o.radius, o.height = t, r, 2 * r
    else:
        o.height = 0.0
    return o


def _button_row(buttons: dict[str, object]):
    """Small buttons side by side, going on to the next line where the next
    would pass the panel's edge ("add plane" was cut off in a 640 px
    window); the value of the one clicked, or None."""
    clicked = None
    style = imgui.get_style()
    for i, (label, value) in enumerate(buttons.items()):
        if i:
            imgui.same_line()
            if imgui.get_content_region_avail().x < imgui.calc_text_size(label).x + 2 * style.frame_padding.x:
                imgui.new_line()
        if imgui.small_button(label):
            clicked = value
    return clicked


def _what(o: SceneObject) -> str:
    return f"{o.type} {o.name}" if o.name else o.type


def _camera_problem(pos, tgt) -> str | None:
    """Why the scene format refuses this camera ("camera.target: must differ
    from camera.position"), or None."""
    try:
        validate_camera(Camera(tuple(pos), tuple(tgt)))
    except SceneError as e:
        return str(e).split(": ", 1)[-1]
    return None
