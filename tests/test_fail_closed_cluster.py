"""A Dask scheduler lost in the middle of a sweep is an outcome, not a crash: one line
(what was lost, how many runs are stored, how to resume, where Dask's log went), exit
status 1, no traceback and none of distributed's log on the terminal; the stored runs
stay and the same command resumes."""

from __future__ import annotations

import os
import subprocess
import sys
import time
from pathlib import Path

import pytest

from .test_cluster import start_scheduler, start_workers, stop

pytest.importorskip("distributed")

ARGV = ["table2", "--quick", "--backends", "numpy", "--shapes", "square", "--seeds", "2", "--quiet"]


@pytest.mark.slow
def test_a_scheduler_killed_mid_sweep_is_one_line_and_resumable(tmp_path):
    scheduler, address = start_scheduler(tmp_path)
    workers = None
    try:
        workers = start_workers(address, tmp_path, 1)
        out = tmp_path / "report"
        proc = subprocess.Popen(
            [
                sys.executable,
                "-m",
                "compact_distributions.bench.commands.cli",
                *ARGV,
                "--out",
                str(out),
                "--scheduler",
                address,
            ],
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
        )
        raw = out / "raw" / "table2-quick"
        deadline = time.monotonic() + 240
        while len(list(raw.glob("*.json"))) < 2:  # a few runs stored: the sweep is under way
            assert proc.poll() is None and time.monotonic() < deadline, proc.communicate()
            time.sleep(0.2)
        scheduler.kill()
        scheduler.wait(timeout=20)
        _, err = proc.communicate(timeout=240)
        err = err.decode()
    finally:
        if workers is not None:
            stop(workers)
        stop(scheduler)
    # besides the one error line, only the suite's one-line notices (where OpenCL cannot
    # run here, the sweep says it uses NumPy instead)
    lines = [line for line in err.strip().splitlines() if line.strip() and not line.startswith("note: ")]
    assert proc.returncode == 1, err
    assert len(lines) == 1 and "Traceback" not in err and "distributed" not in err.replace(address, ""), err
    line = lines[0]
    assert line.startswith("cvtbench: lost the Dask cluster at") and address in line
    stored = len(list(raw.glob("*.json")))
    assert f"{stored} of " in line and "run the same command again to resume" in line
    log = Path(line.split("Dask's log: ")[1].split(")")[0])
    assert log.exists() and log.stat().st_size > 0
    # the same command in-process resumes: it reads the stored runs back and runs the rest
    env = {**os.environ}
    done = subprocess.run(
        [sys.executable, "-m", "compact_distributions.bench.commands.cli", *ARGV, "--out", str(out)],
        capture_output=True,
        text=True,
        timeout=600,
        env=env,
    )
    assert done.returncode == 0, done.stderr
    assert (
        f"{stored} of" in (out / "table2.md").read_text().split("runs were read back")[0].rsplit(";", 1)[-1]
    )


def test_a_local_cluster_that_cannot_start_is_one_line(tmp_path, monkeypatch, capsys):
    import distributed

    from compact_distributions.bench.commands.cli import main

    def refuse(*args, **kwargs):
        raise OSError("no more processes")

    monkeypatch.setattr(distributed, "LocalCluster", refuse)
    code = main([*ARGV, "--out", str(tmp_path / "r"), "--workers", "2"])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 1 and len(err) == 1, err
    assert "could not start a local Dask cluster of 2 workers (OSError: no more processes" in err[0]


@pytest.mark.slow
def test_every_worker_gone_is_one_outcome(tmp_path):
    import threading

    from distributed import Client

    from compact_distributions.bench import table2
    from compact_distributions.bench.cluster import DaskExecutor
    from compact_distributions.bench.sweep import run_sweep
    from compact_distributions.cvt.errors import RunAborted

    scheduler, address = start_scheduler(tmp_path)
    workers = None
    try:
        workers = start_workers(address, tmp_path, 1)
        specs = table2.problem_set(True, 2, ["ours", "hu2016", "smith2005"], ["numpy"], ["square"])
        raw = tmp_path / "out" / "raw" / "table2-quick"

        def kill_workers_once_runs_are_stored():
            deadline = time.monotonic() + 120
            while len(list(raw.glob("*.json"))) < 1 and time.monotonic() < deadline:
                time.sleep(0.1)
            workers.kill()

        killer = threading.Thread(target=kill_workers_once_runs_are_stored)
        killer.start()
        with Client(address, timeout=10) as client, pytest.raises(RunAborted) as err:
            run_sweep(specs, tmp_path / "out", quiet=True, executor=DaskExecutor(client, worker_wait_s=3))
        killer.join()
    finally:
        if workers is not None:
            stop(workers)
        stop(scheduler)
    text = str(err.value)
    assert "every Dask worker of the cluster at" in text and "none for 3 s" in text
    assert f"{len(list(raw.glob('*.json')))} of {len(specs)} runs are stored" in text
