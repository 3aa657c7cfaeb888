"""Mosaics: a picture turned into tiles.

The rooms of the package:

- :mod:`.images` — reading pictures, regions and densities;
- :mod:`.colour` — tile colours from the picture;
- :mod:`.image_fields` — direction fields and walls (strong edges) from a picture;
- :mod:`.cutting` — tiles cut back to the walls;
- :mod:`.render` — drawing elements and mosaics (PNG, SVG);
- :mod:`.pipeline` — :func:`make_mosaic`, the whole job, and :class:`MosaicResult`.

``from compact_distributions.cvt.mosaic import make_mosaic`` keeps working: the two names
of the pipeline are loaded from :mod:`.pipeline` on first use.
"""

from __future__ import annotations

import importlib

_PIPELINE_NAMES = ("make_mosaic", "MosaicResult")

__all__ = list(_PIPELINE_NAMES)


def __getattr__(name: str):
    if name in _PIPELINE_NAMES:
        return getattr(importlib.import_module(".pipeline", __name__), name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
