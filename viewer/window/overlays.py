"""What the window draws over the image with Dear ImGui besides the panel:
the HUD (with the viewer's messages) and the help overlay.  Widgets only,
drawn between ``imgui.new_frame()`` and ``imgui.render()`` by the window
module (window/app.py); which lines the HUD says is the app's, which of them
fit is window/hud.py's.

The HUD's contract: every line it shows is whole.  It lies in the part of
the window the panel leaves free (left of it), its lines wrapped to that
width (a word wider than that is broken, not cut); in a window too low for
all of them it leaves out the least needed (hud.lines_that_fit).  Where the
panel leaves less than HUD_MIN_WIDTH, the panel shows the same lines at its
top instead (Panel.hud).
"""

from __future__ import annotations

from imgui_bundle import imgui

from .controls import HELP_ALL as HELP
from .hud import ALWAYS, NOTE, lines_that_fit

HUD_MARGIN = 6.0        # the HUD's distance from the window's edges and from the panel
HUD_MIN_WIDTH = 150.0   # less room than this beside the panel: the HUD goes into the panel
HUD_COLORS = {"info": (1.0, 0.8, 0.3, 1.0),     # a message that goes after a while
              "error": (1.0, 0.45, 0.35, 1.0)}  # one that stays until read
hud_rect = (0.0, 0.0, 0.0, 0.0)  # where the HUD was last drawn: x0, y0, x1, y1 (tests)


def plain(text: str) -> str:
    """`text` in the glyphs the default font has (it has no ellipsis: "measuring…" showed "measuring?")."""
    return text.replace("`", "").replace("\u2026", "...")


def hud_body(lines, message: str = "", kind: str = "info", room: float | None = None,
             wrap: float | None = None) -> None:
    """The HUD's text in the current ImGui window at its wrap position:
    `lines` (strings, or (string, rank) with hud.py's ranks; a string is a
    NOTE), then the message in the colour of its `kind`, never left out.
    `room`: the height they may take, `wrap` the width they wrap at
    (default: what the window's content region has); lines that do not fit
    are left out by rank."""
    texts = [plain(t) if isinstance(t, str) else plain(t[0]) for t in lines]
    ranks = [NOTE if isinstance(t, str) else t[1] for t in lines]
    message = plain(message)
    shown = [True] * len(texts)
    if room is not None and texts:
        wrap = imgui.get_content_region_avail().x if wrap is None else wrap
        every = texts + ([message] if message else [])
        heights = [imgui.calc_text_size(t, wrap_width=max(1.0, wrap)).y for t in every]
        fit = lines_that_fit(ranks + ([ALWAYS] if message else []), heights, room, imgui.get_style().item_spacing.y)
        shown = fit[:len(texts)]
    for text, show in zip(texts, shown):
        if show:
            imgui.text_wrapped(text)
    if message:
        imgui.push_style_color(imgui.Col_.text, imgui.ImVec4(*HUD_COLORS.get(kind, HUD_COLORS["info"])))
        imgui.text_wrapped(message)
        imgui.pop_style_color()


def draw_hud(lines, message: str = "", kind: str = "info", right: float | None = None) -> None:
    """The HUD in the window's top left: its box ends HUD_MARGIN left of
    `right` (the panel's left edge; the window's right edge without the
    panel) and above the window's bottom."""
    global hud_rect
    io = imgui.get_io()
    right = io.display_size.x if right is None else right
    pad = imgui.get_style().window_padding
    width = max(1.0, right - 2 * HUD_MARGIN)
    height = max(1.0, io.display_size.y - 2 * HUD_MARGIN)
    flags = (imgui.WindowFlags_.no_decoration | imgui.WindowFlags_.always_auto_resize
             | imgui.WindowFlags_.no_saved_settings | imgui.WindowFlags_.no_focus_on_appearing
             | imgui.WindowFlags_.no_nav | imgui.WindowFlags_.no_inputs | imgui.WindowFlags_.no_move)
    imgui.set_next_window_pos(imgui.ImVec2(HUD_MARGIN, HUD_MARGIN), imgui.Cond_.always)
    imgui.set_next_window_size_constraints(imgui.ImVec2(0.0, 0.0), imgui.ImVec2(width, height))
    imgui.set_next_window_bg_alpha(0.55)
    imgui.begin("##hud", None, flags)
    # wrapped at the room the box may have, not at the box's own width
    # (an auto-sized box would be as wide as its longest line)
    imgui.push_text_wrap_pos(width - pad.x)
    hud_body(lines, message, kind, room=height - 2 * pad.y, wrap=width - 2 * pad.x)
    imgui.pop_text_wrap_pos()
    pos, size = imgui.get_window_pos(), imgui.get_window_size()
    hud_rect = (pos.x, pos.y, pos.x + size.x, pos.y + size.y)
    imgui.end()


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
                    imgui.text_wrapped(plain(what))
                imgui.end_table()
        else:  # a narrow window: each input above its effect
            # the wrap position is window-local: the window is at most
            # w - 20 wide, less its padding and the scrollbar at the right
            imgui.push_text_wrap_pos(max(100.0, w - 56.0))
            for key, what in HELP:
                imgui.text_colored(imgui.ImVec4(1.0, 0.85, 0.4, 1.0), key)
                imgui.indent(12.0)                  # every wrapped line of the effect, not just its first
                imgui.text_wrapped(plain(what))
                imgui.unindent(12.0)
            imgui.pop_text_wrap_pos()
    imgui.end()
    return bool(keep_open) if keep_open is not None else True
