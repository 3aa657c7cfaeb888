"""Sweeps on a Dask cluster (bench/cluster.py), on loopback only.

The truth is the in-process sweep: a Table 2 sweep on a local cluster (--workers 2), on
a scheduler and workers started as separate processes, and on that cluster while one of
its worker processes is killed, must give the same coverage and overlap, run for run.
Every scheduler and worker started here listens on 127.0.0.1 only (its HTTP server too)
and has a timeout of its own (scheduler idle timeout, worker death timeout) besides the
fixtures' teardown.
"""

from __future__ import annotations

import importlib.util
import json
import os
import shutil
import signal
import socket
import subprocess
import sys
import time
from dataclasses import dataclass
from itertools import pairwise
from pathlib import Path

import pandas as pd
import pytest

from compact_distributions.bench import cluster, table2
from compact_distributions.bench.commands.cli import main
from compact_distributions.bench.sweep import made_by, run_sweep

ROOT = Path(__file__).resolve().parent.parent
needs_dask = pytest.mark.skipif(
    importlib.util.find_spec("distributed") is None,
    reason=f"dask.distributed is not installed ({cluster.EXTRA})",
)

# ours and a fixed-size baseline (with its smaller tile budgets) on squares, NumPy: 8 runs
METHODS, SHAPES, BACKENDS = "ours,fritzsche2005", "square", "numpy"
SWEEP = ["table2", "--quick", "--methods", METHODS, "--shapes", SHAPES, "--backends", BACKENDS, "--quiet"]
SUITE = "table2-quick"


def sweep_specs():
    """The runs of SWEEP, as `cvtbench table2` builds them."""
    return table2.problem_set(True, None, METHODS.split(","), [BACKENDS], [SHAPES])


def stored(out: Path) -> dict[str, dict]:
    """key -> raw json of every run of the sweep under ``out``."""
    return {p.stem: json.loads(p.read_text()) for p in sorted((out / "raw" / SUITE).glob("*.json"))}


def results(out: Path):
    """(per run: key -> (coverage, overlap), the csv's coverage and overlap columns)."""
    runs = {k: (r["row"]["coverage"], r["row"]["overlap"]) for k, r in stored(out).items()}
    csv = pd.read_csv(out / "table2.csv")
    return runs, csv[
        ["method", "backend", "element", "coverage_mean", "coverage_sd", "overlap_mean", "overlap_sd"]
    ]


def assert_same_results(out: Path, truth):
    runs, csv = results(out)
    assert len(runs) == len(sweep_specs()) == len(truth[0])
    assert runs == truth[0]  # exact floats, run for run
    pd.testing.assert_frame_equal(csv, truth[1])


@pytest.fixture(scope="module")
def truth(tmp_path_factory):
    out = tmp_path_factory.mktemp("inprocess")
    assert main(SWEEP + ["--out", str(out)]) == 0
    assert all(r["worker"] == "in-process" for r in stored(out).values())
    return results(out)


# ---------------------------------------------------------------------------------------
# a scheduler and workers as separate processes


def start_scheduler(folder: Path):
    """`dask scheduler` on 127.0.0.1, a free port; (process, address)."""
    file = folder / "scheduler.json"
    proc = subprocess.Popen(
        [
            sys.executable,
            "-m",
            "dask",
            "scheduler",
            "--host",
            "127.0.0.1",
            "--port",
            "0",
            "--dashboard-address",
            "127.0.0.1:0",
            "--no-dashboard",
            "--scheduler-file",
            str(file),
            "--idle-timeout",
            "300",
        ],
        stdout=subprocess.DEVNULL,
        stderr=open(folder / "scheduler.log", "w"),
    )
    deadline = time.monotonic() + 60
    while not file.exists() or not file.read_text().strip():
        if proc.poll() is not None or time.monotonic() > deadline:
            stop(proc)
            pytest.fail(f"dask scheduler did not start: {(folder / 'scheduler.log').read_text()[-2000:]}")
        time.sleep(0.2)
    return proc, json.loads(file.read_text())["address"]


