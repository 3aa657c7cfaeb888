"""The one panel layout of the suite's pictures: PIL images in a grid, each with its
caption under it, a title on top; and the one way they are written (a palette PNG).
``cvtbench figures`` and the mosaic comparisons both use it."""

from __future__ import annotations

import io
import math


def caption_font(size: int):
    """DejaVu Sans (shipped with matplotlib: it has β, ∞ and Δ), else PIL's default."""
    from PIL import ImageFont

    try:
        from matplotlib import font_manager

        return ImageFont.truetype(font_manager.findfont("DejaVu Sans"), size)
    except (ImportError, OSError, ValueError):
        try:
            return ImageFont.load_default(size=size)
        except TypeError:  # Pillow < 10.1: a fixed bitmap font
            return ImageFont.load_default()


def panel_grid(panels, captions, columns: int | None = None, title: str = "", scale: float = 1.0):
    """Panels (PIL images of one size) in a grid of ``columns`` (default: one row), a
    caption of one or more lines under each, ``title`` on top; ``scale`` resizes the
    panels first.  Returns a PIL image."""
    from PIL import Image, ImageDraw

    if scale != 1.0:
        panels = [
            p.resize((round(p.width * scale), round(p.height * scale)), Image.Resampling.LANCZOS)
            for p in panels
        ]
    columns = columns or len(panels)
    pw, ph = panels[0].size
    pad, line = 10, 18
    cap_h = line * max(len(c.splitlines()) or 1 for c in captions) + 6
    title_h = 30 if title else pad
    rows = math.ceil(len(panels) / columns)
    img = Image.new(
        "RGB",
        (columns * pw + (columns + 1) * pad, title_h + rows * (ph + cap_h + pad) + pad),
        (255, 255, 255),
    )
    draw = ImageDraw.Draw(img)
    if title:
        draw.text((pad, 7), title, fill=(0, 0, 0), font=caption_font(16))
    font = caption_font(13)
    for k, (panel, cap) in enumerate(zip(panels, captions, strict=True)):
        r, c = divmod(k, columns)
        x, y = pad + c * (pw + pad), title_h + r * (ph + cap_h + pad)
        img.paste(panel, (x, y))
        draw.multiline_text((x, y + ph + 4), cap, fill=(0, 0, 0), font=font, spacing=3)
    return img


def png_bytes(img, colours: int = 128) -> bytes:
    """PNG with an adaptive palette: the pictures are flat colours, so a palette keeps
    them small (well under 300 KB) with no visible loss."""
    from PIL import Image

    buf = io.BytesIO()
    img.quantize(colors=colours, method=Image.Quantize.MEDIANCUT, dither=Image.Dither.NONE).save(
        buf, format="PNG", optimize=True
    )
    return buf.getvalue()


__all__ = ["panel_grid", "png_bytes", "caption_font"]
