"""The HUD's layout at every window size: its lines whole (wrapped, never
cut at an edge), clear of the settings panel, and, in a window too small for
all of them, the least needed left out first.  Drawn headlessly (an ImGui
context without a window), the way the viewer draws them (window/app.py,
_ui_new_frame and _draw_overlays)."""

from __future__ import annotations

import pytest

from viewer.window.hud import ALWAYS, DEPTH, HINT, NOTE, RESOLUTION, STATUS, lines_that_fit

imgui = pytest.importorskip("imgui_bundle").imgui

from viewer.scene.load import load_scene  # noqa: E402


# ------------------------------------------------------------ which lines fit (no ImGui)

def test_all_lines_when_they_fit():
    assert lines_that_fit([0, 1, 0, 2, 3], [17] * 5, room=5 * 17 + 4 * 4, gap=4) == [True] * 5


def test_the_highest_rank_goes_first_then_the_next():
    ranks = [STATUS, RESOLUTION, STATUS, DEPTH, HINT]
    # room for four lines of 10 with gaps of 2: 4*10 + 3*2 = 46
    assert lines_that_fit(ranks, [10] * 5, room=46, gap=2) == [True, True, True, True, False]
    # for three: the hint and the depth go, the resolution stays
    assert lines_that_fit(ranks, [10] * 5, room=34, gap=2) == [True, True, True, False, False]
    assert lines_that_fit(ranks, [10] * 5, room=22, gap=2) == [True, False, True, False, False]
    # for one: the later of the two STATUS lines goes before the earlier
    assert lines_that_fit(ranks, [10] * 5, room=10, gap=2) == [True, False, False, False, False]


def test_a_wrapped_line_counts_with_its_height():
    # the depth line is short, the hint wraps onto two lines: leaving out
    # the hint alone makes room
    assert lines_that_fit([0, 2, 3], [10, 10, 22], room=24, gap=2) == [True, True, False]


def test_the_message_stays_even_when_it_does_not_fit():
    assert lines_that_fit([NOTE, HINT, ALWAYS], [10, 10, 30], room=5, gap=2) == [False, False, True]


def test_among_equal_ranks_the_last_goes_first():
    assert lines_that_fit([1, 1, 1], [10] * 3, room=22, gap=2) == [True, True, False]


# ------------------------------------------------------------ drawn, at every size


@pytest.fixture
def ui():
    imgui.create_context()
    io = imgui.get_io()
    io.set_ini_filename(None)
    io.delta_time = 1 / 60
    io.backend_flags |= imgui.BackendFlags_.renderer_has_textures
    yield io
    imgui.destroy_context()


LINES = [("idle (last frame 40.5 ms)", STATUS), ("1280x720", RESOLUTION), ("samples 64/64", STATUS),
         ("max depth 8", DEPTH), ("selected 4: ball (sphere)", NOTE), ("Tab: settings  H: help", HINT)]
MESSAGE = "screenshot not saved in /root/a/folder/that/is/long: Permission denied"
SIZES = [(160, 90), (200, 120), (320, 180), (480, 270), (640, 360), (1280, 720), (2560, 400)]


def draw(io, size, panel, monkeypatch):
    """One frame as the viewer draws it; the texts the HUD gave ImGui."""
    from viewer.window import overlays

    shown: list[str] = []
    real = overlays.imgui.text_wrapped
    monkeypatch.setattr(overlays.imgui, "text_wrapped", lambda s: (shown.append(s), real(s)))
    io.display_size = imgui.ImVec2(*size)
    imgui.new_frame()
    inside = panel is not None and panel.hud_inside(size)
    if panel is not None:
        panel.hud = (LINES, MESSAGE, "error") if inside else None
        panel.draw(load_scene("default"), size)
    if not inside:
        overlays.draw_hud(LINES, MESSAGE, "error", right=panel.left_edge(size) if panel else size[0])
    imgui.render()
    monkeypatch.undo()
    return inside, shown


