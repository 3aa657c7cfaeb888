"""Sweeps on a Dask cluster: an executor for :func:`.sweep.run_sweep` built on
``dask.distributed`` (``pip install 'compact-distributions[cluster]'``).

``--scheduler tcp://HOST:PORT`` sends a sweep's runs to a running Dask cluster,
``--workers N`` starts a ``distributed.LocalCluster`` of N worker processes on loopback
for the length of the command; with neither, runs go in-process as before.

* Dask does the distributing: ``Client.submit`` per run, results as they complete, a run
  whose worker dies is rescheduled on another worker by the scheduler (up to its
  ``allowed-failures``), a run that raises is retried once.  Results come back to the
  driver, which stays the only writer of raw json and reports.
* Same code everywhere: before the first run the driver asks every worker for its code
  fingerprint (:func:`.sweep.made_by`) and package versions and refuses a mismatch with
  one line; each run checks again on its worker (for workers that join later).
* One run at a time per worker process, on one thread that owns the process's one live
  backend (GL and OpenCL contexts belong to the thread that made them).
* Worker settings (``dask.yaml`` beside this module): Dask's memory-trim setting and its
  profiler made a NumPy Lloyd iteration 2.9x slower on a worker than in-process; the local
  cluster turns both off, workers of your own read the file through ``DASK_CONFIG``
  (``python -m compact_distributions.bench.cluster`` prints its path), and the driver warns
  about a worker that runs with either.
* Timings: with ``exclusive`` (``cvtbench backends`` always, ``table2 --exclusive``) a host
  runs one run of the sweep at a time and nothing else of it; otherwise each row records
  ``host_slots``, the number of worker processes on its host, so a report can tell times
  taken while other runs shared the host.
"""

from __future__ import annotations

import logging
import os
import platform
import sys
import tempfile
import time
import uuid
from collections import deque
from contextlib import contextmanager
from functools import lru_cache
from pathlib import Path

from compact_distributions.cvt.errors import InputError, RunAborted, exception_line
from compact_distributions.cvt.validate import whole_number

from .outputs import versions
from .sweep import BackendCache, execute, made_by

EXTRA = "pip install 'compact-distributions[cluster]'"
CONNECT_TIMEOUT_S = 5  # an unreachable scheduler is an input error, not a long hang
WORKER_WAIT_S = 60  # a new cluster's workers (dask-jobqueue, Kubernetes) may take a while to join
POLL_S = 2.0  # how often an exclusive sweep looks for hosts that came or went
CONFIG_FILE = Path(__file__).with_name("dask.yaml")


def require_distributed():
    """The ``distributed`` module, or InputError naming the extra to install."""
    try:
        import distributed
    except ImportError:
        raise InputError(f"--scheduler and --workers need dask.distributed: {EXTRA}") from None
    return distributed


@lru_cache(maxsize=1)
def identity() -> dict:
    """What every process of a sweep must share: the code fingerprint and the versions of
    the packages (with Dask's own), plus the host for messages."""
    import dask
    import distributed

    return {
        "code": made_by()["code"],
        "host": platform.node(),
        "versions": {**versions(), "dask": dask.__version__, "distributed": distributed.__version__},
        "slow_settings": slow_settings(),
    }


def slow_settings() -> list[str]:
    """The settings of this process that :data:`CONFIG_FILE` turns off, where they are on."""
    import dask

    found = (
        [f"MALLOC_TRIM_THRESHOLD_={os.environ['MALLOC_TRIM_THRESHOLD_']}"]
        if "MALLOC_TRIM_THRESHOLD_" in os.environ
        else []
    )
    if dask.config.get("distributed.worker.profile.enabled", False):
        found.append("the Dask profiler")
    return found


def worker_config() -> dict:
    """:data:`CONFIG_FILE` as dotted keys for ``dask.config.set``."""
    import yaml

    def dotted(tree, prefix=""):
        for key, value in tree.items():
            if isinstance(value, dict) and value:
                yield from dotted(value, f"{prefix}{key}.")
            else:
                yield f"{prefix}{key}", value

    return dict(dotted(yaml.safe_load(CONFIG_FILE.read_text())))


