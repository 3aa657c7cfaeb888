"""Reading pictures: the one reader behind density maps, direction fields, region masks
and mosaic pictures.

Any format Pillow reads (PNG, JPEG, TIFF, ...), greyscale, RGB(A), palette or 16-bit.
:func:`read_picture` checks the file before decoding it (it exists, is an image, is not a
decompression bomb: more than twice Pillow's ``Image.MAX_IMAGE_PIXELS``, and its decoded
size fits the memory limit), applies the EXIF orientation (a phone photo comes out the
way it is shown), and decodes at a reduced size where the picture will be resampled
down anyway: JPEG's DCT scaling (``Image.draft``), then whole-factor box reduction
(``Image.reduce``), so a large picture never exists as a float array at full size.
An image whose size differs from the raster is resampled to it (bilinear for density and
fields, nearest for masks): this is documented behaviour, not an error.
"""

from __future__ import annotations

import os
import re
import stat
import warnings

import numpy as np

from ..errors import InputError
from ..resources import Estimate

# EXIF orientations that swap width and height (a turn by 90 or 270 degrees)
_TRANSPOSED = (5, 6, 7, 8)
# bytes per pixel Pillow stores for a mode (multi-band modes are padded to 4)
_PIXEL_BYTES = {"1": 1, "L": 1, "P": 1, "I;16": 2, "I;16L": 2, "I;16B": 2, "I;16N": 2}
# modes that Image.reduce cannot shrink, and the mode each is widened to first
_WIDEN = {"1": "L", "P": "RGBA", "I;16": "I", "I;16L": "I", "I;16B": "I", "I;16N": "I"}


def open_picture(path, name: str = "image"):
    """The picture at ``path`` opened lazily (its header read, nothing decoded), or
    InputError naming ``name`` and the file."""
    from PIL import Image, UnidentifiedImageError

    path = os.fspath(path)
    try:
        st = os.stat(path)
    except FileNotFoundError:
        raise InputError(f"{name} {path}: image file not found") from None
    except OSError as exc:
        raise InputError(f"{name} {path}: cannot read the file ({exc.strerror or exc})") from None
    if stat.S_ISDIR(st.st_mode):
        raise InputError(f"{name} {path}: expected an image file, got a directory")
    if not stat.S_ISREG(st.st_mode):
        raise InputError(f"{name} {path}: expected an image file, got a special file")
    try:
        with warnings.catch_warnings():
            # over MAX_IMAGE_PIXELS Pillow only warns; read_picture's memory check decides
            warnings.simplefilter("ignore", Image.DecompressionBombWarning)
            img = Image.open(path)
    except UnidentifiedImageError:
        raise InputError(f"{name} {path}: not an image file (unrecognised format)") from None
    except Image.DecompressionBombError as exc:
        size = re.search(r"\((\d+) pixels\)", str(exc))
        declared = f"declares {int(size.group(1)) / 1e6:.0f} Mpx, " if size else ""
        raise InputError(
            f"{name} {path}: {declared}more than the {2 * Image.MAX_IMAGE_PIXELS / 1e6:.0f} Mpx "
            "Pillow decodes (its guard against decompression bombs: 2 x Image.MAX_IMAGE_PIXELS); "
            "shrink the picture first"
        ) from None
    except (OSError, ValueError, SyntaxError) as exc:
        raise InputError(f"{name} {path}: cannot read image: {exc}") from None
    if img.width < 1 or img.height < 1:
        raise InputError(f"{name} {path}: the image has no pixels")
    return img


def _orientation(img) -> int:
    """The EXIF orientation from the header, without decoding the pixels."""
    from PIL import Image

    try:
        if img.format == "PNG":  # PNG's getexif() decodes the whole picture to look past it
            raw = img.info.get("exif")
            if not raw:
                return 1
            exif = Image.Exif()
            exif.load(raw)
        else:
            exif = img.getexif()
        return int(exif.get(0x0112, 1))
    except Exception:  # a broken EXIF block must not stop the picture being read
        return 1


def upright_size(img) -> tuple[int, int]:
    """(width, height) of an opened picture as it is shown (after its EXIF orientation)."""
    w, h = img.size
    return (h, w) if _orientation(img) in _TRANSPOSED else (w, h)