def start_workers(address: str, folder: Path, n: int, env: dict | None = None):
    """`dask worker ADDRESS --nworkers n` with the suite's worker settings; waits for them."""
    from distributed import Client

    env = {**os.environ, "DASK_CONFIG": str(cluster.CONFIG_FILE), **(env or {})}
    proc = subprocess.Popen(
        [
            sys.executable,
            "-m",
            "dask",
            "worker",
            address,
            "--nworkers",
            str(n),
            "--nthreads",
            "1",
            "--host",
            "127.0.0.1",
            "--dashboard-address",
            "127.0.0.1:0",
            "--no-dashboard",
            "--death-timeout",
            "30",
        ],
        stdout=subprocess.DEVNULL,
        stderr=open(folder / "workers.log", "w"),
        env=env,
        # not the repository's root, whose compact_distributions/ folder `python -m` would
        # put ahead of PYTHONPATH
        cwd=folder,
    )
    with Client(address, timeout=10) as client:
        try:
            client.wait_for_workers(n, timeout=90)
        except TimeoutError:
            stop(proc)
            pytest.fail(f"dask workers did not start: {(folder / 'workers.log').read_text()[-2000:]}")
    return proc


def stop(proc):
    """Stop a process this module started (SIGTERM, then SIGKILL after 20 s)."""
    if proc.poll() is None:
        proc.terminate()
        try:
            proc.wait(timeout=20)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait(timeout=10)


@pytest.fixture(scope="module")
def dask_cluster(tmp_path_factory):
    pytest.importorskip("distributed")
    folder = tmp_path_factory.mktemp("dask")
    scheduler, address = start_scheduler(folder)
    workers = None
    try:
        workers = start_workers(address, folder, 2)
        yield address
    finally:
        if workers is not None:
            stop(workers)
        stop(scheduler)


# ---------------------------------------------------------------------------------------
# same results


@needs_dask
@pytest.mark.slow
def test_local_cluster_gives_the_in_process_results(truth, tmp_path):
    assert main(SWEEP + ["--out", str(tmp_path), "--workers", "2"]) == 0
    assert_same_results(tmp_path, truth)
    records = stored(tmp_path).values()
    assert {r["worker"].rsplit(":", 1)[0] for r in records} == {"tcp://127.0.0.1"}
    assert len({r["worker"] for r in records}) == 2  # both workers ran some
    for r in records:
        assert r["host"] == r["row"]["host"] and r["versions"]["numpy"] and r["made_by"] == made_by()
        assert r["row"]["host_slots"] == 2  # two runs shared the host: its time says so
    md = (tmp_path / "table2.md").read_text()
    assert "‡ time taken while up to 2 runs of this sweep shared the host" in md
    assert "| host |" not in md  # one host: no host column


@needs_dask
@pytest.mark.slow
def test_subprocess_cluster_gives_the_in_process_results(truth, dask_cluster, tmp_path):
    assert main(SWEEP + ["--out", str(tmp_path), "--scheduler", dask_cluster]) == 0
    assert_same_results(tmp_path, truth)
    # resumable as in-process: a second run reads every run back
    before = {k: r["worker"] for k, r in stored(tmp_path).items()}
    assert main(SWEEP + ["--out", str(tmp_path), "--scheduler", dask_cluster]) == 0
    assert {k: r["worker"] for k, r in stored(tmp_path).items()} == before
    assert "8 of 8 runs were read back" in (tmp_path / "table2.md").read_text()


@needs_dask
@pytest.mark.slow
def test_killed_worker_costs_a_retry_not_the_sweep(truth, dask_cluster, tmp_path):
    from distributed import Client

    killed = {}

    class KillOnFirstResult(cluster.DaskExecutor):
        """Kills (SIGKILL) a worker process that has runs in hand when the first result is in."""

        def run(self, items, on_start=None):
            for n, result in enumerate(super().run(items, on_start)):
                if n == 0:
                    busy = {w: keys for w, keys in self.client.processing().items() if keys}
                    assert busy, "no worker had a run in hand"
                    address, keys = sorted(busy.items())[0]
                    pid = self.client.run(os.getpid, workers=[address])[address]
                    os.kill(pid, signal.SIGKILL)
                    killed.update(address=address, keys=[str(k) for k in keys])
                yield result

    with Client(dask_cluster, timeout=10) as client:
        rows = run_sweep(sweep_specs(), tmp_path, quiet=True, executor=KillOnFirstResult(client))
    assert [r["status"] for r in rows] == ["ok"] * len(rows)
    runs = {k: (r["row"]["coverage"], r["row"]["overlap"]) for k, r in stored(tmp_path).items()}
    assert runs == truth[0]
    # the runs the dead worker had in hand were finished by another worker
    records = stored(tmp_path)
    lost = [k for k in records if any(key.startswith(f"cvtbench-{k}-") for key in killed["keys"])]
    assert lost and all(records[k]["worker"] != killed["address"] for k in lost)


