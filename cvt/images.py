"""Reading images for density maps, direction fields and region masks.

Any format Pillow reads (PNG, JPEG, TIFF, ...), greyscale, RGB(A), palette or 16-bit.
An image whose size differs from the raster is resampled to it (bilinear for density
and fields, nearest for masks): this is documented behaviour, not an error.
"""

from __future__ import annotations

import os

import numpy as np

from .errors import InputError


def open_image(path):
    """Open and fully decode an image, or raise InputError naming the file."""
    from PIL import Image, UnidentifiedImageError

    path = os.fspath(path)
    if not os.path.exists(path):
        raise InputError(f"image file not found: {path}")
    if os.path.isdir(path):
        raise InputError(f"expected an image file, got a directory: {path}")
    try:
        img = Image.open(path)
        img.load()
    except UnidentifiedImageError:
        raise InputError(f"not an image file (unrecognised format): {path}") from None
    except (OSError, ValueError, SyntaxError) as exc:
        raise InputError(f"cannot read image {path}: {exc}") from None
    if img.width < 1 or img.height < 1:
        raise InputError(f"image {path} has no pixels")
    return img


def _to_float_grey(img) -> tuple[np.ndarray, float]:
    """Greyscale float array and its full-scale value (255, or 65535 for 16-bit)."""
    if img.mode in ("I;16", "I;16B", "I;16L", "I"):
        arr = np.asarray(img, dtype=np.float64)
        return arr, 65535.0 if arr.max() > 255 or img.mode.startswith("I;16") else 255.0
    if img.mode == "F":
        return np.asarray(img, dtype=np.float64), 1.0
    if img.mode in ("RGBA", "LA", "PA") or (img.mode == "P" and "transparency" in img.info):
        img = img.convert("RGBA").convert("L")
    else:
        img = img.convert("L")
    return np.asarray(img, dtype=np.float64), 255.0


def _resize(arr: np.ndarray, width: int, height: int, nearest: bool) -> np.ndarray:
    if arr.shape == (height, width):
        return arr
    from PIL import Image

    mode = Image.Resampling.NEAREST if nearest else Image.Resampling.BILINEAR
    out = Image.fromarray(arr.astype(np.float32), mode="F").resize((width, height), mode)
    return np.asarray(out, dtype=np.float64)


def load_grey(path, width: int, height: int) -> tuple[np.ndarray, float]:
    """Greyscale values resampled to (height, width), and the image's full scale."""
    arr, full = _to_float_grey(open_image(path))
    return _resize(arr, width, height, nearest=False), full


def load_mask(path, width: int, height: int) -> np.ndarray:
    """Region mask: where the image has alpha, opaque pixels (alpha >= 128) are inside;
    otherwise light pixels (grey >= half the full scale) are inside."""
    img = open_image(path)
    if img.mode in ("RGBA", "LA", "PA") or (img.mode == "P" and "transparency" in img.info):
        alpha = np.asarray(img.convert("RGBA"), dtype=np.float64)[..., 3]
        inside = alpha >= 128
    else:
        arr, full = _to_float_grey(img)
        inside = arr >= full / 2
    inside = _resize(inside.astype(np.float64), width, height, nearest=True) > 0.5
    if not inside.any():
        raise InputError(f"region mask {path} is empty: no pixel is inside the region")
    return inside


def load_rgb(path) -> np.ndarray:
    """(H, W, 3) float64 RGB in 0..1 (16-bit and palette images converted)."""
    img = open_image(path)
    if img.mode in ("I;16", "I;16B", "I;16L", "I", "F"):
        grey, full = _to_float_grey(img)
        g = np.clip(grey / full, 0, 1)
        return np.repeat(g[..., None], 3, axis=2)
    if img.mode in ("RGBA", "LA", "PA", "P"):
        rgba = np.asarray(img.convert("RGBA"), dtype=np.float64) / 255.0
        a = rgba[..., 3:4]
        return rgba[..., :3] * a + (1 - a)  # composite on white
    return np.asarray(img.convert("RGB"), dtype=np.float64) / 255.0