def differences(mine: dict, theirs: dict) -> list[str]:
    """What differs between two :func:`identity` dicts, as 'what theirs (here mine)'."""
    out = []
    if theirs.get("code") != mine["code"]:
        out.append(f"code {theirs.get('code')} (here {mine['code']})")
    a, b = mine["versions"], theirs.get("versions", {})
    for name in sorted(set(a) | set(b)):
        if a.get(name) != b.get(name):
            out.append(f"{name} {b.get(name, 'missing')} (here {a.get(name, 'missing')})")
    return out


def check_workers(client, mine: dict) -> dict:
    """Every worker's identity; InputError naming the first worker that differs.  A worker
    with a setting that slows runs down gets a warning (its results are still right)."""
    found = client.run(identity, on_error="return")
    for address, theirs in sorted(found.items()):
        if isinstance(theirs, BaseException):
            raise InputError(f"worker {address} cannot run the suite: {exception_line(theirs)}")
        diff = differences(mine, theirs)
        if diff:
            raise InputError(
                f"worker {address} on {theirs.get('host')} differs from this process: " + "; ".join(diff)
            )
    slow = {
        address: theirs["slow_settings"] for address, theirs in found.items() if theirs.get("slow_settings")
    }
    if slow:
        address, what = sorted(slow.items())[0]
        print(
            f"cvtbench: warning: {len(slow)} worker(s), e.g. {address}, run with {' and '.join(what)}, which "
            f"slow runs down; start workers with DASK_CONFIG={CONFIG_FILE}",
            file=sys.stderr,
        )
    return found


# ------------------------------------------------------------------ on a worker
_CACHE: BackendCache | None = None
_THREAD = None


def run_spec(spec, expected: dict):
    """Run one spec on this worker (the task Dask runs): (status, value) as
    :func:`.sweep.execute`, the record stamped with this worker's address."""
    global _CACHE, _THREAD
    from concurrent.futures import ThreadPoolExecutor

    from distributed import get_worker

    address = get_worker().address
    diff = differences(expected, identity())
    if diff:
        return "failed", f"worker {address} differs from the driver: " + "; ".join(diff)
    if _THREAD is None:
        # one thread owns the process's backend: its device context stays on that thread,
        # and runs of this process go one after the other, whatever the worker's nthreads
        _THREAD = ThreadPoolExecutor(max_workers=1, thread_name_prefix="cvtbench-backend")
        _CACHE = BackendCache()
    return _THREAD.submit(execute, spec, _CACHE, address).result()


