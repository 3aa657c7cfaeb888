"""Draw the sample pictures of samples/ (self-made, no third-party content).

    .venv/bin/python samples/make_samples.py      # rewrites samples/*.png

Each picture is drawn 4x larger with Pillow and shrunk with a box filter, so edges are
antialiased but areas stay flat colours; the pictures have the strong straight and
curved edges that make a direction field visible, and both busy and empty areas so
that a density map has something to show.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
from PIL import Image, ImageDraw

HERE = Path(__file__).resolve().parent
SS = 4  # supersampling factor


def _finish(img: Image.Image, w: int, h: int) -> Image.Image:
    return img.resize((w, h), Image.Resampling.BOX)


def shapes(w: int = 480, h: int = 360) -> Image.Image:
    """Sky and ground, a sun (disc), a tilted square house with a triangular roof, and
    a band of slanted stripes: straight edges at several angles and a round one."""
    W, H = w * SS, h * SS
    img = Image.new("RGB", (W, H), (120, 180, 230))
    d = ImageDraw.Draw(img)
    d.rectangle([0, int(H * 0.72), W, H], fill=(90, 150, 70))  # ground
    d.ellipse([int(W * 0.68), int(H * 0.08), int(W * 0.90), int(H * 0.37)], fill=(250, 200, 40))
    # a square tilted by 20 degrees
    cx, cy, r = W * 0.30, H * 0.52, H * 0.19
    a = math.radians(20)
    corners = [(cx + r * math.sqrt(2) * math.cos(a + math.pi / 4 + k * math.pi / 2),
                cy + r * math.sqrt(2) * math.sin(a + math.pi / 4 + k * math.pi / 2)) for k in range(4)]
    d.polygon(corners, fill=(200, 60, 50))
    d.polygon([(W * 0.50, H * 0.70), (W * 0.66, H * 0.40), (W * 0.82, H * 0.70)], fill=(240, 240, 235))
    # slanted stripes across the ground
    for k in range(-4, 14):
        x0 = k * W * 0.09
        d.polygon([(x0, H), (x0 + W * 0.045, H), (x0 + W * 0.045 + H * 0.2, H * 0.80),
                   (x0 + H * 0.2, H * 0.80)], fill=(60, 110, 50))
    return _finish(img, w, h)


def rings(w: int = 400, h: int = 400) -> Image.Image:
    """Concentric rings of four flat colours off-centre, on a plain background: curved
    edges everywhere on one side, a flat area on the other."""
    y, x = np.mgrid[0:h * SS, 0:w * SS] / SS
    r = np.hypot(x - w * 0.38, y - h * 0.45)
    palette = np.array([(30, 60, 120), (240, 180, 40), (200, 70, 60), (250, 245, 230)], np.uint8)
    band = (r // (w * 0.045)).astype(int) % 4
    rgb = palette[band]
    rgb[r > w * 0.36] = (235, 225, 200)
    return _finish(Image.fromarray(rgb, "RGB"), w, h)


def leaf(w: int = 440, h: int = 330) -> Image.Image:
    """A leaf shape with a midrib and side veins (lens-shaped
    curved outline, straight veins at ±45 degrees) on a grey-blue background."""
    W, H = w * SS, h * SS
    img = Image.new("RGB", (W, H), (150, 170, 195))
    d = ImageDraw.Draw(img)
    t = np.linspace(0, math.pi, 200)
    top = [(W * 0.1 + W * 0.8 * (1 - math.cos(s)) / 2, H * 0.5 - H * 0.32 * math.sin(s)) for s in t]
    bot = [(W * 0.1 + W * 0.8 * (1 - math.cos(s)) / 2, H * 0.5 + H * 0.32 * math.sin(s)) for s in t[::-1]]
    d.polygon(top + bot, fill=(110, 180, 60))
    lw = int(SS * 3)
    d.line([(W * 0.1, H * 0.5), (W * 0.9, H * 0.5)], fill=(230, 220, 120), width=lw)
    for k in range(1, 8):
        x0 = W * (0.1 + 0.1 * k)
        reach = H * 0.30 * math.sin(math.pi * (x0 - W * 0.1) / (W * 0.8))
        for sgn in (-1, 1):
            d.line([(x0, H * 0.5), (x0 + reach * 0.8, H * 0.5 + sgn * reach * 0.8)],
                   fill=(230, 220, 120), width=lw)
    return _finish(img, w, h)


SAMPLES = {"shapes.png": shapes, "rings.png": rings, "leaf.png": leaf}


def main() -> None:
    for name, draw in SAMPLES.items():
        path = HERE / name
        draw().save(path, optimize=True)
        print(f"{path}: {path.stat().st_size // 1024} KB")


if __name__ == "__main__":
    main()
