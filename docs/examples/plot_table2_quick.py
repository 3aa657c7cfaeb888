"""
Table 2 from Python
===================

Each sweep command is a function of a typed request: ``cvtbench table2`` builds a
:class:`~compact_distributions.bench.table2.Table2Request` and calls
:func:`~compact_distributions.bench.table2.table2`, which runs the methods on the fixed
problem set (with resume, one raw json per run, and atomic reports) and writes
``table2.md``, ``table2.csv``, ``table2.png`` and the coverage–overlap curves.  Here its
quick form (256², N = 250), cut down to squares, three methods, the NumPy backend and one
seed, so that it runs in seconds.
"""

import tempfile
from pathlib import Path

import matplotlib.pyplot as plt
import pandas as pd
from PIL import Image

from compact_distributions.bench.table2 import Table2Request, table2

out = Path(tempfile.mkdtemp()) / "table2"
request = Table2Request(
    out=out,
    quick=True,
    quiet=True,
    seeds=1,
    methods=("ours", "ours-compact", "hausner2001"),
    backends=("numpy",),
    shapes=("square",),
)
status = table2(request)
print("exit status", status, "; wrote", sorted(p.name for p in out.iterdir() if p.is_file()))

table = pd.read_csv(out / "table2.csv")
print(table[["method", "backend", "element", "coverage_mean", "overlap_mean", "coverage_at_1pct_overlap"]])

picture = Image.open(out / "table2.png")
fig = plt.figure(figsize=(picture.width / 100, picture.height / 100), dpi=100)
fig.add_axes((0, 0, 1, 1)).imshow(picture)
fig.axes[0].set_axis_off()
plt.show()
