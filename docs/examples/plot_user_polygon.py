"""
A user's polygon
================

Any convex polygon is an element: ``element="polygon:FILE"`` reads its vertices (a CSV
with columns ``x,y`` or a JSON list of ``[x, y]``, in any order and at any scale), moves
its unit ball to its area centroid and scales it to circumradius 1.  The problem owns the
shape record, so Lloyd runs under the polygon's own distance, and placement and
compaction read the record like any built-in shape's.  Here an irregular pentagon.
"""

import json
import tempfile
from pathlib import Path

import matplotlib.pyplot as plt

import compact_distributions as cd
from compact_distributions.bench.panels import panel_grid
from compact_distributions.cvt.mosaic.render import PAPER, draw_elements

pentagon = [[0, 0], [4, 0], [5, 3], [2, 5], [-1, 3]]
folder = Path(tempfile.mkdtemp())
(folder / "pentagon.json").write_text(json.dumps(pentagon))

size = 160
problem = cd.problem(n_elements=150, size=size, element=f"polygon:{folder / 'pentagon.json'}", seed=3)
panels, captions = [], []
with cd.create_backend("numpy") as backend:
    for method in ("ours", "ours-compact"):
        result = cd.run(problem, method, backend=backend, iterations=10)
        print(f"{method:13s} coverage {result.coverage:.3f}, overlap {result.overlap:.4f}")
        panels.append(draw_elements(result.elements, size, size, region_colour=PAPER, scale=1.5))
        captions.append(f"{method}: coverage {result.coverage:.1%}")

picture = panel_grid(panels, captions, 2, "An irregular convex pentagon given as a file")
fig = plt.figure(figsize=(picture.width / 100, picture.height / 100), dpi=100)
fig.add_axes((0, 0, 1, 1)).imshow(picture)
fig.axes[0].set_axis_off()
plt.show()
