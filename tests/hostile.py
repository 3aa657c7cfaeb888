"""Helpers for the robustness tests: files a careless or hostile user might hand over, and
running the command line in a child process whose memory is capped and measured."""

from __future__ import annotations

import os
import resource
import shutil
import struct
import subprocess
import sys
import tempfile
import threading
import time
import zlib
from pathlib import Path

CLI = [sys.executable, "-m", "compact_distributions.bench.commands.cli"]
CAP = 4 * 2**30  # address space of a child: a regression fails the test, not the machine


def _chunk(kind: bytes, data: bytes) -> bytes:
    return (
        struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data) & 0xFFFFFFFF)
    )


def blank_png(path: Path, width: int, height: int, rgb: bool = False) -> Path:
    """A valid PNG of zeros written row by row: a file of a few hundred kB that declares a
    picture of any size (a decompression bomb when large)."""
    comp = zlib.compressobj(9)
    row = b"\0" + bytes(width * (3 if rgb else 1))
    idat = b"".join(comp.compress(row) for _ in range(height)) + comp.flush()
    header = struct.pack(">IIBBBBB", width, height, 8, 2 if rgb else 0, 0, 0, 0)
    path.write_bytes(
        b"\x89PNG\r\n\x1a\n" + _chunk(b"IHDR", header) + _chunk(b"IDAT", idat) + _chunk(b"IEND", b"")
    )
    return path


def _cap():
    resource.setrlimit(resource.RLIMIT_AS, (CAP, CAP))


def run_measured(argv, cwd=None, env=None, timeout=300):
    """(exit status, stderr, peak resident MB, seconds) of ``cvtbench ARGV`` in a child
    process with capped address space.  The peak is the child's own after exec (VmHWM,
    which the child reports as it exits): the rusage of a forked child also counts the
    pages of this process it shared before exec.  A child killed before it reports falls
    back to that rusage."""
    from compact_distributions.bench.commands.pipeline import PEAK_LAUNCHER

    report = Path(tempfile.mkdtemp(prefix="hostile-peak-")) / "peak_kb"
    t0 = time.perf_counter()
    proc = subprocess.Popen(
        [sys.executable, "-c", PEAK_LAUNCHER, str(report), *CLI[1:], *[str(a) for a in argv]],
        cwd=cwd,
        env={**os.environ, **(env or {})},
        stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE,
        preexec_fn=_cap,
    )
    err = []
    reader = threading.Thread(target=lambda: err.append(proc.stderr.read()))
    reader.start()
    deadline = time.monotonic() + timeout
    while True:
        pid, status, usage = os.wait4(proc.pid, os.WNOHANG)
        if pid:
            break
        if time.monotonic() > deadline:
            proc.kill()
            pid, status, usage = os.wait4(proc.pid, 0)
            break
        time.sleep(0.05)
    reader.join()
    proc.stderr.close()
    proc.returncode = os.waitstatus_to_exitcode(status)  # reaped here, not by Popen
    peak_kb = int(report.read_text()) if report.exists() else usage.ru_maxrss
    shutil.rmtree(report.parent, ignore_errors=True)
    return (
        proc.returncode,
        b"".join(err).decode(errors="replace"),
        peak_kb / 1024,
        time.perf_counter() - t0,
    )
