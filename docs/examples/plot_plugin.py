"""
A plug-in method and backend
============================

The Extending guide's complete plug-in, ``cvt_plugin_example.py``, adds a method
(``shrunk``: ours, every element then scaled about its centre, with one declared option,
``shrink``) and a backend (``brute``: every pixel against every site).  Installed, its
entry points put both in ``cvtbench info``, ``--method`` and ``--backend``.  Here the very
same file is imported without installing it: its ``METHOD`` goes through the registry's
``records_of`` as the entry point would, and its backend is started like any other.
The brute-force labels equal the NumPy reference's, so the cells are the same.
"""

import sys
from pathlib import Path

import matplotlib.pyplot as plt
import numpy as np

import compact_distributions as cd
from compact_distributions.bench.panels import panel_grid
from compact_distributions.cvt.mosaic.render import PAPER, draw_elements
from compact_distributions.cvt.registry import records_of

here = Path(__file__).resolve().parent if "__file__" in globals() else Path.cwd()
sys.path.insert(0, str(here.parent / "extending"))
import cvt_plugin_example  # noqa: E402

(shrunk,) = records_of(cvt_plugin_example.METHOD, "shrunk")
print(f"{shrunk.name}: {shrunk.summary}; options {[o.flag for o in shrunk.options]}")

size = 96
problem = cd.problem(n_elements=60, size=size, element="square", seed=4)
with cvt_plugin_example.BruteBackend() as brute, cd.create_backend("numpy") as numpy_backend:
    print("device:", brute.device())
    ours = cd.run(problem, "ours", backend=numpy_backend, iterations=8)
    mine = cd.run(problem, shrunk, backend=brute, iterations=8, shrink=0.7)
print("same sites as the NumPy reference:", np.allclose(ours.distribution.sites, mine.distribution.sites))

panels = [draw_elements(r.elements, size, size, region_colour=PAPER, scale=2) for r in (ours, mine)]
captions = [
    f"ours on numpy: coverage {ours.coverage:.1%}",
    f"shrunk (shrink 0.7) on brute: {mine.coverage:.1%}",
]
picture = panel_grid(panels, captions, 2, "A plug-in method on a plug-in backend")
fig = plt.figure(figsize=(picture.width / 100, picture.height / 100), dpi=100)
fig.add_axes((0, 0, 1, 1)).imshow(picture)
fig.axes[0].set_axis_off()
plt.show()
