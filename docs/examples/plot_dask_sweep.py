"""
A sweep on a local Dask cluster
===============================

``cvtbench table2``, ``backends`` and ``reproduce`` can send their runs to a Dask
cluster: ``workers=N`` starts a local cluster of N single-threaded worker processes for
the length of the call, ``scheduler=ADDRESS`` uses a running one.  The driver stays the
only writer and runs are pure functions of their spec, so coverage and overlap are the
same as in-process; each raw json records the worker that ran it.  Here a tiny Table 2
(two methods, one seed) on two local workers, and the same in-process.  Without the
``cluster`` extra (``dask[distributed]``) this example says so and draws nothing else.
The worker processes start by importing this script again, so its work sits under
``if __name__ == "__main__"``.
"""

import importlib.util
import json
import tempfile
from pathlib import Path

import matplotlib.pyplot as plt
import pandas as pd

from compact_distributions.bench.table2 import Table2Request, table2


def main() -> None:
    have_dask = importlib.util.find_spec("distributed") is not None
    root = Path(tempfile.mkdtemp())
    common = dict(
        quick=True, quiet=True, seeds=1, methods=("ours", "ours-fit"), backends=("numpy",), shapes=("square",)
    )
    fig, ax = plt.subplots(figsize=(6, 3.2))
    if not have_dask:
        print("dask[distributed] is not installed: pip install -e '.[cluster]' to run this sweep")
        ax.text(0.5, 0.5, "dask[distributed] is not installed", ha="center", va="center")
        ax.set_axis_off()
        return
    table2(Table2Request(out=root / "cluster", workers=2, **common))
    table2(Table2Request(out=root / "local", **common))
    on_cluster = pd.read_csv(root / "cluster" / "table2.csv")
    in_process = pd.read_csv(root / "local" / "table2.csv")
    same = on_cluster["coverage_mean"].tolist() == in_process["coverage_mean"].tolist()
    print("coverage identical on the cluster and in-process:", same)
    workers = {json.loads(p.read_text()).get("worker") for p in (root / "cluster" / "raw").rglob("*.json")}
    print("runs were made by", sorted(w for w in workers if w))
    x = range(len(on_cluster))
    ax.bar([k - 0.2 for k in x], 100 * on_cluster["coverage_mean"], 0.4, label="2 Dask workers")
    ax.bar([k + 0.2 for k in x], 100 * in_process["coverage_mean"], 0.4, label="in-process")
    ax.set_xticks(list(x), on_cluster["method"])
    ax.set_ylabel("coverage, %")
    ax.set_title("Table 2 (quick, squares, one seed): 2 workers and in-process")
    ax.legend(loc="lower right")
    fig.tight_layout()


if __name__ == "__main__":
    main()
    plt.show()