# ------------------------------------------------------------------ on the driver
class DaskExecutor:
    """Runs specs on the workers of a ``distributed.Client`` (see the module docstring)."""

    def __init__(self, client, exclusive: bool = False, worker_wait_s: float = WORKER_WAIT_S):
        self.client = client
        self.exclusive = exclusive
        self.worker_wait_s = worker_wait_s  # how long the sweep waits for a worker when none is left
        self.slots: dict[str, int] = {}  # host -> most worker processes seen on it

    def hosts(self) -> dict[str, int]:
        """host -> worker processes on it now (and remember the most seen)."""
        now: dict[str, int] = {}
        for info in self.client.scheduler_info()["workers"].values():
            now[info["host"]] = now.get(info["host"], 0) + 1
        for host, n in now.items():
            self.slots[host] = max(n, self.slots.get(host, 0))
        return now

    def run(self, items, on_start=None):
        """Yield (index, (status, value)) for each (index, spec) of ``items`` as runs finish."""
        from distributed import wait

        if not items:
            return
        mine = identity()
        check_workers(self.client, mine)
        self.hosts()
        queue = deque(sorted(items, key=lambda item: (item[1].backend, item[0])))
        pending: dict = {}  # future -> (index, spec, the host it is pinned to or None)

        def submit(i, spec, host=None):
            future = self.client.submit(
                run_spec,
                spec,
                mine,
                key=f"cvtbench-{spec.key}-{uuid.uuid4().hex[:8]}",
                pure=False,
                retries=1,
                workers=[host] if host else None,
                allow_other_workers=False,
            )
            pending[future] = (i, spec, host)

        try:
            yield from self._run(queue, pending, submit, on_start, wait)
        except (KeyboardInterrupt, MemoryError):
            raise
        except Exception as exc:
            if self.lost():
                raise RunAborted(
                    f"lost the Dask cluster at {self.address} in the middle of the sweep "
                    f"({exception_line(exc)}; Dask's log: {log_file()})"
                ) from None
            raise
        finally:
            if pending and not self.lost():
                self.client.cancel(list(pending))

    def check_workers_left(self) -> None:
        """RunAborted once the cluster has had no worker for WORKER_WAIT_S: the runs left
        would wait for ever."""
        if self.client.scheduler_info()["workers"]:
            self._no_worker_since = None
            return
        now = time.monotonic()
        self._no_worker_since = getattr(self, "_no_worker_since", None) or now
        if now - self._no_worker_since > self.worker_wait_s:
            raise RunAborted(
                f"every Dask worker of the cluster at {self.address} is gone (none for "
                f"{self.worker_wait_s:g} s; Dask's log: {log_file()})"
            )

    def lost(self) -> bool:
        """Whether the scheduler is gone (the client no longer runs, or cannot reach it)."""
        if self.client.status != "running":
            return True
        try:
            self.client.scheduler_info()
        except Exception:
            return True
        return False

    @property
    def address(self) -> str:
        try:
            return self.client.scheduler.address
        except Exception:
            return "?"

    def _run(self, queue, pending, submit, on_start, wait):
        if not self.exclusive:
            while queue:
                submit(*queue.popleft())
        while pending or queue:
            if self.exclusive:
                yield from self._dispatch_exclusive(queue, pending, submit)
                if not pending:
                    continue
            if on_start is not None:  # the oldest run not finished: most likely one in hand
                on_start(next(iter(pending.values()))[1])
            try:
                done, _ = wait(list(pending), timeout=POLL_S, return_when="FIRST_COMPLETED")
            except TimeoutError:
                self.check_workers_left()
                continue
            for future in done:
                i, spec, _ = pending.pop(future)
                if future.status == "cancelled" and self.lost():
                    raise RunAborted("the scheduler cancelled the runs")
                yield i, self.outcome(future)

    def _dispatch_exclusive(self, queue, pending, submit):
        """Give each host without a run of this sweep the next queued run, pinned to that
        host; runs pinned to a host that lost all its workers go back to the queue.  When
        no worker is left at all, wait for one; after WORKER_WAIT_S the rest fail."""
        hosts = self.hosts()
        for future, (i, spec, host) in list(pending.items()):
            if host not in hosts:
                future.cancel()
                del pending[future]
                queue.appendleft((i, spec))
        if not hosts and not pending:
            try:
                self.client.wait_for_workers(1, timeout=WORKER_WAIT_S)
            except TimeoutError:
                while queue:
                    i, _ = queue.popleft()
                    yield i, ("failed", f"no Dask worker left (waited {WORKER_WAIT_S} s)")
            return
        busy = {host for (_, _, host) in pending.values()}
        for host in hosts:
            if host not in busy and queue:
                submit(*queue.popleft(), host=host)

    def outcome(self, future) -> tuple[str, object]:
        """(status, value) of a finished future; a run the cluster lost is 'failed' (not
        stored, so the next sweep retries it)."""
        from distributed.comm import get_address_host

        if future.status == "finished":
            status, value = future.result()
            if status == "ok":
                host = get_address_host(value["worker"])
                value["row"]["host_slots"] = 1 if self.exclusive else self.slots.get(host, 1)
            return status, value
        if future.status == "error":
            return "failed", exception_line(future.exception())
        return "failed", f"the cluster lost the run ({future.status})"


def log_file() -> Path:
    """Where Dask's own log of this process goes (named when a cluster is lost)."""
    return Path(tempfile.gettempdir()) / f"cvtbench-dask-{os.getpid()}.log"


def _quiet_logs() -> None:
    """Dask's own log lines (a worker lost and replaced, a comm closed, a scheduler gone)
    go to :func:`log_file`, not the terminal: they would break the progress bar, and a
    lost cluster is said in one line of the suite's own."""
    handler = logging.FileHandler(log_file(), delay=True)
    handler.setFormatter(logging.Formatter("%(asctime)s %(name)s %(levelname)s %(message)s"))
    names = {"distributed", "dask", "tornado", "asyncio"}
    names |= {n for n in logging.root.manager.loggerDict if n.split(".")[0] in names}
    for name in sorted(names):
        logger = logging.getLogger(name)
        for old in list(logger.handlers):
            if isinstance(old, logging.StreamHandler) and not isinstance(old, logging.FileHandler):
                logger.removeHandler(old)
        if not any(
            isinstance(h, logging.FileHandler) and h.baseFilename == handler.baseFilename
            for h in logger.handlers
        ):
            logger.addHandler(handler)
        logger.setLevel(logging.INFO)
        logger.propagate = False


