"""The sweep engine: many independent runs, stored one raw json each, resumable.

Every sweep of ``cvtbench`` (Tables 2 and 3, the backend timings, the regression checks) is a
list of *specs*.  A spec is a frozen description of one run with

* ``suite`` (the raw/ sub-folder), ``backend`` (a backend variant name), ``key`` (the
  name of its raw json) and ``describe()`` (the progress line),
* ``params()``: the fields of its row when it does not run (skipped or failed),
* ``execute(backend) -> record``: the run itself on a live backend, a pure function of
  the spec; the record is a JSON-ready dict whose ``"row"`` is the run's line in the
  report, and which may carry ``"picture_png"`` (bytes) for an effect picture.

:func:`run_sweep` reads back the runs already stored, hands the others to an *executor*
(the one place where runs are executed: :class:`InProcessExecutor` runs them here, one
after the other, grouped by backend so that one backend is alive at a time;
:class:`.cluster.DaskExecutor` sends them to the workers of a Dask cluster), and stores
each record as it arrives: the driver is the only writer.  Why a file per run: a sweep of
many minutes can be interrupted (Ctrl-C) and resumed, a run whose json exists, made by
the same code on the same host (:func:`made_by`), is read back instead of run again
(``force`` re-runs it), and the report is always made from what is on disk, so it never
mixes two half sweeps.  Each json is written atomically: it exists only when the run
finished.  A backend that cannot start turns its runs into "skipped" rows with the reason,
a run that raises into a "failed" row (no json, so the next sweep retries it).
"""

from __future__ import annotations

import hashlib
import json
import math
import os
import platform
import signal
import sys
import traceback
from collections import deque
from functools import lru_cache
from pathlib import Path

from compact_distributions.cvt.errors import BackendUnavailable, PluginError, RunAborted, exception_line


class BackendCache:
    """Keeps at most one live backend: consecutive runs on the same variant share it (a
    kernel is compiled once), and switching variants closes the old one first (several
    live moderngl contexts would steal each other's current-context state)."""

    def __init__(self):
        self.variant: str | None = None
        self.backend = None

    def get(self, variant: str):
        from compact_distributions.backends import create_backend

        if variant != self.variant:
            self.close()
            self.backend = create_backend(variant)
            self.variant = variant
        return self.backend

    def close(self):
        if self.backend is not None:
            try:
                self.backend.close()
            finally:
                self.backend, self.variant = None, None


def execute(spec, cache: BackendCache, worker: str = "in-process", stage=None) -> tuple[str, object]:
    """Run one spec: ("ok", record), ("skipped", reason) when its backend cannot start,
    or ("failed", reason) when the run raised (one broken run must not sink a sweep).
    The record says where it ran: ``worker`` (a Dask worker's address, a worker
    process, or "in-process") and ``host``, which its row repeats so that reports can
    tell hosts apart.  ``stage(name)``, where given, hears "opening" before a backend is
    started and "running" before the run itself (a worker process tells its driver, so a
    crash is blamed on the backend or on the run)."""
    try:
        if stage is not None and cache.variant != spec.backend:
            cache.close()  # before "opening": a runtime that aborts as it is released is no start's fault
            stage("opening")
        backend = cache.get(spec.backend)
        if stage is not None:
            stage("running")
        record = spec.execute(backend)
        record["worker"], record["host"] = worker, platform.node()
        record["row"]["host"] = record["host"]
        return "ok", record
    except BackendUnavailable as exc:
        return "skipped", str(exc)
    except (KeyboardInterrupt, MemoryError):
        raise
    except PluginError as exc:  # it names the plug-in and what it did: the whole reason
        cache.close()
        return "failed", str(exc)
    except Exception as exc:
        cache.close()  # a failed backend may be in a bad state
        last = traceback.extract_tb(exc.__traceback__)[-1]
        return "failed", f"{type(exc).__name__}: {exc} ({Path(last.filename).name}:{last.lineno})"


class InProcessExecutor:
    """Runs specs here, one after the other, grouped by backend."""

    def run(self, items, on_start=None):
        """Yield (index, (status, value)) for each (index, spec) of ``items``."""
        cache = BackendCache()
        dead: dict[str, str] = {}
        try:
            for i, spec in sorted(items, key=lambda item: (item[1].backend, item[0])):
                if spec.backend in dead:
                    yield i, ("skipped", dead[spec.backend])
                    continue
                if on_start is not None:
                    on_start(spec)
                status, value = execute(spec, cache)
                if status == "skipped":
                    dead[spec.backend] = value
                yield i, (status, value)
        finally:
            cache.close()


