"""Draw the sample pictures of samples/ (self-made, no third-party content).

    .venv/bin/python samples/make_samples.py            # rewrites every sample
    .venv/bin/python samples/make_samples.py small.png  # only the one named

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
    corners = [
        (
            cx + r * math.sqrt(2) * math.cos(a + math.pi / 4 + k * math.pi / 2),
            cy + r * math.sqrt(2) * math.sin(a + math.pi / 4 + k * math.pi / 2),
        )
        for k in range(4)
    ]
    d.polygon(corners, fill=(200, 60, 50))
    d.polygon([(W * 0.50, H * 0.70), (W * 0.66, H * 0.40), (W * 0.82, H * 0.70)], fill=(240, 240, 235))
    # slanted stripes across the ground
    for k in range(-4, 14):
        x0 = k * W * 0.09
        d.polygon(
            [(x0, H), (x0 + W * 0.045, H), (x0 + W * 0.045 + H * 0.2, H * 0.80), (x0 + H * 0.2, H * 0.80)],
            fill=(60, 110, 50),
        )
    return _finish(img, w, h)


def rings(w: int = 400, h: int = 400) -> Image.Image:
    """Concentric rings of four flat colours off-centre, on a plain background: curved
    edges everywhere on one side, a flat area on the other."""
    y, x = np.mgrid[0 : h * SS, 0 : w * SS] / SS
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
            d.line(
                [(x0, H * 0.5), (x0 + reach * 0.8, H * 0.5 + sgn * reach * 0.8)],
                fill=(230, 220, 120),
                width=lw,
            )
    return _finish(img, w, h)


def scene(w: int = 512, h: int = 512, seed: int = 7) -> Image.Image:
    """A picture that behaves like a photograph: a sky graded from deep to pale blue with
    a glow, hills in shaded greens, a shaded red ball, a lit box, a dark post and its
    shadow, then lens blur and sensor noise: smooth gradients everywhere, hard edges
    between objects of clearly different colour, and soft ones (the shadow, the glow)."""
    rng = np.random.default_rng(seed)
    y, x = (np.mgrid[0 : h * SS, 0 : w * SS] + 0.5) / SS
    u, v = x / w, y / h
    sky = np.stack([60 + 140 * v, 110 + 110 * v, 200 + 45 * v], axis=-1)
    glow = np.exp(-((u - 0.78) ** 2 + (v - 0.18) ** 2) / 0.02)[..., None]
    rgb = sky * (1 - 0.6 * glow) + np.array([255, 240, 200]) * 0.6 * glow
    hill_far = v > 0.55 + 0.06 * np.sin(2 * math.pi * (u * 1.3 + 0.1))
    rgb[hill_far] = (np.stack([70 + 40 * u, 120 + 30 * u, 60 + 0 * u], -1) * (1.1 - 0.4 * v)[..., None])[
        hill_far
    ]
    hill_near = v > 0.70 + 0.05 * np.sin(2 * math.pi * (u * 0.8 + 0.55))
    rgb[hill_near] = (np.stack([90 + 30 * u, 160 - 20 * u, 50 + 20 * u], -1) * (1.25 - 0.5 * v)[..., None])[
        hill_near
    ]
    # the post's shadow on the near hill: soft, a darker band
    shadow = hill_near & (np.abs((u - 0.22) + 0.6 * (v - 0.80)) < 0.02 + 0.05 * (v - 0.7))
    rgb[shadow] *= 0.65
    # a lit box: three faces, each a gradient
    front = (u > 0.52) & (u < 0.70) & (v > 0.52) & (v < 0.74)
    rgb[front] = (np.stack([200 - 80 * (u - 0.52), 150 - 60 * (v - 0.52), 60 + 0 * u], -1) * 1.0)[front]
    side = (u >= 0.70) & (u < 0.78) & (v > 0.52 - (u - 0.70) * 0.8) & (v < 0.74 - (u - 0.70) * 0.8)
    rgb[side] = np.array([130, 90, 40])
    top = (v <= 0.52) & (v > 0.46) & (u > 0.52 + (0.52 - v) * 1.25) & (u < 0.70 + (0.52 - v) * 1.25)
    rgb[top] = np.array([235, 200, 110])
    # a shaded red ball: lit from the upper right
    r = np.hypot(u - 0.36, v - 0.60)
    ball = r < 0.13
    light = np.clip(1.0 - np.hypot(u - 0.40, v - 0.55) / 0.16, 0, 1)[..., None]
    rgb[ball] = (np.array([120, 20, 25]) + np.array([130, 90, 80]) * light)[ball]
    # a dark post
    post = (np.abs(u - 0.16) < 0.018) & (v > 0.30) & (v < 0.82)
    rgb[post] = np.array([45, 35, 30])
    img = _finish(Image.fromarray(np.clip(rgb, 0, 255).astype(np.uint8), "RGB"), w, h)
    from PIL import ImageFilter

    arr = np.asarray(img.filter(ImageFilter.GaussianBlur(0.8)), dtype=np.float64)
    arr += rng.normal(0.0, 3.0, arr.shape)  # sensor noise, about 1 % of full scale
    return Image.fromarray(np.clip(np.round(arr), 0, 255).astype(np.uint8), "RGB")


def small(w: int = 160, h: int = 120) -> Image.Image:
    """A small picture for the regression check of `cvtbench regress`: a sky graded from
    blue to pale, a dark disc, a tilted orange bar and a green curved hill: a gradient,
    straight edges at an angle and curved ones in 160x120 px."""
    y, x = (np.mgrid[0 : h * SS, 0 : w * SS] + 0.5) / SS
    u, v = x / w, y / h
    rgb = np.stack([70 + 150 * v, 120 + 110 * v, 210 + 30 * v], axis=-1)
    hill = v > 0.68 + 0.12 * np.sin(math.pi * (u * 1.4 + 0.15))
    rgb[hill] = (70, 140, 60)
    rgb[np.hypot(u - 0.74, (v - 0.30) * h / w) < 0.13] = (40, 40, 70)  # disc
    # a bar tilted by 30 degrees
    a = math.radians(30)
    along = (u - 0.32) * math.cos(a) + (v - 0.45) * h / w * math.sin(a)
    across = -(u - 0.32) * math.sin(a) + (v - 0.45) * h / w * math.cos(a)
    rgb[(np.abs(along) < 0.20) & (np.abs(across) < 0.05)] = (235, 140, 40)
    return _finish(Image.fromarray(rgb.astype(np.uint8), "RGB"), w, h)


SAMPLES = {"shapes.png": shapes, "rings.png": rings, "leaf.png": leaf, "scene.jpg": scene, "small.png": small}


def main(names=None) -> None:
    """Draw the pictures ``names`` (default: every one of SAMPLES) into this folder."""
    for name, draw in SAMPLES.items():
        if names and name not in names:
            continue
        path = HERE / name
        if name.endswith(".jpg"):
            draw().save(path, quality=90, optimize=True)  # a photograph: a JPEG
        else:
            draw().save(path, optimize=True)
        print(f"{path}: {path.stat().st_size // 1024} KB")


if __name__ == "__main__":
    import sys

    main(sys.argv[1:])