# ------------------------------------------------------------------ options
def chosen(args) -> tuple[str | None, int | None]:
    """(scheduler address, local worker count) from --scheduler / --workers, checked."""
    scheduler, workers = getattr(args, "scheduler", None), getattr(args, "workers", None)
    if scheduler is None and workers is None:
        return None, None
    if scheduler is not None and workers is not None:
        raise InputError(
            "--scheduler and --workers exclude each other: --workers N starts a local cluster, "
            "--scheduler ADDRESS uses a running one"
        )
    require_distributed()
    return scheduler, None if workers is None else whole_number(workers, "--workers", minimum=1)


@contextmanager
def local_cluster(n_workers: int):
    """A ``distributed.LocalCluster`` of ``n_workers`` single-threaded worker processes on
    loopback (no dashboard), closed on exit."""
    import dask
    from distributed import LocalCluster

    _quiet_logs()
    with dask.config.set(worker_config()):
        try:
            cluster = LocalCluster(
                n_workers=n_workers,
                threads_per_worker=1,
                processes=True,
                host="127.0.0.1",
                scheduler_port=0,
                dashboard_address="127.0.0.1:0",
                silence_logs=logging.ERROR,
            )
        except Exception as exc:  # no process could start, no port, no memory: an outcome, not a crash
            raise RunAborted(
                f"could not start a local Dask cluster of {n_workers} workers ({exception_line(exc)}; "
                f"Dask's log: {log_file()}); run without --workers to run here"
            ) from None
        with cluster:
            yield cluster


@contextmanager
def scheduler_address(args):
    """The address of the cluster the options name: --scheduler's, or that of a local
    cluster of --workers processes started for the block; None for in-process."""
    scheduler, workers = chosen(args)
    if workers is None:
        yield scheduler
    else:
        with local_cluster(workers) as cluster:
            yield cluster.scheduler_address


@contextmanager
def connect(address: str):
    """A ``distributed.Client`` of the scheduler at ``address`` with at least one worker;
    InputError (one line) when it cannot be reached within CONNECT_TIMEOUT_S or no worker
    joins within WORKER_WAIT_S."""
    from distributed import Client

    _quiet_logs()
    try:
        client = Client(address, timeout=CONNECT_TIMEOUT_S)
    except (OSError, TimeoutError, ValueError) as exc:
        raise InputError(f"cannot reach the Dask scheduler at {address}: {exception_line(exc)}") from None
    with client:
        if not client.scheduler_info()["workers"]:
            try:
                client.wait_for_workers(1, timeout=WORKER_WAIT_S)
            except TimeoutError:
                raise InputError(
                    f"no Dask worker joined the scheduler at {address} within {WORKER_WAIT_S} s "
                    f"(start one with: dask worker {address})"
                ) from None
        yield client


@contextmanager
def executor_for(args, *, exclusive: bool = False):
    """The sweep executor the options ask for: a :class:`DaskExecutor` on --scheduler's
    cluster or on a local cluster of --workers processes, or None (in-process)."""
    with scheduler_address(args) as address:
        if address is None:
            yield None
        else:
            with connect(address) as client:
                yield DaskExecutor(client, exclusive=exclusive)


__all__ = [
    "EXTRA",
    "CONNECT_TIMEOUT_S",
    "WORKER_WAIT_S",
    "POLL_S",
    "CONFIG_FILE",
    "require_distributed",
    "identity",
    "slow_settings",
    "worker_config",
    "differences",
    "check_workers",
    "run_spec",
    "DaskExecutor",
    "log_file",
    "chosen",
    "local_cluster",
    "scheduler_address",
    "connect",
    "executor_for",
]


if __name__ == "__main__":  # the worker settings file, for DASK_CONFIG
    print(CONFIG_FILE)