# ---------------------------------------------------------------------------------------
# runs that can take their process down


def runs_apart(spec) -> bool:
    """Whether a run could take its process down, and so runs in a worker process: its
    backend's runtime is native code that can abort or crash (OpenCL, GL, any plug-in:
    ``Backend.contained`` is False), or its method is another distribution's code."""
    from compact_distributions.backends import backend_class

    try:
        if not vars(backend_class(spec.backend)).get("contained", False):  # declared by the class itself
            return True
        record = getattr(spec, "method_record", None)
    except Exception:  # a plug-in that does not even load: never here
        return True
    return record is not None and record.foreign


def suspects(spec, starting: bool = False) -> str:
    """What a crash's reason names: the backend (a plug-in with its entry point and
    distribution) where it crashed while ``starting``, else the run's plug-in method
    and plug-in backend, or the backend whose runtime can crash."""
    from compact_distributions.backends import _plugins, plugin_name

    backend = plugin_name(spec.backend) if spec.backend in _plugins() else f"backend {spec.backend!r}"
    if starting:
        return backend
    try:
        record = getattr(spec, "method_record", None)
    except Exception:
        record = None
    names = [record.who] if record is not None and record.foreign else []
    if spec.backend in _plugins() or not names:
        names.append(backend)
    return " on ".join(names)


WORKER = "worker process"  # a record's ``worker`` when it ran in one: "worker process PID"


def serve(inbox: int, outbox: int) -> None:
    """A worker process (``python -c``, see :class:`WorkerProcess`): run the specs the
    driver sends on the pipe ``inbox``, one at a time, on one cached backend (kernels
    compiled once per process), telling it each stage on ``outbox``."""
    from multiprocessing.connection import Connection

    down, up = Connection(inbox, writable=False), Connection(outbox, readable=False)
    cache = BackendCache()
    try:
        while (spec := down.recv()) is not None:
            outcome = execute(spec, cache, f"{WORKER} {os.getpid()}", stage=up.send)
            try:
                up.send(outcome)
            except Exception as exc:  # a record that does not pickle is that run's failure
                up.send(("failed", f"its record could not be sent back: {exception_line(exc)}"))
    except (EOFError, KeyboardInterrupt):  # the driver is gone or interrupted: stop
        pass
    finally:
        cache.close()


def death_text(exitcode: int | None) -> str:
    """How a worker process ended: ``signal SIGSEGV`` or ``exit status 1``."""
    if exitcode is not None and exitcode < 0:
        try:
            return f"signal {signal.Signals(-exitcode).name}"
        except ValueError:
            return f"signal {-exitcode}"
    return f"exit status {exitcode}"


class WorkerProcess:
    """One worker process and the pipes to it.  A fresh interpreter (``python -c``): it
    inherits none of the driver's runtimes (an OpenCL or GL context), and, unlike
    multiprocessing's spawn, never re-imports the caller's main script (a script that
    calls a sweep without a ``__main__`` guard); it sees the driver's ``sys.path``."""

    def __init__(self):
        import subprocess
        from multiprocessing.connection import Connection

        down_r, down_w = os.pipe()
        up_r, up_w = os.pipe()
        path = os.pathsep.join(p for p in sys.path if p)
        env = {**os.environ, "PYTHONPATH": path}
        code = f"from {__name__} import serve; serve({down_r}, {up_w})"
        try:
            self.process = subprocess.Popen(
                [sys.executable, "-c", code], pass_fds=(down_r, up_w), env=env, stdin=subprocess.DEVNULL
            )
        finally:
            os.close(down_r)
            os.close(up_w)  # the driver reads EOF as soon as the worker is gone
        self.conn = Connection(down_w, readable=False)
        self.replies = Connection(up_r, writable=False)

    def run(self, spec) -> tuple[str, tuple | None]:
        """(the stage it reached, (status, value)), the outcome None if the process died."""
        stage = "starting"
        try:
            self.conn.send(spec)
        except OSError:  # gone before it was asked (it died as the last backend was released)
            self.process.wait()
            return stage, None
        while True:
            try:
                message = self.replies.recv()
            except (EOFError, OSError):
                self.process.wait()
                return stage, None
            if isinstance(message, str):
                stage = message
            else:
                return stage, message

    @property
    def ended(self) -> str:
        return death_text(self.process.returncode)

    def stop(self) -> None:
        import subprocess

        try:
            self.conn.send(None)
        except OSError:
            pass
        try:
            self.process.wait(timeout=30)
        except subprocess.TimeoutExpired:
            self.process.kill()
            self.process.wait()
        self.conn.close()
        self.replies.close()


