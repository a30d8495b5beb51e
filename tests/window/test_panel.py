"""The settings panel's widgets, drawn headlessly (an ImGui context with no
window): every section of every built-in scene draws, and "Save scene"
writes TOML that loads back to the same scene."""

from __future__ import annotations

import pytest

imgui = pytest.importorskip("imgui_bundle").imgui

from viewer.scene.load import builtin_scene_names, load_scene  # noqa: E402


@pytest.fixture
def ui():
    imgui.create_context()
    io = imgui.get_io()
    io.set_ini_filename(None)
    io.display_size = imgui.ImVec2(1280, 720)
    io.delta_time = 1 / 60
    io.backend_flags |= imgui.BackendFlags_.renderer_has_textures
    yield io
    imgui.destroy_context()


@pytest.mark.parametrize("name", builtin_scene_names())
def test_every_section_draws_without_changing_the_scene(ui, name):
    import copy

    from viewer.window.overlays import draw_help, draw_hud
    from viewer.window.panel import Panel

    scene = load_scene(name)
    before = copy.deepcopy(scene)
    panel = Panel(scene)
    panel.open_all = True
    panel.error = "a shader error\nsecond line"
    for size in ((1280, 720), (320, 180)):
        for _ in range(3):
            imgui.new_frame()
            res = panel.draw(scene, size)
            draw_hud(["1.0 ms  60 fps", "320x180"], "a message")
            draw_help(size)
            imgui.render()
            assert not (res.changed or res.camera_changed or res.target_ms_changed)
    assert scene == before


@pytest.mark.parametrize("view", ["image", "cost", "depth"])
@pytest.mark.parametrize("max_error_on", [False, True])
def test_view_combo_and_max_error_draw(ui, view, max_error_on):
    """The view combo (V) and the "max error" setting: drawn in every state
    (measuring, a pick) without touching the scene or raising a flag."""
    import copy

    from viewer.window.controls import VIEWS
    from viewer.window.panel import Panel

    scene = load_scene("default")
    before = copy.deepcopy(scene)
    panel = Panel(scene)
    assert panel.view == "image" and panel.max_error_on is False and panel.max_error > 0  # off by default
    panel.view, panel.max_error_on = view, max_error_on
    for status in ("max error 0.02: measuring\u2026 37%", "max error 0.02: 8 spp, depth 6, w 0.001 (RMSE 0.0099)"):
        panel.quality_status = status
        for _ in range(3):
            imgui.new_frame()
            res = panel.draw(scene, (1280, 720))
            imgui.render()
            assert not (res.changed or res.view_changed or res.quality_changed or res.remeasure)
    assert panel.view in VIEWS and panel.view == view
    assert scene == before


def test_view_combo_picks_a_view_with_the_mouse(ui):
    """Clicking the combo, then its second entry, selects "cost" (the mouse
    driven through ImGui's input events)."""
    from viewer.window.panel import Panel

    scene = load_scene("default")
    panel = Panel(scene)
    io = imgui.get_io()
    picked = []

    def frame(pos=None, down=False):
        if pos is not None:
            io.add_mouse_pos_event(*pos)
        io.add_mouse_button_event(0, down)
        imgui.new_frame()
        res = panel.draw(scene, (1280, 720))
        imgui.render()
        if res.view_changed:
            picked.append(panel.view)

    for _ in range(3):
        frame()
    x0, y0, x1, y1 = panel.view_rect
    centre = ((x0 + x1) / 2, (y0 + y1) / 2)
    frame(centre, True)
    frame(centre, False)  # the popup opens below the combo: one row per view
    row = y1 - y0
    entry = (centre[0], y1 + 1.5 * row)  # the second entry
    for _ in range(2):
        frame(entry, False)
    frame(entry, True)
    frame(entry, False)
    assert picked == ["cost"] and panel.view == "cost"


def test_save_scene_writes_toml_that_loads_to_the_same_scene(tmp_path):
    from viewer.window.panel import Panel

    scene = load_scene("default")
    scene.materials["water"].absorption = (0.25, 0.125, 0.0625)
    scene.lights[0].position = (1.5, 7.25, -2.0)
    scene.render.max_depth = 5
    panel = Panel(scene)
    assert panel.save_path == "default.toml"  # a built-in scene is saved in the current folder
    panel.save_path = str(tmp_path / "saved.toml")
    assert panel.save(scene)
    back = load_scene(tmp_path / "saved.toml")
    back.path = scene.path = None
    assert back == scene
    assert "saved" in panel.status
    # a scene file of the user's is saved in place by default
    assert Panel(load_scene(tmp_path / "saved.toml")).save_path == str(tmp_path / "saved.toml")


def test_save_while_max_error_is_on_writes_the_users_render_settings(tmp_path):
    """The "max error" pick replaces samples, max depth and min weight with
    values measured for this machine and window; a saved scene keeps the
    user's own (restored when the box is switched off), not the pick."""
    from viewer.window.panel import Panel

    scene = load_scene("default")
    user = (scene.render.samples, scene.render.max_depth, scene.render.min_weight)
    panel = Panel(scene)
    panel.user_render = user                                   # as the app sets it with the pick
    scene.render.samples, scene.render.max_depth, scene.render.min_weight = 3, 12, 1e-4
    panel.save_path = str(tmp_path / "picked.toml")
    assert panel.save(scene)
    back = load_scene(tmp_path / "picked.toml")
    assert (back.render.samples, back.render.max_depth, back.render.min_weight) == user
    assert (scene.render.samples, scene.render.max_depth) == (3, 12)   # the window keeps the pick
    panel.user_render = None                                   # max error off: what is shown is the user's
    assert panel.save(scene)
    assert load_scene(tmp_path / "picked.toml").render.max_depth == 12


