"""
Figure 15: regions that are not rectangles
==========================================

The paper's Figure 15: squares in a star, ellipses in a ring under a circular field and
triangles in a star under a radial field.  The region is a mask (``Grid(width, height,
mask)``); the sites, the Lloyd cells and the elements stay inside it.
"""

import matplotlib.pyplot as plt

from compact_distributions.backends import create_backend
from compact_distributions.bench.commands.figures import Settings, figure_regions

settings = Settings(size=128, sites=120, iterations=10, scale=1.5)
with create_backend("numpy") as backend:
    picture = figure_regions(backend, settings)

fig = plt.figure(figsize=(picture.width / 100, picture.height / 100), dpi=100)
fig.add_axes((0, 0, 1, 1)).imshow(picture)
fig.axes[0].set_axis_off()
plt.show()
