"""The stress suite's report: the table of the cases (plain or Markdown) and
the contact sheet (GPU | reference | error heat map per case; PIL,
imported when drawn).
"""

from __future__ import annotations

import math

import numpy as np

from ..base.views import heat
from .stress_suite import CaseResult, level_diff

# ---------------------------------------------------------------- table and contact sheet


HEADER = ("case", "size", "max", "mean", ">1/255", ">0.05", "masked", "NaN/Inf", "acne", "ms", "result")


def table_rows(results: list[CaseResult]) -> list[tuple[str, ...]]:
    rows = []
    for r in results:
        verdict = "ok" if r.ok else "FAIL"
        extra = "; ".join(c.text() for c in r.checks)
        rows.append((r.name, f"{r.size[0]}x{r.size[1]}", f"{r.max_err:.0f}", f"{r.mean_err:.3f}",
                     f"{100 * r.off1:.2f}%", f"{100 * r.off05:.2f}%", f"{100 * r.masked:.1f}%", str(r.nonfinite),
                     f"{100 * r.acne:.2f}%", f"{r.ms:.0f}", verdict + (f" ({extra})" if extra else "")))
    return rows


def format_table(results: list[CaseResult], markdown: bool = False) -> str:
    rows = [HEADER] + table_rows(results)
    if markdown:
        lines = ["| " + " | ".join(rows[0]) + " |", "|" + "---|" * len(HEADER)]
        lines += ["| " + " | ".join(r) + " |" for r in rows[1:]]
        return "\n".join(lines)
    widths = [max(len(r[i]) for r in rows) for i in range(len(HEADER) - 1)]
    out = []
    for r in rows:
        cells = [r[i].ljust(widths[i]) if i == 0 else r[i].rjust(widths[i]) for i in range(len(HEADER) - 1)]
        out.append("  ".join(cells + [r[-1]]))
    return "\n".join(out)


def error_heat(g8: np.ndarray, r8: np.ndarray, mask: np.ndarray) -> np.ndarray:
    """(H, W, 3) uint8: log heat of the largest channel difference (0 levels
    black, 1 level dim, 255 levels yellow); masked pixels in grey."""
    d = level_diff(g8, r8).astype(np.float64)
    x = np.log2(1.0 + d) / 8.0
    img = heat(x)
    grey = np.repeat(np.clip(0.15 + 0.6 * x, 0, 1)[..., None], 3, axis=2)
    img = np.where((mask & (d > 1))[..., None], grey, img)
    return np.round(255 * img).astype(np.uint8)


def contact_sheet(results: list[CaseResult], columns: int = 3, scale: int | None = None):
    """A PIL image: per case a cell with its name and verdict above
    GPU | reference | error heat map (log scale; grey = masked pixels)."""
    from PIL import Image, ImageDraw

    shown = [r for r in results if r.gpu8 is not None]
    if not shown:
        return Image.new("RGB", (1, 1))
    wmax = max(r.size[0] for r in shown)
    hmax = max(r.size[1] for r in shown)
    k = scale or max(1, math.ceil(128 / wmax))
    gap, label_h, pad = 3, 24, 10
    cell_w = 3 * wmax * k + 2 * gap
    cell_h = label_h + hmax * k
    columns = max(1, min(columns, len(shown)))
    rows = math.ceil(len(shown) / columns)
    title_h = 18
    sheet = Image.new("RGB", (columns * cell_w + (columns + 1) * pad, title_h + rows * (cell_h + pad) + pad),
                      (24, 24, 28))
    draw = ImageDraw.Draw(sheet)
    draw.text((pad, 4), "glassray stress: GPU (float32) | reference (float64) | |difference| "
                        "(log heat: dark blue = equal, yellow = 255 levels; grey = masked straddling pixels)", fill=(230, 230, 230))
    for i, r in enumerate(shown):
        x0 = pad + (i % columns) * (cell_w + pad)
        y0 = title_h + pad + (i // columns) * (cell_h + pad)
        colour = (150, 230, 150) if r.ok else (255, 110, 110)
        draw.text((x0, y0), f"{r.name}  {'ok' if r.ok else 'FAIL'}", fill=colour)
        draw.text((x0, y0 + 11), f">1/255 {100 * r.off1:.2f}%  masked {100 * r.masked:.0f}%  "
                                 f"NaN {r.nonfinite}", fill=(190, 190, 190))
        tiles = [r.gpu8, r.ref8, error_heat(r.gpu8, r.ref8, r.mask)]
        for j, t in enumerate(tiles):
            im = Image.fromarray(np.ascontiguousarray(t)).resize((t.shape[1] * k, t.shape[0] * k), Image.NEAREST)
            sheet.paste(im, (x0 + j * (wmax * k + gap), y0 + label_h))
    return sheet
