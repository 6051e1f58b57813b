"""The dataset card's pictures, drawn with Pillow alone: a bar chart of a histogram and a
contact sheet of frames."""

from __future__ import annotations

import pathlib

import numpy as np

BAR = (66, 133, 244)
INK = (32, 32, 32)


def bar_chart(labels: list[str], values: list[float], title: str, path: pathlib.Path,
              size: tuple[int, int] = (640, 320)) -> pathlib.Path:
    """A PNG bar chart: one bar per label (height ∝ value), the title on top, every label under
    its bar (rotated labels are not drawn: long ones are cut to fit)."""
    from PIL import Image, ImageDraw, ImageFont
    width, height = size
    image = Image.new("RGB", size, "white")
    draw = ImageDraw.Draw(image)
    font = ImageFont.load_default()
    draw.text((10, 6), title, fill=INK, font=font)
    top, bottom, left, right = 28, height - 40, 50, width - 10
    draw.line([(left, top), (left, bottom), (right, bottom)], fill=INK)
    peak = max([float(v) for v in values] + [1e-12])
    draw.text((4, top - 4), f"{peak:.3g}", fill=INK, font=font)
    draw.text((4, bottom - 10), "0", fill=INK, font=font)
    n = max(len(values), 1)
    step = (right - left) / n
    chars = max(int(step / 6), 1)
    for i, (label, value) in enumerate(zip(labels, values, strict=True)):
        x0, x1 = left + i * step + 1, left + (i + 1) * step - 1
        y = min(bottom - (bottom - top) * float(value) / peak, bottom - 2)
        if value > 0:  # at least one pixel high
            draw.rectangle([x0, y, max(x1, x0 + 1), bottom - 1], fill=BAR)
        draw.text((x0, bottom + 4 + 12 * (i % 2)), str(label)[:chars], fill=INK, font=font)
    path = pathlib.Path(path)
    image.save(path)
    return path


def contact_sheet(frames: list[np.ndarray], names: list[str], path: pathlib.Path,
                  columns: int = 4, tile: int = 160) -> pathlib.Path:
    """A PNG grid of ``frames`` ((H, W, 3) uint8 each), each scaled to ``tile`` pixels wide
    (nearest neighbour) with its name under it."""
    from PIL import Image, ImageDraw, ImageFont
    font = ImageFont.load_default()
    rows = -(-len(frames) // columns)
    h, w = frames[0].shape[:2]
    tile_h = max(int(round(tile * h / w)), 1)
    sheet = Image.new("RGB", (columns * tile, rows * (tile_h + 14)), "white")
    draw = ImageDraw.Draw(sheet)
    for i, (frame, name) in enumerate(zip(frames, names, strict=True)):
        x, y = (i % columns) * tile, (i // columns) * (tile_h + 14)
        picture = Image.fromarray(np.ascontiguousarray(frame[..., :3])).resize(
            (tile, tile_h), Image.NEAREST)
        sheet.paste(picture, (x, y))
        draw.text((x + 2, y + tile_h + 1), name, fill=INK, font=font)
    path = pathlib.Path(path)
    sheet.save(path)
    return path
