"""
Figure 3: the six metrics' CVTs
===============================

The paper's Figure 3: centroidal Voronoi tessellations under the six distances whose
unit balls are the elements' shapes (L2, L1, L∞, the axially scaled L∞ and L2, and the
triangle's distance), cells coloured, sites dark.  The panels come from
``cvtbench figures``' own function, here on a 128² raster with 120 sites.
"""

import matplotlib.pyplot as plt

from compact_distributions.backends import create_backend
from compact_distributions.bench.commands.figures import Settings, figure_metrics

settings = Settings(size=128, sites=120, iterations=10, scale=1.5)
with create_backend("numpy") as backend:
    picture = figure_metrics(backend, settings)

fig = plt.figure(figsize=(picture.width / 100, picture.height / 100), dpi=100)
fig.add_axes((0, 0, 1, 1)).imshow(picture)
fig.axes[0].set_axis_off()
plt.show()