@pytest.mark.parametrize("with_panel", [False, True])
@pytest.mark.parametrize("size", SIZES)
def test_the_hud_is_whole_and_clear_of_the_panel(ui, size, with_panel, monkeypatch):
    from viewer.window import overlays
    from viewer.window.panel import Panel

    panel = Panel(load_scene("default")) if with_panel else None
    for _ in range(3):                       # auto-sized windows settle in a frame or two
        inside, shown = draw(ui, size, panel, monkeypatch)
    w, h = size
    # the message is there, whole, whatever the size
    assert MESSAGE in shown, shown
    if inside:
        # no room beside the panel: the panel shows the lines, there is no box over it
        assert with_panel and panel.left_edge(size) < overlays.HUD_MIN_WIDTH
        return
    x0, y0, x1, y1 = overlays.hud_rect
    right = panel.rect[0] if panel else w
    # inside the window and clear of the panel, margins kept: no line cut
    # at an edge (what does not fit is left out whole, not cut)
    assert overlays.HUD_MARGIN <= x0 and x1 <= right - overlays.HUD_MARGIN + 0.5, (size, overlays.hud_rect, right)
    assert overlays.HUD_MARGIN <= y0 and y1 <= h - overlays.HUD_MARGIN + 0.5, (size, overlays.hud_rect)
    # (the box is held inside the window: what it shows must fit in it too)
    style = imgui.get_style()
    wrap = right - 2 * overlays.HUD_MARGIN - 2 * style.window_padding.x
    need = sum(imgui.calc_text_size(t, wrap_width=wrap).y for t in shown) + style.item_spacing.y * (len(shown) - 1)
    assert need <= y1 - y0 - 2 * style.window_padding.y + 0.5 or shown == [MESSAGE], (size, shown, need)
    # a big window shows every line; a small one leaves out by rank: no
    # line shown ranks above one left out, or equal to it and later
    if w >= 640 and h >= 360:
        assert len(shown) == len(LINES) + 1
    order = [(r, i) for i, (t, r) in enumerate(LINES)]
    left_out = [o for o, (t, _) in zip(order, LINES) if t not in shown]
    kept = [o for o, (t, _) in zip(order, LINES) if t in shown]
    assert all((k[0], k[1]) < (o[0], o[1]) for k in kept for o in left_out), (size, shown)


def test_the_lines_wrap_at_the_room_beside_the_panel(ui, monkeypatch):
    """A 640-wide window with the panel open leaves the HUD about 340 px:
    the long message wraps there (the box is taller than one line per text)
    instead of running under the panel."""
    from viewer.window import overlays
    from viewer.window.panel import Panel

    panel = Panel(load_scene("default"))
    for _ in range(3):
        draw(ui, (640, 720), panel, monkeypatch)
    x0, y0, x1, y1 = overlays.hud_rect
    assert x1 <= panel.rect[0] - overlays.HUD_MARGIN + 0.5
    one_line_each = (len(LINES) + 1) * imgui.get_text_line_height_with_spacing()
    assert y1 - y0 > one_line_each + imgui.get_text_line_height(), overlays.hud_rect


# ------------------------------------------------------------ messages: how long they stay


@pytest.fixture
def viewer(monkeypatch):
    """A Viewer with only what say and message_read use, and a clock of our own."""
    pytest.importorskip("glfw")
    from viewer.window import app

    clock = [100.0]
    monkeypatch.setattr(app.time, "perf_counter", lambda: clock[0])
    v = object.__new__(app.Viewer)
    v.message, v.message_until, v.message_kind, v.message_t0, v.needs_display = "", 0.0, "info", 0.0, False
    return v, clock, app


def shown_message(v, clock) -> str:
    return v.message if clock[0] < v.message_until else ""


def test_a_message_of_what_was_done_stays_its_time_whatever_is_pressed(viewer):
    v, clock, app = viewer
    v.say("saved glassray-1.png")
    clock[0] += app.MESSAGE_S - 0.1
    v.message_read()                               # a key pressed: not taken away
    assert shown_message(v, clock) == "saved glassray-1.png" and v.message_kind == "info"
    clock[0] += 0.2
    assert shown_message(v, clock) == ""


def test_an_error_stays_until_read(viewer, capsys):
    v, clock, app = viewer
    v.say("screenshot not saved in /x: Permission denied", error=True)
    assert "screenshot not saved" in capsys.readouterr().err
    clock[0] += 3600.0                             # an hour, nothing pressed: still there
    assert shown_message(v, clock).startswith("screenshot not saved") and v.message_kind == "error"
    v.message_read()                               # the next key or click takes it away
    assert shown_message(v, clock) == ""


def test_the_key_that_caused_an_error_does_not_take_it_away(viewer):
    v, clock, app = viewer
    v.say("cannot open nowhere.toml: no such file", keep=True)
    clock[0] += app.READ_S / 2                     # held, auto-repeated: too soon to have been read
    v.message_read()
    assert shown_message(v, clock) != ""
    clock[0] += app.READ_S
    v.message_read()
    assert shown_message(v, clock) == ""
