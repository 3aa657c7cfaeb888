"""
A photograph to a mosaic, with its edges
========================================

``cd.mosaic`` turns a picture into a mosaic: tile sizes follow a density map (smaller
where the picture has detail), tile sides run along the picture's edges, the strong
edges (a colour contrast of at least ``edge_threshold`` ΔE*ab) are walls that no tile
crosses, and each tile is filled with the picture's colour under it.  Here
``samples/scene.jpg`` at 192 px with 400 squares: the picture, its strong edges, the
mosaic with the edges as walls and, for comparison, without walls.
"""

from importlib.resources import files

import matplotlib.pyplot as plt
import numpy as np
from PIL import Image

import compact_distributions as cd
from compact_distributions.bench.panels import panel_grid

scene = str(files("compact_distributions.samples") / "scene.jpg")
with cd.create_backend("numpy") as backend:
    walled = cd.mosaic(scene, backend=backend, n_elements=400, size=192, iterations=10, seed=1)
    no_walls = cd.mosaic(scene, backend=backend, n_elements=400, size=192, iterations=10, seed=1, edges=False)

for name, m in (("walls", walled), ("no walls", no_walls)):
    print(
        f"{name:9s} {m.placed} tiles, coverage {m.coverage:.3f}, colour error {m.colour_error:.2f} ΔE*ab, "
        f"straddling {m.straddling:.3f}"
    )

picture = Image.fromarray(np.round(255 * np.asarray(walled.picture)).astype(np.uint8))
edges = Image.fromarray(np.where(walled.edges, 0, 255).astype(np.uint8)).convert("RGB")
panels = [picture, edges, walled.render(), no_walls.render()]
captions = [
    "the picture",
    f"strong edges (≥ {walled.edge_threshold:g} ΔE*ab)",
    f"walls: straddling {walled.straddling:.1%}",
    f"no walls: straddling {no_walls.straddling:.1%}",
]
sheet = panel_grid(panels, captions, 4, "samples/scene.jpg, 400 squares", scale=1.25)
fig = plt.figure(figsize=(sheet.width / 100, sheet.height / 100), dpi=100)
fig.add_axes((0, 0, 1, 1)).imshow(sheet)
fig.axes[0].set_axis_off()
plt.show()
