"""
A density and a field
=====================

Element sizes follow a density (bright = dense = small elements) and their sides follow
a direction field.  Here: a radial density, dense at the centre, and a circular field,
through the declared API (``cd.problem``, ``cd.run``), with ``ours`` (each element
centred at its site) beside ``ours-compact`` (fitted, then compacted).  The fidelity
measures say how well the sizes follow the density (``size_fidelity``: 0 is perfect) and
the directions the field (``direction_fidelity``, degrees).
"""

import matplotlib.pyplot as plt

import compact_distributions as cd
from compact_distributions.bench.commands.figures import radial_density
from compact_distributions.bench.panels import panel_grid
from compact_distributions.cvt.evaluate import measures
from compact_distributions.cvt.fields import DirectionField
from compact_distributions.cvt.mosaic.render import PAPER, draw_elements

size = 160
problem = cd.problem(
    n_elements=180,
    size=size,
    element="square",
    seed=2,
    density=radial_density(size),
    field=DirectionField.named("circular", size, size),
)

panels, captions = [], []
with cd.create_backend("numpy") as backend:
    for method in ("ours", "ours-compact"):
        result = cd.run(problem, method, backend=backend, iterations=10)
        m = measures(result.elements, problem, "square")
        print(
            f"{method:13s} coverage {result.coverage:.3f}  size_fidelity {m['size_fidelity']:.3f}  "
            f"direction_fidelity {m['direction_fidelity']:.2f}°"
        )
        panels.append(draw_elements(result.elements, size, size, region_colour=PAPER, scale=1.5))
        captions.append(f"{method}: coverage {result.coverage:.1%}")

picture = panel_grid(panels, captions, 2, "Radial density, circular field (180 squares)")
fig = plt.figure(figsize=(picture.width / 100, picture.height / 100), dpi=100)
fig.add_axes((0, 0, 1, 1)).imshow(picture)
fig.axes[0].set_axis_off()
plt.show()