class ProcessExecutor:
    """Runs specs in a worker process, one after the other, grouped by backend (one live
    backend, so its kernels are compiled once per process).  A run that takes the process
    down (a runtime's abort, a plug-in's segfault) is a failed run with the reason, a
    backend that does so as it starts fails its runs, and a fresh process takes the runs
    left."""

    def run(self, items, on_start=None):
        """Yield (index, (status, value)) for each (index, spec) of ``items``."""
        queue = deque(sorted(items, key=lambda item: (item[1].backend, item[0])))
        dead: dict[str, tuple[str, str]] = {}  # variant -> (status, reason) of its runs
        worker = None
        try:
            while queue:
                i, spec = queue.popleft()
                if spec.backend in dead:
                    yield i, dead[spec.backend]
                    continue
                if on_start is not None:
                    on_start(spec)
                worker = worker or WorkerProcess()
                stage, outcome = worker.run(spec)
                if outcome is not None:
                    if outcome[0] == "skipped":
                        dead[spec.backend] = outcome
                    yield i, outcome
                    continue
                ended, worker = worker.ended, None
                if stage == "starting":  # the last backend aborted as it was released: run this one again
                    queue.appendleft((i, spec))
                elif stage == "opening":
                    dead[spec.backend] = (
                        "failed",
                        f"{suspects(spec, starting=True)} took its worker process down as it started ({ended})",
                    )
                    yield i, dead[spec.backend]
                else:
                    yield i, ("failed", f"{suspects(spec)} took its worker process down ({ended})")
        finally:
            if worker is not None:
                worker.stop()


class LocalExecutor:
    """The default executor: runs that cannot take the process down run here
    (:class:`InProcessExecutor`), the others in a worker process
    (:class:`ProcessExecutor`, :func:`runs_apart`), never at the same time."""

    def __init__(self, apart=runs_apart):
        self.apart = apart

    def run(self, items, on_start=None):
        """Yield (index, (status, value)) for each (index, spec) of ``items``."""
        items = list(items)
        apart = [self.apart(spec) for _, spec in items]
        yield from InProcessExecutor().run([x for x, a in zip(items, apart, strict=True) if not a], on_start)
        yield from ProcessExecutor().run([x for x, a in zip(items, apart, strict=True) if a], on_start)


def raw_path(out, spec) -> Path:
    return Path(out) / "raw" / spec.suite / f"{spec.key}.json"


def picture_path(out, spec) -> Path:
    return Path(out) / "raw" / spec.suite / f"{spec.key}.png"


def not_run_row(spec, reason: str, status: str = "skipped") -> dict:
    return {"key": spec.key, **spec.params(), "status": status, "reason": reason}


def run_sweep(
    specs: list,
    out,
    *,
    force: bool = False,
    store: bool = True,
    quiet: bool = False,
    unavailable: dict[str, str] | None = None,
    executor=None,
) -> list[dict]:
    """Run every spec (stored raw json read back unless ``force``) and return the rows in
    the order of ``specs``.  ``unavailable`` maps a backend variant to the reason it
    cannot run.  ``store=False`` (regression checks) neither reads nor writes raw json.
    Ctrl-C stops the sweep; finished runs stay on disk, so the same command resumes."""
    from tqdm import tqdm

    from .outputs import atomic_write

    unavailable = unavailable or {}
    rows: dict[int, dict] = {}
    pending = []
    for i, spec in enumerate(specs):
        if spec.backend in unavailable:
            rows[i] = not_run_row(spec, unavailable[spec.backend])
        elif store and not force and (stored := read_stored(raw_path(out, spec))) is not None:
            rows[i] = {**stored, "cached": True}
        else:
            pending.append((i, spec))
    executor = executor or LocalExecutor()
    bar = tqdm(
        total=len(specs),
        initial=len(specs) - len(pending),
        desc="runs",
        unit="run",
        disable=quiet,
        file=sys.stderr,
        dynamic_ncols=True,
        mininterval=0.5,
    )
    try:
        for i, (status, value) in executor.run(pending, on_start=lambda s: bar.set_postfix_str(s.describe())):
            spec = specs[i]
            if status != "ok":
                rows[i] = not_run_row(spec, value, status)
            else:
                picture = value.pop("picture_png", None)
                rows[i] = value["row"]
                if store:
                    if picture is not None:
                        atomic_write(picture_path(out, spec), picture)
                    write_stored(raw_path(out, spec), value)
            bar.update(1)
    except RunAborted as exc:
        done = sum(1 for r in rows.values() if r.get("status") == "ok")
        raise RunAborted(
            f"{exc}; {done} of {len(specs)} runs are stored under {Path(out) / 'raw'}: run the same "
            "command again to resume (without --scheduler/--workers it runs here)"
        ) from None
    except KeyboardInterrupt:
        done = sum(1 for r in rows.values() if r.get("status") == "ok")
        print(
            f"\ninterrupted: {done} of {len(specs)} runs are stored under {Path(out) / 'raw'}; "
            "run the same command again to resume",
            file=sys.stderr,
        )
        raise
    finally:
        bar.close()
    return [rows[i] for i in range(len(specs))]


