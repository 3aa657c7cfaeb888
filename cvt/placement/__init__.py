"""Placement: one element per Lloyd cell.

The rooms of the package:

- :mod:`.fit` — each element the largest that fits its raster cell, centred at its site or
  moved inside the cell to grow it (``ours-fit``);
- :mod:`.compaction` — rounds of a linear program over centres and sizes, so that
  neighbouring elements share their walls (``ours-compact``);
- :mod:`.alternate` — triangles that point either way, whichever fits larger;
- :mod:`.ours` — the paper's method and its two extensions as method records.

A plug-in reuses them by path, e.g.
``from compact_distributions.cvt.placement.ours import run_ours``.
"""