def test_save_failure_is_reported_not_raised(tmp_path):
    from viewer.window.panel import Panel

    panel = Panel(load_scene("default"))
    panel.save_path = str(tmp_path / "missing" / "s.toml")
    assert not panel.save(load_scene("default"))
    assert "could not save" in panel.status


def test_the_panel_stays_in_a_window_made_smaller(ui):
    """The panel was placed once (at the right edge of the window it was
    first shown in) and then left there: after the window was made smaller
    it lay outside it, and one squeezed through a tiny window ended up above
    and left of it, title bar and all (it could not be dragged back)."""
    from viewer.window.panel import Panel

    scene = load_scene("default")
    panel = Panel(scene)
    for size in ((1280, 720), (400, 300), (1, 1), (640, 400)):
        ui.display_size = imgui.ImVec2(*size)
        for _ in range(3):
            imgui.new_frame()
            panel.draw(scene, size)
            imgui.render()
        if size == (1, 1):
            continue
        x0, y0, x1, y1 = panel.rect
        w, h = size
        assert 0 <= x0 < x1 <= w and 0 <= y0 < y1 <= h, (size, panel.rect)
        assert x1 > w - 20  # still at the right edge


def test_the_hud_shows_no_glyph_the_font_lacks(ui, monkeypatch):
    """The HUD line of "max error" ("measuring…") showed a "?" for the
    ellipsis, which the default font does not have (the panel and the help
    already wrote it as "...")."""
    from viewer.window import overlays as ui_module

    shown = []
    monkeypatch.setattr(ui_module.imgui, "text_wrapped", lambda s: shown.append(s))
    imgui.new_frame()
    ui_module.draw_hud(["12.0 ms  80 fps", "max error 0.02: measuring\u2026 37%"], "max error: measuring\u2026")
    imgui.render()
    assert len(shown) == 3 and "measuring... 37%" in shown[1]
    assert not any("\u2026" in s or not s.isascii() for s in shown), shown


def test_a_long_hud_message_is_wrapped_inside_the_window(ui):
    # a failed F5's message was one line cut at the window's edge: at 320 px
    # only "reload failed, keeping the last good scene:" could be read
    from viewer.window import overlays as ui_module

    message = ("reload failed, keeping the last good scene: /tmp/scene.toml: objects[0].radius: "
               "expected a number > 0, got -1")
    heights = {}
    for w, h in ((320, 180), (2000, 600)):
        ui.display_size = imgui.ImVec2(w, h)
        for _ in range(3):
            imgui.new_frame()
            ui_module.draw_hud(["1.0 ms  60 fps", f"{w}x{h}"], message)
            imgui.render()
        x0, y0, x1, y1 = ui_module.hud_rect
        assert 0 <= x0 < x1 <= w - ui_module.HUD_MARGIN + 1, (w, ui_module.hud_rect)
        heights[w] = y1 - y0
    # all of it is there: one line at 2000 px, three at 320 (the window's
    # 308 px hold about 44 characters of its 122)
    assert heights[320] >= heights[2000] + 2 * imgui.get_text_line_height(), heights


def test_the_help_stays_in_a_window_resized_while_it_is_open(ui):
    """The help was centred only when it opened: a window made smaller
    while it was open left it partly outside."""
    from viewer.window import overlays as ui_module

    for size in ((1280, 720), (640, 400), (400, 300)):
        ui.display_size = imgui.ImVec2(*size)
        for _ in range(3):
            imgui.new_frame()
            ui_module.draw_help(size)
            imgui.render()
        x0, y0, x1, y1 = ui_module.help_rect
        w, h = size
        assert 0 <= x0 < x1 <= w and 0 <= y0 < y1 <= h, (size, ui_module.help_rect)


def test_the_add_buttons_stay_inside_a_narrow_panel(ui, monkeypatch):
    # side by side, "add plane" was cut off at the panel's edge in a 640 px window
    from viewer.window import panel as ui_module
    from viewer.window.panel import Panel

    real = imgui.small_button
    seen = {}

    def small_button(label):
        clicked = real(label)
        if label.startswith("add "):
            seen[label] = (imgui.get_item_rect_min().x, imgui.get_item_rect_max().x,
                           imgui.get_window_pos().x + imgui.get_window_size().x)
        return clicked

    monkeypatch.setattr(ui_module.imgui, "small_button", small_button)
    scene = load_scene("default")
    panel = Panel(scene)
    panel.open_all = True
    for w, h in ((640, 480), (1280, 720)):
        ui.display_size = imgui.ImVec2(w, h)
        seen.clear()
        for _ in range(3):
            imgui.new_frame()
            panel.draw(scene, (w, h))
            imgui.render()
        assert {"add sphere", "add plane", "add point light", "add directional light"} <= set(seen)
        for label, (x0, x1, right) in seen.items():
            assert x1 <= right, (w, label, x1, right)