class RunsFailed(RunAborted):
    """Runs of a sweep failed: its report is written, the failed rows marked; the command
    ends with one line naming them and exits with status 1.  ``rows``: the sweep's rows."""

    def __init__(self, message: str, rows: list[dict]):
        super().__init__(message)
        self.rows = rows


def check_runs(specs: list, rows: list[dict], command: str) -> None:
    """RunsFailed naming the first failed run of a sweep and why (and how many more), if
    any failed; skipped runs (a backend not on this machine) are no failure."""
    failed = [(spec, row) for spec, row in zip(specs, rows, strict=True) if row.get("status") == "failed"]
    if not failed:
        return
    spec, row = failed[0]
    more = f"; {len(failed) - 1} more failed (the report lists them)" if len(failed) > 1 else ""
    raise RunsFailed(
        f"{command}: {len(failed)} of {len(rows)} runs failed: {spec.describe()}: {row.get('reason')}{more}",
        rows,
    )


@lru_cache(maxsize=1)
def made_by() -> dict:
    """What a stored run must share with this process to be read back instead of re-run:
    the same source code (a hash of every .py and .cl file of the four packages) on the
    same host.  So a sweep resumes after Ctrl-C, but a fresh clone, a code change or
    another machine computes its own figures instead of reusing committed ones."""
    root = Path(__file__).resolve().parent.parent
    digest = hashlib.sha1()
    for pkg in ("cvt", "backends", "baselines", "bench"):
        for f in sorted((root / pkg).rglob("*")):
            if f.suffix in (".py", ".cl") and f.is_file():
                digest.update(f.relative_to(root).as_posix().encode() + b"\0" + f.read_bytes())
    return {"code": digest.hexdigest()[:16], "host": platform.node()}


STORED_MAX_BYTES = 256 * 2**20


def read_stored(path: Path) -> dict | None:
    """The row of a stored run, or None when there is none, it is unreadable, other code
    or another host made it, or a figure of it is not finite (then the caller runs it
    again: a stored NaN is no result)."""
    try:
        if Path(path).stat().st_size > STORED_MAX_BYTES:  # sized before it is read: no run stores that much
            return None
        stored = json.loads(Path(path).read_text())
        row = stored["row"] if stored.get("made_by") == made_by() else None
    except (OSError, ValueError, KeyError, TypeError, AttributeError):
        return None
    if not isinstance(row, dict) or any(isinstance(v, float) and not math.isfinite(v) for v in row.values()):
        return None
    return row


def write_stored(path: Path, record: dict) -> None:
    """Store a run's record (with its :func:`made_by`) atomically."""
    from .outputs import atomic_write, dumps

    atomic_write(path, dumps({**record, "made_by": made_by()}))


# ---------------------------------------------------------------------------------------
# memory


def memory_class(variant: str):
    """The backend class of ``variant`` for memory estimates (the base class's figures
    when its runtime is missing: its runs are skipped anyway)."""
    from compact_distributions.backends import Backend, backend_class

    try:
        return backend_class(variant)
    except BackendUnavailable:
        return Backend


def check_memory(specs: list, limit=None, lower: str = "leave it out", name: str = "--memory-limit") -> None:
    """Refuse a sweep, before any run, when one of its specs (``spec.memory_estimate()``)
    needs more memory than the limit (:mod:`compact_distributions.cvt.resources`)."""
    if not specs:
        return
    estimates = [spec.memory_estimate() for spec in specs]
    worst = max(range(len(specs)), key=lambda i: estimates[i].total)
    estimates[worst].check(limit, lower=lower, name=name)


__all__ = [
    "BackendCache",
    "execute",
    "InProcessExecutor",
    "runs_apart",
    "suspects",
    "WORKER",
    "serve",
    "death_text",
    "WorkerProcess",
    "ProcessExecutor",
    "LocalExecutor",
    "raw_path",
    "picture_path",
    "not_run_row",
    "run_sweep",
    "RunsFailed",
    "check_runs",
    "made_by",
    "STORED_MAX_BYTES",
    "read_stored",
    "write_stored",
    "memory_class",
    "check_memory",
]