@needs_dask
@pytest.mark.slow
def test_backend_timings_on_the_cluster(dask_cluster, tmp_path):
    argv = [
        "backends",
        "--quick",
        "--backends",
        "numpy,ckdtree",
        "--metrics",
        "l2",
        "--elements",
        "100",
        "--sizes",
        "64",
        "--quiet",
        "--out",
        str(tmp_path),
        "--scheduler",
        dask_cluster,
    ]
    assert main(argv) == 0
    df = pd.read_csv(tmp_path / "backends.csv")
    assert list(df["status"]) == ["ok", "ok"] and df["host"].nunique() == 1
    raws = [json.loads(p.read_text()) for p in (tmp_path / "raw" / "backends-quick").glob("*.json")]
    assert len(raws) == 2 and all(r["worker"].startswith("tcp://127.0.0.1:") for r in raws)
    assert all(r["row"]["host_slots"] == 1 for r in raws)  # each timing had its host to itself


# ---------------------------------------------------------------------------------------
# refusals


@needs_dask
@pytest.mark.slow
def test_worker_with_other_code_is_refused(tmp_path, capsys):
    """A worker that imports a copy of the package with one file changed."""
    copy = tmp_path / "other" / "compact_distributions"
    for layer in ("cvt", "backends", "baselines", "bench", "samples"):
        shutil.copytree(ROOT / layer, copy / layer, ignore=shutil.ignore_patterns("__pycache__"))
    (copy / "__init__.py").write_text("")
    with open(copy / "cvt" / "__init__.py", "a") as f:
        f.write("# changed\n")
    scheduler, address = start_scheduler(tmp_path)
    workers = None
    try:
        workers = start_workers(address, tmp_path, 1, env={"PYTHONPATH": str(copy.parent)})
        capsys.readouterr()
        assert main(SWEEP + ["--out", str(tmp_path / "out"), "--scheduler", address]) == 2
    finally:
        if workers is not None:
            stop(workers)
        stop(scheduler)
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1, err
    assert (
        err[0].startswith("cvtbench: error: worker tcp://127.0.0.1:")
        and "differs from this process: code " in err[0]
    )
    assert f"(here {made_by()['code']})" in err[0]
    assert not (tmp_path / "out" / "raw").exists()  # refused before any run


def test_differences_name_code_and_versions():
    mine = {"code": "aaaa", "versions": {"numpy": "2.0.0", "scipy": "1.13.0"}}
    assert cluster.differences(mine, mine) == []
    theirs = {"code": "bbbb", "versions": {"numpy": "1.26.4"}}
    assert cluster.differences(mine, theirs) == [
        "code bbbb (here aaaa)",
        "numpy 1.26.4 (here 2.0.0)",
        "scipy missing (here 1.13.0)",
    ]


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


@needs_dask
def test_unreachable_scheduler_is_one_line_and_exit_2(tmp_path, capsys):
    address = f"tcp://127.0.0.1:{free_port()}"  # nothing listens there
    t0 = time.monotonic()
    assert main(SWEEP + ["--out", str(tmp_path), "--scheduler", address]) == 2
    assert time.monotonic() - t0 < cluster.CONNECT_TIMEOUT_S + 10
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith(
        f"cvtbench: error: cannot reach the Dask scheduler at {address}"
    )


@pytest.mark.parametrize("option", [["--scheduler", "tcp://127.0.0.1:8786"], ["--workers", "2"]])
def test_without_the_extra_one_line_names_it(option, tmp_path, capsys, monkeypatch):
    monkeypatch.setitem(sys.modules, "distributed", None)  # import distributed raises ImportError
    for command in (SWEEP, ["backends", "--quick", "--quiet"], ["reproduce", "--quick", "--quiet"]):
        assert main(command + ["--out", str(tmp_path)] + option) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert err == [
            "cvtbench: error: --scheduler and --workers need dask.distributed: "
            "pip install 'compact-distributions[cluster]'"
        ]
    assert not any(tmp_path.iterdir())