def read_picture(
    path,
    name: str = "image",
    at_least: tuple[int, int] | None = None,
    memory_limit=None,
    memory_option: str = "--memory-limit",
):
    """The picture at ``path`` decoded and upright, no smaller than ``at_least`` (W, H)
    on either side (the picture's own size when it is smaller): a PIL image.

    The decoded size is estimated from the header and checked against ``memory_limit``
    (:mod:`cvt.resources`) before anything is decoded."""
    from PIL import Image, ImageOps

    img = open_picture(path, name)
    path = os.fspath(path)
    turned = _orientation(img) in _TRANSPOSED
    want = None
    if at_least is not None:
        want = (
            (max(1, int(at_least[1])), max(1, int(at_least[0])))
            if turned
            else (max(1, int(at_least[0])), max(1, int(at_least[1])))
        )
        if img.format == "JPEG" and img.mode in ("L", "RGB", "CMYK", "YCbCr"):
            img.draft(img.mode, want)  # DCT scaling: decodes at 1/2, 1/4 or 1/8 when that is enough
    w, h = img.size
    est = Estimate(f"reading {name} {path} ({w}x{h} px)")
    est.add("the decoded picture", w * h * _PIXEL_BYTES.get(img.mode, 4))
    if img.mode in _WIDEN:
        est.add("its conversion", w * h * 4)
    est.check(memory_limit, lower="shrink the picture first", name=memory_option)
    try:
        with warnings.catch_warnings():
            # over MAX_IMAGE_PIXELS Pillow only warns; the memory check above decides
            warnings.simplefilter("ignore", Image.DecompressionBombWarning)
            img.load()
    except (OSError, ValueError, SyntaxError, EOFError) as exc:
        raise InputError(f"{name} {path}: cannot read image: {exc}") from None
    source_mode = img.mode
    factor = 1 if want is None else min(img.width // want[0], img.height // want[1])
    if factor >= 2:
        if img.mode in _WIDEN:
            img = img.convert(_WIDEN[img.mode])
        img = img.reduce(factor)
    try:
        img = ImageOps.exif_transpose(img)
    except Exception:  # a broken EXIF block: the picture as stored
        pass
    img.info["source_mode"] = source_mode  # a widened 16-bit picture keeps its full scale
    return img


def _to_float_grey(img) -> tuple[np.ndarray, float]:
    """Greyscale float array and its full-scale value (255, or 65535 for 16-bit)."""
    if img.mode in ("I;16", "I;16B", "I;16L", "I"):
        arr = np.asarray(img, dtype=np.float64)
        sixteen = img.info.get("source_mode", img.mode).startswith("I;16")
        return arr, 65535.0 if arr.max() > 255 or sixteen else 255.0
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


def load_grey(
    path, width: int, height: int, name: str = "image", memory_limit=None
) -> tuple[np.ndarray, float]:
    """Greyscale values resampled to (height, width), and the image's full scale.
    Float images must hold finite values."""
    arr, full = _to_float_grey(read_picture(path, name, (width, height), memory_limit))
    if not np.isfinite(arr).all():
        raise InputError(f"{name} {os.fspath(path)}: the image holds NaN or infinite values")
    return _resize(arr, width, height, nearest=False), full


def load_mask(path, width: int, height: int, name: str = "region mask", memory_limit=None) -> np.ndarray:
    """Region mask: where the image has alpha, opaque pixels (alpha >= 128) are inside;
    otherwise light pixels (grey >= half the full scale) are inside."""
    img = read_picture(path, name, (width, height), memory_limit)
    if img.mode in ("RGBA", "LA", "PA") or (img.mode == "P" and "transparency" in img.info):
        alpha = np.asarray(img.convert("RGBA"), dtype=np.float64)[..., 3]
        inside = alpha >= 128
    else:
        arr, full = _to_float_grey(img)
        inside = arr >= full / 2
    inside = _resize(inside.astype(np.float64), width, height, nearest=True) > 0.5
    if not inside.any():
        raise InputError(f"{name} {os.fspath(path)} is empty: no pixel is inside the region")
    return inside


def load_rgb(
    path, at_least: tuple[int, int] | None = None, name: str = "image", memory_limit=None
) -> np.ndarray:
    """(H, W, 3) float64 RGB in 0..1 (16-bit and palette images converted), no smaller
    than ``at_least`` where the picture is larger."""
    img = read_picture(path, name, at_least, memory_limit)
    if img.mode in ("I;16", "I;16B", "I;16L", "I", "F"):
        grey, full = _to_float_grey(img)
        if not np.isfinite(grey).all():
            raise InputError(f"{name} {os.fspath(path)}: the image holds NaN or infinite values")
        g = np.clip(grey / full, 0, 1)
        return np.repeat(g[..., None], 3, axis=2)
    if img.mode in ("RGBA", "LA", "PA", "P"):
        rgba = np.asarray(img.convert("RGBA"), dtype=np.float64) / 255.0
        a = rgba[..., 3:4]
        return rgba[..., :3] * a + (1 - a)  # composite on white
    return np.asarray(img.convert("RGB"), dtype=np.float64) / 255.0


__all__ = ["open_picture", "upright_size", "read_picture", "load_grey", "load_mask", "load_rgb"]
