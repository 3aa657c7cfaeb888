"""
Figure 14: elements of every shape, of varying size and direction
=================================================================

The paper's Figure 14: squares, rectangles, ellipses and triangles, then elements whose
size follows a radial density and whose direction follows a circular field.  Each panel
is a run of ours (20 Lloyd iterations here: 10) with the elements placed in their cells
and captioned with the coverage ``cvt.evaluate`` measures.
"""

import matplotlib.pyplot as plt

from compact_distributions.backends import create_backend
from compact_distributions.bench.commands.figures import Settings, figure_elements

settings = Settings(size=128, sites=120, iterations=10, scale=1.5)
with create_backend("numpy") as backend:
    picture = figure_elements(backend, settings)

fig = plt.figure(figsize=(picture.width / 100, picture.height / 100), dpi=100)
fig.add_axes((0, 0, 1, 1)).imshow(picture)
fig.axes[0].set_axis_off()
plt.show()
