"""
Compaction on hexagons
======================

The paper places one element in each Lloyd cell, so the cells' slack becomes grout.
``ours-compact`` fits each element in its cell, then solves rounds of a linear program
over the centres and sizes in which neighbours share their walls (see the user guide's
page on compaction).  Hexagons start furthest from their lattice, so their record asks for
12 rounds by default.  Left: ``ours``; right: ``ours-compact``, with a one-pixel grout.
"""

import matplotlib.pyplot as plt

import compact_distributions as cd
from compact_distributions.bench.panels import panel_grid
from compact_distributions.cvt.mosaic.render import PAPER, draw_elements

size = 160
problem = cd.problem(n_elements=150, size=size, element="hexagon", seed=1)
panels, captions = [], []
with cd.create_backend("numpy") as backend:
    for method in ("ours", "ours-compact"):
        result = cd.run(problem, method, backend=backend, iterations=10, gap=1.0)
        print(f"{method:13s} coverage {result.coverage:.3f}, overlap {result.overlap:.4f}")
        panels.append(draw_elements(result.elements, size, size, region_colour=PAPER, scale=1.5))
        captions.append(f"{method}: coverage {result.coverage:.1%}, overlap {result.overlap:.2%}")

picture = panel_grid(panels, captions, 2, "150 hexagons, gap 1 px")
fig = plt.figure(figsize=(picture.width / 100, picture.height / 100), dpi=100)
fig.add_axes((0, 0, 1, 1)).imshow(picture)
fig.axes[0].set_axis_off()
plt.show()