def test_scheduler_and_workers_exclude_each_other(tmp_path, capsys):
    assert main(SWEEP + ["--out", str(tmp_path), "--workers", "2", "--scheduler", "tcp://127.0.0.1:1"]) == 2
    assert "--scheduler and --workers exclude each other" in capsys.readouterr().err


# ---------------------------------------------------------------------------------------
# honest timings


@dataclass(frozen=True)
class StampSpec:
    """A run that only notes when it ran, where, and in which process."""

    i: int
    suite: str = "stamp"
    backend: str = "numpy"

    @property
    def key(self) -> str:
        return f"stamp{self.i}"

    def describe(self) -> str:
        return self.key

    def params(self) -> dict:
        return {"i": self.i}

    def execute(self, backend) -> dict:
        start = time.time()
        time.sleep(0.4)
        return {
            "row": {"key": self.key, "status": "ok", "start": start, "end": time.time(), "pid": os.getpid()}
        }


def overlapping(rows) -> int:
    spans = sorted((r["start"], r["end"]) for r in rows)
    return sum(1 for (_, end), (start, _) in pairwise(spans) if start < end)


@needs_dask
@pytest.mark.slow
def test_exclusive_runs_never_share_a_host(tmp_path):
    from distributed import Client

    specs = [StampSpec(i) for i in range(6)]
    with cluster.local_cluster(2) as local, Client(local) as client:
        shared = run_sweep(specs, tmp_path, store=False, quiet=True, executor=cluster.DaskExecutor(client))
        alone = run_sweep(
            specs, tmp_path, store=False, quiet=True, executor=cluster.DaskExecutor(client, exclusive=True)
        )
    for rows in (shared, alone):
        assert [r["status"] for r in rows] == ["ok"] * 6 and len({r["pid"] for r in rows}) == 2
    assert overlapping(shared) > 0  # two worker processes on one host: runs overlap
    assert overlapping(alone) == 0  # exclusive: one at a time on the host
    assert {r["host_slots"] for r in shared} == {2} and {r["host_slots"] for r in alone} == {1}


def test_reports_name_hosts_when_rows_come_from_several():
    from compact_distributions.bench.commands.backends import with_ratios

    rows = [
        {
            "backend": b,
            "metric": "l2",
            "n_elements": 100,
            "size": 64,
            "ms_per_iteration": ms,
            "status": "ok",
            "host": h,
        }
        for b, ms, h in [
            ("numpy", 10.0, "a"),
            ("opencl", 2.0, "a"),
            ("numpy", 20.0, "b"),
            ("ckdtree", 5.0, "c"),
        ]
    ]
    df = with_ratios(rows)
    # NumPy on the same host is the unit; none on host c: no ratio across machines
    assert list(df["x_numpy"].round(6).fillna(-1)) == [1.0, 5.0, 1.0, -1]

    base = {
        "method": "ours",
        "backend": "numpy",
        "element": "square",
        "metric": "linf",
        "width": 64,
        "height": 64,
        "n_elements": 20,
        "iterations": 3,
        "label": "ours",
        "status": "ok",
        "reason": "",
        "device": "cpu",
        "coverage": 0.7,
        "overlap": 0.0,
        "method_seconds": 1.0,
        "lloyd_seconds": 0.5,
        "ms_per_iteration": 3.0,
        "placed": 20,
        "empty_cells": 0,
    }
    table = table2.aggregate(
        [{**base, "seed": 0, "host": "a", "host_slots": 1}, {**base, "seed": 1, "host": "b", "host_slots": 1}]
    )
    assert table.loc[0, "hosts"] == "a, b" and table.loc[0, "host_slots"] == 1
    prov = {"machine": {}, "devices": {}, "versions": {}, "commit": "x", "date": "today"}
    md = table2.render_markdown(table, prov, "cvtbench table2", True, table2.QUICK, 2, 1.0, 0, 2)
    assert "| host |" in md and "| a, b |" in md and "‡" not in md
