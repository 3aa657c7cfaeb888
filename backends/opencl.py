"""The OpenCL backend: one work-item per pixel, nearest site by a ring search over a grid.

Each call the host (NumPy) folds angles and scales into per-site coefficients with
:func:`cvt.metrics.compile_sites` (the one definition of every metric: the kernel never
re-types a shape), buckets the sites into a uniform grid of cells about one average
spacing wide, and uploads them sorted by cell.  The kernel (``opencl_kernels.cl``)
searches the cells around each pixel ring by ring and stops once the next ring cannot
hold a nearer site; the bound ``|x - p_i| <= circumradius · s_max · d_i(x)`` holds for
every angle, scale and aspect, so the result is exact (up to float32) and the cost per
pixel does not grow with N.

:meth:`OpenCLBackend.moments` also sums the moments on the device, added with atomics,
so a Lloyd iteration reads back 5·N integers, not the raster; :meth:`OpenCLBackend.label`
reads the raster.  The block kernel sums its own block once per label in it as it writes
the labels; after the per-pixel kernel, ``row_moments`` sums runs of equal labels per row
segment.

:meth:`OpenCLBackend.walled_moments` (the walled step of a mosaic) also cuts each cell to
the one 4-connected piece that :func:`cvt.mosaic.split_cells` keeps, on the device: the
runs of the cells that may be in pieces are listed and joined into pieces by a
union-find, and the sums of the pieces not kept are taken from their cells' sums: the
host reads back 5·N sums, as for the unwalled step.

Two label kernels, the same search: ``label_blocks`` (one work-item per ``STRIP`` square
blocks of 4, 8 or 16 px side by side in a row; the default on CPUs, where PoCL vectorises
its inner loop over a block's pixels) and ``label_pixels`` (one work-item per pixel; the
default on GPUs).

Device choice, first that applies: the ``device`` option ("PLATFORM[:DEVICE]", indices
or name fragments, as ``cvtbench run --device``), the ``PYOPENCL_CTX`` environment
variable (same syntax), else the first GPU, else the first CPU device, else any device.
A device is used only once a child process has built every program the backend builds
on it (with their kernels, also when read back from the runtime's kernel cache) and run
them on a small problem of each ball against the NumPy reference (:func:`check_device`;
the verdict is kept under the user's cache folder, so this costs once per device,
driver, configuration and kernel source): a runtime that aborts or crashes then takes
down the child, not the process.  A device that fails is passed over, or, when named,
refused with the reason and what to install.  Nothing is ever asked interactively.
"""

from __future__ import annotations

import hashlib
import itertools
import json
import math
import os
import signal
import subprocess
import sys
import time
import warnings
from contextlib import nullcontext
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from compact_distributions.cvt.errors import BackendUnavailable, InputError
from compact_distributions.cvt.metrics import Depth, Metric, compile_sites
from compact_distributions.cvt.moments import Moments
from compact_distributions.cvt.pixels import pixel_index
from compact_distributions.cvt.problem import Grid
from compact_distributions.cvt.quiet import c_output_silenced

from .base import Backend

KERNEL_FILE = Path(__file__).with_name("opencl_kernels.cl")
SEGMENT = 64  # pixels of a row per work-item of the moments kernel
# work-group of the walled-cell kernels (a row or a cell per work-item), fixed: PoCL
# builds a kernel anew for each work-group size it is left to choose
WALL_GROUP = 16
WALL_KERNELS = (
    "row_runs",
    "suspect_cells",
    "suspect_runs",
    "pieces_join",
    "pieces_site",
    "pieces_dropped",
    "pieces_homeless",
)
ACC_BYTES = 64  # per site: five 64-bit sums in one cache line (the kernel file says why)
STRIP = 4  # blocks side by side per work-item of label_blocks: they share their sums
BLOCK_SIZES = (0, 4, 8, 16)  # label_blocks works a row of a block as one 4-, 8- or 16-wide vector
# label_blocks' default work-group: PoCL holds the private arrays of all of a group's
# work-items at once, and its own choice (thousands of them) overflowed a thread's stack
BLOCK_GROUP = (8, 1)
REACH_MARGIN = 1e-4  # relative slack on the search bound against float32 rounding


def _facet_count(metric: Metric) -> int:
    """K of the kernels built for ``metric`` (0: an ellipse)."""
    return 0 if metric.curved else np.asarray(metric.normals).shape[0]


def block_mask_words(mask: np.ndarray, block: int) -> np.ndarray:
    """``mask`` (H, W) bool as label_blocks reads it: a bit per pixel, one 16-bit word
    per row of each ``block`` x ``block`` block, the blocks in raster order and a block's
    words top to bottom; bit x of a word is the pixel x columns from the block's left
    edge, and pixels off the raster are 0."""
    h, w = mask.shape
    rows, cols = -(-h // block), -(-w // block)
    padded = np.zeros((rows * block, cols * block), dtype=np.uint16)
    padded[:h, :w] = mask
    blocks = padded.reshape(rows, block, cols, block).transpose(0, 2, 1, 3)
    return np.ascontiguousarray(blocks @ (np.uint16(1) << np.arange(block, dtype=np.uint16)))


def _bits_row_bytes(width: int) -> int:
    """Bytes a row of ``width`` pixels takes in ``below_bits``: a bit per pixel, in whole
    64-bit words (row_runs' windows); the label kernel and row_runs both take it."""
    return 8 * -(-width // 64)


def _near(last, raster: tuple, sites: np.ndarray, reach: float) -> bool:
    """Whether ``last`` ((raster, sites) of the last labels) is of ``raster`` and of as
    many sites, none of which has moved more than ``reach`` pixels in x or y."""
    if last is None or last[0] != raster or last[1].shape != sites.shape:
        return False
    return bool(np.abs(sites - last[1]).max(initial=0.0) <= reach)


def _site_grid(sites, spacing: float, w: int, h: int):
    """The uniform grid of the label search: cells of about ``spacing`` px (about one
    site each over the region); returns the cell side, the cells across and down, the
    sites in cell order and where each cell's sites start."""
    # float32-exact, so the host's buckets and the kernel's cell edges agree
    cell = float(np.float32(max(1.0, spacing)))
    ncx, ncy = max(1, math.ceil(w / cell)), max(1, math.ceil(h / cell))
    cx = np.clip(np.floor(sites[:, 0] / cell), 0, ncx - 1).astype(np.int64)
    cy = np.clip(np.floor(sites[:, 1] / cell), 0, ncy - 1).astype(np.int64)
    cid = cy * ncx + cx
    # stable, so a cell's sites stay in index order; 16-bit keys get numpy's radix sort
    key_type = np.uint16 if ncx * ncy <= 65535 else np.int32
    order = np.argsort(cid.astype(key_type), kind="stable")
    starts = np.zeros(ncx * ncy + 1, dtype=np.int32)
    np.cumsum(np.bincount(cid, minlength=ncx * ncy), out=starts[1:])
    return cell, ncx, ncy, order, starts


def _fit_key(ellipse: bool, k: int) -> tuple:
    """The key of the program that holds the fit kernel for a ball kind and facet count
    (an ellipse's fit uses no K)."""
    return ("fit", True) if ellipse else ("fit", False, k)


def _import_pyopencl():
    try:
        import pyopencl as cl
    except ImportError as exc:  # pyopencl missing, or its native library fails to load
        raise BackendUnavailable(
            f"opencl: pyopencl is not importable ({exc}); install the 'opencl' extra "
            "(pip install 'compact-distributions[opencl]')"
        ) from None
    return cl


def pocl_cache_dir() -> str:
    """Where PoCL keeps its kernel cache: POCL_CACHE_DIR, else under XDG_CACHE_HOME or
    ~/.cache.  PoCL offers no device at all when it cannot make this folder."""
    if os.environ.get("POCL_CACHE_DIR"):
        return os.environ["POCL_CACHE_DIR"]
    return os.path.join(_user_cache(), "pocl", "kcache")


def cache_problem() -> str | None:
    """Why the kernel cache cannot be written, or None: said instead of "no device"."""
    import tempfile

    path = pocl_cache_dir()
    try:
        os.makedirs(path, exist_ok=True)
        tempfile.TemporaryFile(dir=path).close()
    except OSError as exc:
        return (
            f"the OpenCL kernel cache folder {path} cannot be written ({exc.strerror or exc}; "
            f"HOME={os.environ.get('HOME', '')!r}); set POCL_CACHE_DIR or XDG_CACHE_HOME to a writable folder"
        )
    return None


def _no_device(text: str) -> BackendUnavailable:
    problem = cache_problem()
    return BackendUnavailable(f"opencl: {problem}" if problem else f"opencl: {text}")


# PoCL's CPU device runs a kernel on one worker thread per core; left to the scheduler,
# two workers often share a core and a Lloyd step then takes twice as long.  Pinned, one
# per core, steps take the same time every time.  A user's own setting wins.
POCL_PINNING = ("POCL_AFFINITY", "1")


def _platforms(cl) -> list:
    # read by PoCL when it starts its devices, at the process's first platform query
    os.environ.setdefault(*POCL_PINNING)
    try:
        platforms = cl.get_platforms()
    except cl.Error as exc:  # no ICD loader / no platform: PLATFORM_NOT_FOUND_KHR
        raise BackendUnavailable(f"opencl: no OpenCL platform found ({exc})") from None
    if not platforms:
        raise BackendUnavailable("opencl: no OpenCL platform found")
    return platforms


def _devices(cl, platform) -> list:
    try:
        return platform.get_devices()
    except cl.Error:  # DEVICE_NOT_FOUND on a platform without devices
        return []


def describe_device(cl, dev) -> str:
    """'platform / device name (type)', the text recorded in result.json."""
    kind = cl.device_type.to_string(dev.type).replace("ALL | ", "")
    return f"{dev.platform.name.strip()} / {dev.name.strip()} ({kind})"


def _pick(items, token: str, what: str, source: str, names):
    """One of ``items`` by index or (case-insensitive) name fragment."""
    token = token.strip()
    if token.isdigit():
        k = int(token)
        if k < len(items):
            return items[k]
    else:
        hits = [it for it, nm in zip(items, names, strict=True) if token.lower() in nm.lower()]
        if hits:
            return hits[0]
    have = "; ".join(f"{k}: {nm.strip()}" for k, nm in enumerate(names)) or "none"
    raise InputError(f"{source}={token!r}: no OpenCL {what} {token!r} (have {have})")


_PROBE = "__kernel void probe(__global int *a) { a[get_global_id(0)] = 1; }"


def _error_line(exc) -> str:
    """The compiler's last error line of a failed build (or the whole message, squeezed)."""
    lines = [ln.strip() for ln in str(exc).splitlines() if "error" in ln.lower()]
    return (lines[-1] if lines else " ".join(str(exc).split()))[:200]


def compile_problem(cl, dev) -> str | None:
    """Why ``dev`` cannot compile a one-line kernel, or None (PoCL built with an LLVM that
    does not know the host processor stops with "unknown target CPU 'generic'"): the first
    thing the device check tries, for the clearest reason."""
    try:
        ctx = cl.Context([dev])
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # compiler chatter is not an error
            cl.Program(ctx, _PROBE).build()
    except cl.Error as exc:
        return _error_line(exc)
    return None


# ------------------------------------------------------------ the suite's programs
@dataclass(frozen=True)
class ProgramSpec:
    """A program the backend builds: its kernel files (one after the other), its build
    options and the kernels it must hold."""

    files: tuple[Path, ...]
    options: tuple[str, ...]
    kernels: tuple[str, ...]


LABEL_KERNELS = ("label_pixels", "label_blocks", "row_moments", *WALL_KERNELS)


def label_program(ellipse: bool, k: int, block: int, int64: bool, fits: bool) -> ProgramSpec:
    """The program of the label, moments and walled-cell kernels for a ball kind and facet
    count ``k``, block size (0: per pixel), 64-bit atomics or not; with ``fits`` (the
    device has float64) the element fit's kernel rides in it: one build instead of two,
    and the second costs most of a fit at a few thousand elements."""
    opts = [
        f"-DSTRIDE={8 if ellipse else 4 + 2 * k}",
        f"-DK={k}",
        f"-DBW={block or 8}",  # label_pixels uses none, but the program holds label_blocks too
        f"-DBH={block or 8}",
        f"-DSTRIP={STRIP}",
    ]
    opts += ["-DMETRIC_ELLIPSE"] if ellipse else []
    opts += ["-DUSE_INT64_ATOMICS"] if int64 else []
    if not fits:
        return ProgramSpec((KERNEL_FILE,), tuple(opts), LABEL_KERNELS)
    opts.append(f"-DVW={FIT_VECTOR}")
    return ProgramSpec((KERNEL_FILE, FIT_KERNEL_FILE), tuple(opts), (*LABEL_KERNELS, "fit_search"))


def fit_program(ellipse: bool, k: int) -> ProgramSpec:
    """The fit kernel's own program, for a shape whose label program was not built."""
    opts = (f"-DK={k}", f"-DVW={FIT_VECTOR}") + (("-DMETRIC_ELLIPSE",) if ellipse else ())
    return ProgramSpec((FIT_KERNEL_FILE,), opts, ("fit_search",))


def device_config(cl, dev, block: int | None = None, split_atomics: bool = False) -> tuple:
    """(block, 64-bit atomics, fits on the device) of a backend on ``dev`` with these
    options: CPUs vectorise over a block's pixels, GPUs want a pixel each."""
    if block is None:
        block = 0 if dev.type & cl.device_type.GPU else 8
    int64 = "cl_khr_int64_base_atomics" in dev.extensions and not split_atomics
    return int(block), int64, "cl_khr_fp64" in dev.extensions


def suite_programs(block: int, int64: bool, fits: bool) -> list[ProgramSpec]:
    """Every program a backend of this configuration builds for the suite's metrics (a
    user's polygon of another facet count is checked when it is first built)."""
    from compact_distributions.cvt.metrics import METRIC_NAMES, make_metric

    shapes = sorted({(m.curved, _facet_count(m)) for m in map(make_metric, METRIC_NAMES)})
    programs = [label_program(e, k, block, int64, fits) for e, k in shapes]
    if fits:  # an ellipse's fit uses no K: the kernel's arrays take one
        programs += [fit_program(e, 1 if e else k) for e, k in dict.fromkeys(shapes)]
    return list(dict.fromkeys(programs))


# ------------------------------------------------------------ can the device run them?
# A runtime can build a program "successfully" with no kernels in it (the PoCL wheel
# that pyopencl brings, on a processor newer than its LLVM, does so for every program it
# reads back from its kernel cache) and then abort the process at exit, or crash while a
# kernel runs (the same wheel, with 16-pixel blocks).  So a device is first tried in a
# child process: every program a backend of its configuration builds, each built twice
# (the second is read back from the cache where the runtime keeps one) and checked for
# its kernels, then run on a small problem of each ball against the NumPy reference.
# The verdict is kept in a file under the user's cache folder, per device, driver,
# configuration and kernel source, so this costs once.  A device whose programs lose
# their kernels only when read back is used with every build made outside the cache (a
# build option no build had before).
CHECK_VERSION = 2  # bump when what the check tries changes
CHECK_TIMEOUT = 600  # s for a child to build and run a configuration's programs
CHECK_MARK = "cvt-opencl-check: "  # the child's verdict line on its standard output
CHECK_ENTRY = "compact_distributions.backends.opencl"  # the child: python -m CHECK_ENTRY --check
CHECK_AGREEMENT = 0.995  # share of the check's pixels labelled as the reference does (float32 ties)
INSTALL_HINT = (
    "on Debian or Ubuntu, `apt-get install pocl-opencl-icd` adds a PoCL that runs them; "
    "or install another OpenCL runtime"
)
MAX_VERDICTS = 1000  # kept in the verdict file, the newest
_VERDICTS: dict[str, dict] | None = None  # this process's copy of the verdict file
_FRESH: set[tuple] = set()  # devices whose every build is made outside the kernel cache
_DIGESTS: dict[tuple, str] = {}  # (path, mtime, size) -> sha256 of a kernel file
_IN_CHECK = False  # set in the check's child: its backend trusts the programs it tries
_builds = itertools.count()


def _user_cache() -> str:
    return os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")


def verdict_path() -> Path:
    """The file of the device check's verdicts (``cvtbench info --recheck`` empties it)."""
    return Path(_user_cache()) / "compact-distributions" / "opencl-devices.json"


def device_identity(dev) -> tuple[str, ...]:
    """What a device's verdicts are kept under: platform, its version, device, driver."""
    plat = dev.platform
    return (plat.name.strip(), plat.version.strip(), dev.name.strip(), str(dev.driver_version).strip())


def _digest(path: Path) -> str:
    try:
        st = path.stat()
        tag = (str(path), st.st_mtime_ns, st.st_size)
        if tag not in _DIGESTS:
            _DIGESTS[tag] = hashlib.sha256(path.read_bytes()).hexdigest()
        return _DIGESTS[tag]
    except OSError:
        return "missing"  # the build says so


def _verdict_key(identity: tuple, programs: list[ProgramSpec], config: tuple | None) -> str:
    what = [CHECK_VERSION, identity, config]
    what += [[[_digest(f) for f in p.files], p.options, p.kernels] for p in programs]
    what.append(os.environ.get("POCL_KERNEL_CACHE", ""))  # the cache's switch changes what is read back
    return hashlib.sha256(json.dumps(what).encode()).hexdigest()[:32]


def forget_verdicts() -> None:
    """Forget every kept verdict: each device is tried again when next asked for."""
    global _VERDICTS
    _VERDICTS = {}
    _FRESH.clear()
    try:
        verdict_path().unlink(missing_ok=True)
    except OSError:
        pass  # nothing kept where nothing can be written


def _read_verdicts() -> dict:
    try:
        data = json.loads(verdict_path().read_text())
    except (OSError, ValueError):
        return {}
    return data if isinstance(data, dict) else {}


def _known() -> dict:
    global _VERDICTS
    if _VERDICTS is None:
        _VERDICTS = _read_verdicts()
    return _VERDICTS


def _keep(key: str, verdict: dict) -> None:
    """Add a verdict to the file (merged with what other processes wrote since; where the
    file cannot be written, the check is made again next time)."""
    path = verdict_path()
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        merged = {**_read_verdicts(), key: verdict}
        newest = sorted(merged.items(), key=lambda kv: kv[1].get("at", 0))[-MAX_VERDICTS:]
        tmp = path.with_name(f"{path.name}.{os.getpid()}.tmp")
        tmp.write_text(json.dumps(dict(newest), indent=0))
        os.replace(tmp, path)
    except OSError:
        pass


def _position(cl, dev) -> tuple[int, int]:
    """(platform, device) indices of ``dev``, as a child process sees them too."""
    for i, plat in enumerate(_platforms(cl)):
        for j, other in enumerate(_devices(cl, plat)):
            if other == dev:
                return i, j
    raise BackendUnavailable(f"opencl: {describe_device(cl, dev)} is not listed by its platform")


def _fresh_option() -> str:
    """A build option no build had before: PoCL's cache has nothing under it."""
    return f"-DCVT_FRESH_BUILD={os.getpid()}_{time.time_ns()}_{next(_builds)}"


def _child_check(cl, dev, programs: list[ProgramSpec], config: tuple | None, fresh: bool) -> dict:
    """Build ``programs`` on ``dev`` in a child process (``fresh``: each outside the kernel
    cache, which the child then leaves alone), and with ``config`` (block, 64-bit atomics,
    fits) run a backend of it on the check's problems: {"ok", "empty" (a program came
    without its kernels), "reason", "transient"}.  A child that crashes fails the device
    with the signal and the runtime's last line; one that hangs, for this time only."""
    i, j = _position(cl, dev)
    payload = {
        "platform": i,
        "device": j,
        "identity": list(device_identity(dev)),
        "programs": [[[str(f) for f in p.files], list(p.options), list(p.kernels)] for p in programs],
        "config": config,
        "fresh": fresh,
        # the files the backend builds from (a test may point them elsewhere)
        "sources": {"KERNEL_FILE": str(KERNEL_FILE), "FIT_KERNEL_FILE": str(FIT_KERNEL_FILE)},
    }
    env = dict(os.environ, **({"POCL_KERNEL_CACHE": "0"} if fresh else {}))
    cmd = [sys.executable, "-m", CHECK_ENTRY, "--check"]
    try:
        proc = subprocess.run(
            cmd, input=json.dumps(payload), capture_output=True, text=True, timeout=CHECK_TIMEOUT, env=env
        )
    except subprocess.TimeoutExpired:
        why = f"building and running the suite's programs took over {CHECK_TIMEOUT} s"
        return {"ok": False, "reason": why, "transient": True}
    except OSError as exc:
        return {"ok": False, "reason": f"could not start the device check ({exc})", "transient": True}
    for line in reversed(proc.stdout.splitlines()):
        if line.startswith(CHECK_MARK):
            return json.loads(line[len(CHECK_MARK) :])
    code = proc.returncode
    sig = -code if code < 0 and -code in signal.valid_signals() else None
    how = f"crashed (signal {signal.Signals(sig).name})" if sig else f"stopped (status {code})"
    lines = [ln.strip() for ln in proc.stderr.splitlines() if ln.strip()]
    steps = [ln[len(CHECK_MARK) :] for ln in lines if ln.startswith(CHECK_MARK)]
    step = f" in {steps[-1]}" if steps else ""
    # the runtime's own last word: an error line where it printed one, not compiler chatter
    said = [ln for ln in lines if "error" in ln.lower() and not ln.startswith(CHECK_MARK)]
    said = f": {said[-1][:160]}" if said else ""
    # killed from outside (out of memory, a user's ^C): not the device's verdict, not kept
    outside = sig in (signal.SIGKILL, signal.SIGTERM, signal.SIGINT)
    return {"ok": False, "reason": f"the device check {how}{step}{said}", "transient": outside}


def check_device(cl, dev, programs: list[ProgramSpec], config: tuple | None = None) -> dict:
    """Whether ``dev`` builds ``programs`` with their kernels (and with ``config``, runs a
    backend of that configuration to the reference's results): {"ok", "fresh" (only
    outside the kernel cache), "reason"}, from the verdict file or else from a child
    process (kept for next time)."""
    if _IN_CHECK:
        return {"ok": True, "fresh": device_identity(dev) in _FRESH, "reason": ""}
    identity = device_identity(dev)
    key = _verdict_key(identity, programs, config)
    if key not in _known():
        found = _child_check(cl, dev, programs, config, fresh=False)
        fresh = bool(found.get("empty"))
        if fresh:  # read back without kernels: all once more, each outside the cache
            found = _child_check(cl, dev, programs, config, fresh=True)
        verdict = {
            "ok": bool(found["ok"]),
            "fresh": fresh and bool(found["ok"]),
            "reason": found.get("reason", ""),
            "device": describe_device(cl, dev),
            "at": time.time(),
        }
        _known()[key] = verdict
        if not found.get("transient"):
            _keep(key, verdict)
    verdict = _known()[key]
    if verdict["fresh"]:
        _FRESH.add(identity)
    return verdict


def suite_problem(cl, dev, *, block: int | None = None, split_atomics: bool = False) -> str | None:
    """Why ``dev`` cannot run the programs a backend with these options builds, or None."""
    config = device_config(cl, dev, block, split_atomics)
    verdict = check_device(cl, dev, suite_programs(*config), config)
    return None if verdict["ok"] else verdict["reason"]


def _check_main() -> int:
    """The child process of the device check: tries what it is given on one device,
    prints its verdict line, and leaves at once (PoCL aborts at exit once a program came
    back without kernels; the verdict is out by then)."""
    global _IN_CHECK
    _IN_CHECK = True
    try:
        out = _check_here(json.loads(sys.stdin.read()))
    except Exception as exc:  # noqa: BLE001 - any failure is the device's verdict
        said = " ".join(str(exc).split())[:300]
        out = {"ok": False, "reason": f"the device check failed: {type(exc).__name__}: {said}"}
    sys.stdout.write(CHECK_MARK + json.dumps(out) + "\n")
    sys.stdout.flush()
    os._exit(0)


_HELD: list = []  # the child's contexts and programs, kept until it leaves


def _check_here(payload: dict) -> dict:
    """The child's check (see :func:`_child_check`)."""
    cl = _import_pyopencl()
    dev = _devices(cl, _platforms(cl)[payload["platform"]])[payload["device"]]
    if list(device_identity(dev)) != payload["identity"]:
        return {
            "ok": False,
            "reason": f"the device check found {describe_device(cl, dev)}, not the one asked for",
        }
    problem = compile_problem(cl, dev)
    if problem is not None:
        return {"ok": False, "reason": f"cannot compile a kernel: {problem}"}
    ctx = cl.Context([dev])
    _HELD.append(ctx)  # released, a context whose program came back empty aborts at once
    fresh = payload["fresh"]
    print(f"{CHECK_MARK}building the suite's programs", file=sys.stderr, flush=True)
    for files, opts, kernels in payload["programs"]:
        if fresh and payload["config"] is not None and "label_pixels" in kernels:
            continue  # the run below builds these (each checked for its kernels) as it needs them
        source = "\n".join(Path(f).read_text() for f in files)
        shown = " ".join(opts)
        # twice: the second build is read back from the kernel cache, where there is one
        for _ in range(1 if fresh else 2):
            try:
                with warnings.catch_warnings():
                    warnings.simplefilter("ignore")
                    prg = cl.Program(ctx, source).build(
                        options=[*opts, *([_fresh_option()] if fresh else [])]
                    )
                _HELD.append(prg)
                names = set(prg.get_info(cl.program_info.KERNEL_NAMES).split(";"))
            except cl.Error as exc:
                return {
                    "ok": False,
                    "reason": f"the kernels failed to build ({shown}): {_error_line(exc)}",
                }
            missing = [k for k in kernels if k not in names]
            if missing:
                why = (
                    f"the suite's program ({shown}) was built without its kernels ({', '.join(missing[:3])})"
                )
                return {"ok": False, "empty": True, "reason": why}
    if payload["config"] is None:
        return {"ok": True}
    print(f"{CHECK_MARK}starting a backend", file=sys.stderr, flush=True)
    if fresh:
        _FRESH.add(device_identity(dev))
    block, int64, _ = payload["config"]
    globals().update({name: Path(path) for name, path in payload["sources"].items()})
    device = f"{payload['platform']}:{payload['device']}"
    try:
        with OpenCLBackend(device=device, block=block, split_atomics=not int64) as backend:
            why = _run_problem(backend)
    except BackendUnavailable as exc:  # a kernel that failed, or a program without kernels
        return {"ok": False, "reason": str(exc).removeprefix("opencl: ").split(f"; {INSTALL_HINT}")[0]}
    return {"ok": why is None, "reason": why or ""}


def _run_problem(backend) -> str | None:
    """Why ``backend`` does not give the reference's results on a small problem of each
    ball kind and facet count of the suite's metrics (labels, their sums, the walled
    step's sums, the fit), or None."""
    from compact_distributions.cvt.metrics import METRIC_NAMES, make_metric
    from compact_distributions.cvt.moments import moments_from_labels
    from compact_distributions.cvt.mosaic.pipeline import split_cells
    from compact_distributions.cvt.placement.fit import element_for, fit_centres

    from .numpy_backend import NumpyBackend

    w, h, n = 83, 61, 40
    ys, xs = np.mgrid[0:h, 0:w] + 0.5
    mask = ((xs - w / 2) / (0.47 * w)) ** 2 + ((ys - h / 2) / (0.47 * h)) ** 2 < 1
    mask[h // 2 - 3 : h // 2 + 3, : w // 3] = False  # a wall into the region: cells in pieces
    rng = np.random.default_rng(7)
    iy, ix = np.nonzero(mask)
    pick = rng.choice(len(ix), n, replace=False)
    sites = np.stack([ix[pick], iy[pick]], axis=1) + rng.random((n, 2))
    angles, scales = rng.uniform(0, np.pi, n), rng.uniform(0.7, 1.4, n)
    grid = Grid(w, h, mask)
    shapes = {}
    for name in METRIC_NAMES:
        metric = make_metric(name)
        shapes.setdefault((metric.curved, _facet_count(metric)), metric)
    reference = NumpyBackend()

    def step(what: str) -> None:  # where the child was, should the runtime crash it
        print(f"{CHECK_MARK}{what}", file=sys.stderr, flush=True)

    for metric in shapes.values():
        args = dict(angles=angles, scales=scales, metric=metric, grid=grid)
        step(f"the labels of {metric.name}")
        labels = backend.label(sites, **args)
        agree = float((labels == reference.label(sites, **args)).mean())
        if agree < CHECK_AGREEMENT:
            return f"{metric.name}: {100 * (1 - agree):.1f}% of the pixels labelled unlike the reference"
        step(f"the sums of {metric.name}")
        sums = [(backend.moments(sites, **args), moments_from_labels(labels, n), "sums")]
        step(f"the walled step of {metric.name}")
        sums.append(
            (
                backend.walled_moments(sites, **args),
                moments_from_labels(split_cells(labels, sites), n),
                "walled sums",
            )
        )
        for got, want, what in sums:
            if any(
                not np.array_equal(getattr(got, f), getattr(want, f))
                for f in ("count", "sx", "sy", "sxx", "syy")
            ):
                return f"{metric.name}: the {what} of its labels are not the host's"
        shape, turn = element_for(metric)
        step(f"the fit of {metric.name}")
        on_device = fit_centres(labels, sites, angles + turn, shape, metric.aspect, search=backend.fit_search)
        on_host = fit_centres(labels, sites, angles + turn, shape, metric.aspect)
        if not all(np.array_equal(a, b) for a, b in zip(on_device, on_host, strict=True)):
            return f"{metric.name}: the fit's centres are not the host's"
    return None


def _preferred(cl, devices: list, problem, named: str | None = None):
    """The first device that runs the suite's programs (``problem(dev)`` is None): GPUs,
    then CPUs, then any other.  ``named``: how the user named these devices, for the
    error where none does."""

    def rank(dev):
        return 0 if dev.type & cl.device_type.GPU else 1 if dev.type & cl.device_type.CPU else 2

    failures = []
    for dev in sorted(devices, key=rank):  # sorted() is stable: driver order within a kind
        why = problem(dev)
        if why is None:
            return dev
        failures.append(f"{describe_device(cl, dev)}: {why}")
    said = "; ".join(failures)
    if named:
        raise BackendUnavailable(f"opencl: {named} cannot run the suite's kernels ({said}); {INSTALL_HINT}")
    raise BackendUnavailable(f"opencl: no OpenCL device runs the suite's kernels ({said}); {INSTALL_HINT}")


def choose_device(cl, spec: str | None = None, *, block: int | None = None, split_atomics: bool = False):
    """The device named by ``spec``, else by PYOPENCL_CTX, else the preferred one; only a
    device that runs the programs a backend with these options builds (one named that
    does not is refused with the reason)."""
    source = "device"
    if spec is None or str(spec).strip() == "":
        spec, source = os.environ.get("PYOPENCL_CTX", ""), "PYOPENCL_CTX"
    platforms = _platforms(cl)

    def problem(dev):
        return suite_problem(cl, dev, block=block, split_atomics=split_atomics)

    if not str(spec).strip():
        devices = [d for p in platforms for d in _devices(cl, p)]
        if not devices:
            raise _no_device("OpenCL platforms exist but none has a device")
        return _preferred(cl, devices, problem)
    parts = str(spec).split(":")
    if len(parts) > 2:
        raise InputError(f"{source}={spec!r}: expected PLATFORM[:DEVICE], e.g. 0:0")
    platform = _pick(platforms, parts[0], "platform", source, [p.name for p in platforms])
    devices = _devices(cl, platform)
    if not devices:
        raise _no_device(f"platform {platform.name.strip()!r} has no device")
    if len(parts) > 1 and parts[1].strip():
        devices = [_pick(devices, parts[1], "device", source, [d.name for d in devices])]
    return _preferred(cl, devices, problem, named=f"{source}={spec}")


class OpenCLBackend(Backend):
    """Labels and moments by an OpenCL kernel; see the module docstring.

    ``device``: "PLATFORM[:DEVICE]" (indices or name fragments); ``split_atomics``: keep
    the moment sums as 32-bit split counters even where 64-bit atomics exist (tests use
    it to check the portable path); ``cell_factor``: grid cell width in average site
    spacings; ``local_size``: the label kernel's work-group shape (None: the driver's for
    the per-pixel kernel, ``BLOCK_GROUP`` for the block kernel);
    ``block``: pixels per side of the block kernel's work-item (4, 8 or 16), 0 for the
    per-pixel kernel, None for the device's default; ``seed``: seed the block search with
    the last call's labels (False: the plain search, for tests)."""

    name = "opencl"
    bytes_per_pixel = (
        24  # labels and moments live on the device; the host reads back the raster for the final labels
    )
    bytes_per_site = 1000

    def __init__(
        self,
        device: str | None = None,
        split_atomics: bool = False,
        cell_factor: float = 1.0,
        local_size: tuple[int, int] | None = None,
        block: int | None = None,
        seed: bool = True,
    ):
        if block is not None and block not in BLOCK_SIZES:
            raise InputError(
                f"opencl: block must be one of {BLOCK_SIZES} (0: a pixel per work-item), got {block!r}"
            )
        cl = self._cl = _import_pyopencl()
        self._device = choose_device(cl, device, block=block, split_atomics=split_atomics)
        try:
            self._context = cl.Context([self._device])
            self._queue = cl.CommandQueue(self._context)
        except cl.Error as exc:
            raise BackendUnavailable(
                f"opencl: cannot open {describe_device(cl, self._device)}: {exc}"
            ) from None
        self.block, self.int64_atomics, self._fits_on_device = device_config(
            cl, self._device, block, split_atomics
        )
        self.cell_factor = float(cell_factor)
        self.local_size = None if local_size is None else tuple(int(v) for v in local_size)
        # the programs the device check built and ran (choose_device): built without asking again
        self._checked = set(suite_programs(self.block, self.int64_atomics, self._fits_on_device))
        # (kind, K, int64, block) -> (label, moments kernels); _fit_key -> the fit's program
        self._programs: dict[tuple, object] = {}
        self._buffers: dict[str, object] = {}
        self._mask_source = None  # the mask array last uploaded (grids are immutable)
        self._mask_pixels = 0
        self.seed = bool(seed)
        self._labels_buf = None  # the buffer the last labels went to, their (w, h) and sites
        self._labelled = None
        self._wall_kernels: dict[int, dict] = {}  # program -> walled-cell kernels by name
        self._fit_kernels: dict[tuple, object] = {}  # _fit_key -> fit kernel
        self._row_room = 0  # slots for each row's runs the walled step needed so far

    # ------------------------------------------------------------------ device
    @classmethod
    def probe(cls) -> str:
        cl = _import_pyopencl()
        try:
            dev = choose_device(cl, None)
        except InputError as exc:  # a bad PYOPENCL_CTX: `info` shows why
            raise BackendUnavailable(f"opencl: {exc}") from None
        if device_identity(dev) in _FRESH:
            return (
                f"{describe_device(cl, dev)}, every program built anew (its kernel cache loses their kernels)"
            )
        return describe_device(cl, dev)

    def device(self) -> str:
        return describe_device(self._cl, self._device)

    def release_buffers(self) -> None:
        for buf in self._buffers.values():
            buf.release()
        self._buffers.clear()
        self._mask_source = None  # its buffer went with the rest
        self._labels_buf = self._labelled = None

    def close(self) -> None:
        self.release_buffers()
        self._programs.clear()
        self._wall_kernels.clear()
        self._fit_kernels.clear()
        self._queue = self._context = None

    # ---------------------------------------------------------------- programs
    def _kernels(self, metric: Metric, k: int):
        """The built (label, moments) kernels for this metric kind; built once."""
        key = (metric.curved, k, self.int64_atomics, self.block)
        if key not in self._programs:
            cl = self._cl
            ellipse = metric.curved
            prg = self._build(label_program(ellipse, k, self.block, self.int64_atomics, self._fits_on_device))
            if self._fits_on_device:
                self._programs[_fit_key(ellipse, k)] = prg
            label_name = "label_blocks" if self.block > 0 else "label_pixels"
            self._programs[key] = (cl.Kernel(prg, label_name), cl.Kernel(prg, "row_moments"))
        return self._programs[key]

    def _buffer(self, name: str, nbytes: int):
        """A device buffer of at least ``nbytes``, reused across calls."""
        nbytes = max(int(nbytes), 4)
        buf = self._buffers.get(name)
        if buf is None or buf.size < nbytes:
            cl = self._cl
            limit = self._device.max_mem_alloc_size
            if nbytes > limit:
                raise BackendUnavailable(
                    f"opencl: {name} needs {nbytes / 2**20:.0f} MiB, more than the "
                    f"{limit / 2**20:.0f} MiB one buffer may have on {self.device()}"
                )
            if buf is not None:
                buf.release()
            try:
                buf = cl.Buffer(self._context, cl.mem_flags.READ_WRITE, nbytes)
            except cl.Error as exc:
                raise BackendUnavailable(
                    f"opencl: out of device memory for {name} ({nbytes / 2**20:.0f} MiB) "
                    f"on {self.device()}: {exc}"
                ) from None
            self._buffers[name] = buf
        return buf

    def _upload(self, name: str, array: np.ndarray):
        array = np.ascontiguousarray(array)
        buf = self._buffer(name, array.nbytes)
        if array.nbytes:
            self._cl.enqueue_copy(self._queue, buf, array, is_blocking=True)
        return buf

    # ------------------------------------------------------------------ labels
    def _site_records(self, sites, angles, scales, metric: Metric):
        """Per-site float32 records (see the kernel file) and the search reach."""
        n = len(sites)
        uniform = np.ptp(angles) == 0 and np.ptp(scales) == 0
        if uniform:  # one shape for all: compile it once and repeat it (N-fold less work)
            one = compile_sites(metric, sites[:1], angles[:1], scales[:1])
            coeffs = (
                one
                if n == 1
                else type(one)(
                    one.curved,
                    sites,
                    facets=None
                    if one.facets is None
                    else np.broadcast_to(one.facets, (n,) + one.facets.shape[1:]),
                    quad=None if one.quad is None else np.broadcast_to(one.quad, (n, 3)),
                )
            )
        else:
            coeffs = compile_sites(metric, sites, angles, scales)
        hi = sites.astype(np.float32)
        lo = (sites - hi.astype(np.float64)).astype(np.float32)
        if metric.curved:
            qxx, qxy, qyy = coeffs.quad.T
            l11 = np.sqrt(qxx)
            l21 = qxy / l11
            l22 = np.sqrt(np.maximum(qyy - l21 * l21, 0.0))
            coef = np.stack([l11, l21, l22, np.zeros_like(l11)], axis=1)
            k = 0
        else:
            k = coeffs.facets.shape[1]
            coef = coeffs.facets.reshape(len(sites), 2 * k)
        records = np.concatenate([hi, lo, coef.astype(np.float32)], axis=1)
        reach = metric.circumradius * float(scales.max()) * (1 + REACH_MARGIN)
        return records, k, reach

    def _run_labels(self, sites, angles, scales, metric: Metric, grid: Grid, acc_buf=None, below_bits=None):
        """Enqueue the label kernel; the labels stay in the device buffer 'labels'.  With
        ``acc_buf`` (zeroed, block kernel only) the kernel also adds the moments to it;
        with ``below_bits`` (block kernel of :meth:`_bits_period` rows only) it leaves
        there the bits the walled step's ``row_runs`` reads (the kernel file says which)."""
        n = len(sites)
        if self._queue is None:
            raise RuntimeError("opencl: this backend was closed; create a new one")
        w, h = grid.width, grid.height
        records, k, reach = self._site_records(sites, angles, scales, metric)
        label_kernel, _ = self._kernels(metric, k)

        use_mask = grid.mask is not None
        if use_mask and self._mask_source is not grid.mask:
            packed = block_mask_words(grid.mask, self.block) if self.block > 0 else grid.mask.view(np.uint8)
            self._upload("mask", packed)
            self._mask_source, self._mask_pixels = grid.mask, int(grid.mask.sum())
        area = self._mask_pixels if use_mask else w * h

        cell, ncx, ncy, order, starts = _site_grid(sites, self.cell_factor * math.sqrt(area / n), w, h)

        cl = self._cl
        starts_buf = self._upload("cell_start", starts)
        records_buf = self._upload("records", records[order])
        index_buf = self._upload("site_index", order.astype(np.int32))
        site_reach = scales[order] * (metric.circumradius * (1 + REACH_MARGIN))
        # each kernel reads its own bounds; the other's arguments get a placeholder
        if self.block > 0:
            # per sorted site: float32 position and its own reach (the box test), and
            # where each site went (the seeds are site indices)
            site_pos = np.zeros((n, 4), dtype=np.float32)
            site_pos[:, :2] = records[order, :2]
            site_pos[:, 2] = site_reach
            pos_buf = self._upload("site_pos", site_pos)
            rank = np.empty(n, dtype=np.int32)
            rank[order] = np.arange(n, dtype=np.int32)
            rank_buf = self._upload("site_rank", rank)
            reach_buf = self._buffer("cell_reach", 4)
        else:
            # per cell: circumradius x the largest scale in it (the kernel's local bound)
            cell_reach = np.zeros(ncx * ncy, dtype=np.float32)
            full = starts[1:] > starts[:-1]
            cell_reach[full] = np.maximum.reduceat(site_reach, starts[:-1][full])
            reach_buf = self._upload("cell_reach", cell_reach)
            pos_buf, rank_buf = self._buffer("site_pos", 16), self._buffer("site_rank", 4)
        mask_buf = self._buffer("mask", 4)
        # the last call's labels seed the block search when they are of this raster and
        # of about these sites (a Lloyd step's, or the same): seeds only speed the
        # search, as any index below n gives the same labels, but those of another
        # problem's sites (a sweep's next run, a second mosaic) would slow it many times
        labels_buf = self._buffer("labels", 4 * w * h)
        seed = labels_buf is self._labels_buf and _near(self._labelled, (w, h), sites, cell)
        self._labels_buf, self._labelled = labels_buf, ((w, h), sites.copy())
        slack = 1e-3 + 4 * max(w, h) * 2.0**-24  # px: float32 rounding of far cell edges
        label_kernel.set_args(
            np.int32(w),
            np.int32(h),
            np.int32(ncx),
            np.int32(ncy),
            np.float32(cell),
            np.float32(reach),
            np.float32(slack),
            starts_buf,
            reach_buf,
            records_buf,
            pos_buf,
            index_buf,
            mask_buf,
            np.int32(use_mask),
            labels_buf,
            rank_buf,
            np.int32(n),
            np.int32(seed and self.seed),
            self._buffer("moments", 4) if acc_buf is None else acc_buf,
            np.int32(acc_buf is not None),
            self._buffer("below_bits", 4) if below_bits is None else below_bits,
            np.int32(0 if below_bits is None else _bits_row_bytes(w)),
        )
        local = self.local_size
        if self.block > 0:  # one work-item per STRIP blocks of a row
            w, h = -(-w // (self.block * STRIP)), -(-h // self.block)
            local = BLOCK_GROUP if local is None else local
        if local is None:
            global_size = (w, h)
        else:
            global_size = (-(-w // local[0]) * local[0], -(-h // local[1]) * local[1])
        try:
            cl.enqueue_nd_range_kernel(self._queue, label_kernel, global_size, local)
        except cl.Error as exc:
            raise BackendUnavailable(f"opencl: label kernel failed on {self.device()}: {exc}") from None
        return labels_buf, n

    def _label(self, sites, angles, scales, metric: Metric, grid: Grid) -> np.ndarray:
        labels_buf, _ = self._run_labels(sites, angles, scales, metric, grid)
        out = np.empty((grid.height, grid.width), dtype=np.int32)
        self._read(out, labels_buf)
        return out

    def _read(self, out: np.ndarray, buf) -> None:
        try:
            self._cl.enqueue_copy(self._queue, out, buf, is_blocking=True)
        except self._cl.Error as exc:  # a kernel that failed surfaces here
            raise BackendUnavailable(f"opencl: device error on {self.device()}: {exc}") from None

    # ----------------------------------------------------------------- moments
    def _moments(self, sites, angles, scales, metric: Metric, grid: Grid) -> Moments:
        """Labels and their integer moments on the device; reads back 5·N sums."""
        acc_buf, _ = self._enqueue_moments(sites, angles, scales, metric, grid)
        return self._read_moments(acc_buf, len(sites))

    def _enqueue_moments(self, sites, angles, scales, metric: Metric, grid: Grid, below_bits=None):
        """Enqueue the labels and their sums: (sums buffer, labels buffer); ``below_bits``
        as for :meth:`_run_labels`."""
        cl = self._cl
        n = len(sites)
        acc_buf = self._buffer("moments", ACC_BYTES * n)
        cl.enqueue_fill_buffer(self._queue, acc_buf, np.uint32(0), 0, ACC_BYTES * n)
        if self.block > 0:  # the block kernel sums its own labels
            labels_buf, _ = self._run_labels(sites, angles, scales, metric, grid, acc_buf, below_bits)
        else:
            labels_buf, _ = self._run_labels(sites, angles, scales, metric, grid)
            _, moments_kernel = self._kernels(metric, _facet_count(metric))
            w, h = grid.width, grid.height
            moments_kernel.set_args(
                np.int32(w), np.int32(h), np.int32(SEGMENT), labels_buf, np.int32(n), acc_buf
            )
            try:
                cl.enqueue_nd_range_kernel(self._queue, moments_kernel, (-(-w // SEGMENT), h), None)
            except cl.Error as exc:
                raise BackendUnavailable(f"opencl: moments kernel failed on {self.device()}: {exc}") from None
        return acc_buf, labels_buf

    def _read_moments(self, acc_buf, n: int) -> Moments:
        acc = np.empty((n, ACC_BYTES // 8), dtype=np.uint64)
        self._read(acc, acc_buf)
        if self.int64_atomics:
            sums = acc[:, :5].view(np.int64).T
        else:  # 32-bit low words, then high words, in one record
            words = acc.view(np.uint32).astype(np.int64)
            sums = ((words[:, 8:13] << 32) | words[:, :5]).T
        return Moments(*(np.ascontiguousarray(row) for row in sums))

    # ------------------------------------------------------------ walled cells
    def _wall_kernel(self, metric: Metric, name: str, items: int, *args) -> None:
        """Enqueue walled-cell kernel ``name`` over ``items`` work-items (rows, cells, or
        1 for one work-group), padded to a multiple of its fixed work-group: the kernels
        skip the rest."""
        cl = self._cl
        program = self._kernels(metric, _facet_count(metric))[0].program
        if program.int_ptr not in self._wall_kernels:
            self._wall_kernels[program.int_ptr] = {n: cl.Kernel(program, n) for n in WALL_KERNELS}
        kernel = self._wall_kernels[program.int_ptr][name]
        kernel.set_args(*args)
        size = -(-items // WALL_GROUP) * WALL_GROUP
        cl.enqueue_nd_range_kernel(self._queue, kernel, (size,), (WALL_GROUP,))

    def _bits_period(self) -> int:
        """Rows of the blocks whose row pairs' bits the block kernel leaves for row_runs:
        blocks 8 or 16 wide (a byte or two a block row), on a little-endian device (the
        bytes read as 64-bit words); 0: none, row_runs reads the labels."""
        return self.block if self.block >= 8 and self._device.endian_little else 0

    def _row_slots(self, w: int, n: int, area: int) -> int:
        """Slots for the runs of each row of a ``w``-pixel-wide raster: as many as a row
        needed in the last calls, at least twice the cells a row crosses (one per
        sqrt(area / n) pixels) and some, at most a pixel each."""
        crossed = w / math.sqrt(max(area, 1) / max(n, 1))
        return min(w, max(self._row_room, 2 * math.ceil(crossed) + 32))

    def _suspect_runs(
        self, metric: Metric, labels_buf, w: int, h: int, n: int, cap: int, below_bits=None, period: int = 0
    ):
        """List the runs of the labels in ``labels_buf``, each row's in its ``cap`` slots
        (``row_runs``), and move to the front of its slots those of the cells that may be
        in pieces (``suspect_cells``, ``suspect_runs``), without a wait: (counts buffer,
        per row its kept runs, (the runs, their labels), their union-find parents, per
        cell its top and bottom run counts, per cell whether it may be in pieces).  The
        counts buffer holds the most runs of any row (where more than ``cap``, the lists
        are cut short and the caller asks again with more slots), then room for the
        number of runs that ``pieces_dropped`` leaves to ``pieces_homeless``.  Where
        ``period`` > 0, ``below_bits`` holds the label kernel's bits of the row pairs
        inside its blocks of ``period`` rows, which row_runs reads instead of the labels."""
        cl, queue = self._cl, self._queue
        slots = h * cap
        ends, counts = self._buffer("run_ends", 8 * n), self._buffer("run_counts", 8)
        cl.enqueue_fill_buffer(queue, ends, np.uint32(0), 0, 8 * n)
        cl.enqueue_fill_buffer(queue, counts, np.uint32(0), 0, 8)
        # the runs as (first pixel, length) and their labels apart: suspect_runs reads
        # the labels alone, the pieces kernels whole vectors of either
        runs, labels_of = self._buffer("runs", 8 * slots), self._buffer("run_labels", 4 * slots)
        found, kept = self._buffer("row_count", 4 * h), self._buffer("row_kept", 4 * h)
        parent = self._buffer("piece_parent", 4 * slots)
        suspect = self._buffer("suspect_cells", n)
        listing = (ends, runs, labels_of, found, counts)
        bits = self._buffer("below_bits", 4) if below_bits is None else below_bits
        raster = (np.int32(w), np.int32(h), labels_buf, bits, np.int32(_bits_row_bytes(w)), np.int32(period))
        self._wall_kernel(metric, "row_runs", h, *raster, np.uint32(cap), *listing)
        self._wall_kernel(metric, "suspect_cells", n, np.int32(n), ends, suspect)
        keeping = (found, suspect, runs, labels_of, kept, parent)
        self._wall_kernel(metric, "suspect_runs", h, np.int32(h), np.uint32(cap), *keeping)
        return counts, kept, (runs, labels_of), parent, ends, suspect

    def _enqueue_pieces(
        self, metric: Metric, n: int, w: int, h: int, acc_buf, labels_buf, site_at, cap: int, bits
    ):
        """Enqueue the walled-cell kernels over the labels and sums the label kernel left,
        each row's runs in ``cap`` slots, with no wait before the sums are read.  Returns
        (moments, the most runs of any row): the moments hold only where that is at most
        ``cap``.  ``bits``: (below_bits buffer, period) as for :meth:`_suspect_runs`."""
        counts, kept, listed, parent, _, suspect = self._suspect_runs(metric, labels_buf, w, h, n, cap, *bits)
        site_piece = self._buffer("site_piece", 4 * n)
        # the runs of the cells whose site is not in them, each with its piece's root
        homeless = self._buffer("homeless_runs", 8 * h * cap)
        rows = (np.int32(h), np.uint32(cap), kept)
        self._wall_kernel(metric, "pieces_join", h, *rows, np.int32(w), *listed, parent)
        self._wall_kernel(
            metric,
            "pieces_site",
            n,
            np.int32(n),
            np.int32(w),
            np.uint32(cap),
            kept,
            suspect,
            *listed,
            parent,
            site_at,
            site_piece,
        )
        cut = (np.int32(w), np.int32(n), acc_buf)
        self._wall_kernel(
            metric, "pieces_dropped", h, *rows, *listed, parent, site_piece, homeless, counts, *cut
        )
        sizes = (
            self._buffer(name, 4 * size)
            for name, size in (("piece_size", h * cap), ("largest", n), ("last_largest", n))
        )
        self._wall_kernel(metric, "pieces_homeless", 1, *listed, parent, homeless, counts, *sizes, *cut)
        most = np.empty(2, dtype=np.uint32)
        # before the sums (in order); its event is held until they are read, since
        # pyopencl waits for a host copy whose event is let go, holding the GIL
        copied = self._cl.enqueue_copy(self._queue, most, counts, is_blocking=False)
        moments = self._read_moments(acc_buf, n)
        del copied
        return moments, int(most[0])

    def _walled_moments(self, sites, angles, scales, metric: Metric, grid: Grid) -> Moments:
        """The moments of the labels with each cell cut to the piece it keeps, found on
        the device: ``row_runs`` lists each row's runs and counts each cell's top and
        bottom runs, ``suspect_runs`` keeps the runs of the cells that may be in pieces,
        the ``pieces_*`` kernels find their pieces and take the sums of the runs of those
        not kept from their cells' sums (``pieces_homeless``, one work-group, those of the
        few cells whose site is not in them); the host reads 5·N sums (never the raster) and
        the most runs of a row, and waits once, for these.  Where a row had more runs than
        its slots, it labels again with more."""
        cl = self._cl
        n = len(sites)
        w, h = grid.width, grid.height
        # each site's pixel, for pieces_site: sent now, without a wait (the array and
        # the copy's event live until the sums are read: pyopencl waits, holding the
        # GIL, for a copy whose event is let go)
        i, j = pixel_index(sites, w, h)
        site_pixel = (i * w + j).astype(np.int32)
        site_at = self._buffer("site_at", site_pixel.nbytes)
        sent = cl.enqueue_copy(self._queue, site_at, site_pixel, is_blocking=False)
        # the label kernel leaves the bits of which pixels have the label below them,
        # where it has them at hand (inside its blocks), for row_runs
        period = self._bits_period()
        bits = (self._buffer("below_bits", _bits_row_bytes(w) * h), period) if period else (None, 0)
        acc_buf, labels_buf = self._enqueue_moments(sites, angles, scales, metric, grid, bits[0])
        area = self._mask_pixels if grid.mask is not None else w * h
        try:
            while True:
                cap = self._row_slots(w, n, area)
                mom, most = self._enqueue_pieces(metric, n, w, h, acc_buf, labels_buf, site_at, cap, bits)
                if most <= cap:
                    del sent  # done: the sums are read
                    return mom
                self._row_room = most + most // 4  # a row needs at most w: the next fits
                acc_buf, labels_buf = self._enqueue_moments(sites, angles, scales, metric, grid, bits[0])
        except cl.Error as exc:
            raise BackendUnavailable(
                f"opencl: walled-cell kernels failed on {self.device()}: {exc}"
            ) from None

    # --------------------------------------------------------------------- fit
    def fit_search(self, cells):
        """The centre search of ``cvt.placement.fit_centres`` in a kernel
        (``opencl_fit.cl``): one work-item per cell and start, the host's search step for
        step, so the centres and sizes are :func:`cvt.placement.search_on_host`'s bit for
        bit (``Backend.fit_search`` says what goes in and out).  The second starts (each
        cell's deepest pixel) are found by the kernel too where its depths are the host's
        bit for bit, else by the host (``FitCells.inscribed``).  Needs float64 on the
        device; without it the host searches."""
        if not self._fits_on_device:
            return super().fit_search(cells)
        if self._queue is None:
            raise RuntimeError("opencl: this backend was closed; create a new one")
        cl = self._cl
        ellipse = cells.curved
        k = 1 if ellipse else len(cells.slack)
        key = _fit_key(ellipse, k)
        if key not in self._programs:  # no label program of this shape built the fit's
            self._programs[key] = self._build(fit_program(ellipse, k))
        if key not in self._fit_kernels:
            self._fit_kernels[key] = cl.Kernel(self._programs[key], "fit_search")
        kernel = self._fit_kernels[key]
        # the kernel's depths are the host's bit for bit where the host's are exact: whole
        # numbers (chessboard) or sums of squared quarters (spacings 1, 2, 1/2, ...)
        kind, sy, sx = cells.depth
        on_device = kind is Depth.CHESSBOARD or (float(4 * sy).is_integer() and float(4 * sx).is_integer())
        starts = np.empty((2, len(cells.ids), 2))
        starts[0] = cells.anchor
        if not on_device:
            starts[1] = cells.inscribed()
        m = len(cells.ids)
        h, w = cells.labels.shape
        centres, sizes = np.empty((2, m, 2)), np.empty((2, m))
        flags = cl.mem_flags.READ_ONLY | cl.mem_flags.COPY_HOST_PTR
        inputs = [
            cells.labels,
            cells.qx,
            cells.qy,
            cells.first.astype(np.int64),
            cells.counts.astype(np.int32),
            cells.ids.astype(np.int32),
            cells.anchor,
            cells.coef,
            np.concatenate([cells.slack, [0.0]]),  # never empty
            starts,
        ]
        bufs = [cl.Buffer(self._context, flags, hostbuf=np.ascontiguousarray(a)) for a in inputs]
        out_c = cl.Buffer(self._context, cl.mem_flags.WRITE_ONLY, centres.nbytes)
        out_s = cl.Buffer(self._context, cl.mem_flags.WRITE_ONLY, sizes.nbytes)
        scratch = cl.Buffer(self._context, cl.mem_flags.READ_WRITE, 8 * len(cells.qx) if on_device else 8)
        try:
            labels, qx, qy, first, counts, ids, anchor, coef, slack, starts = bufs
            kernel.set_args(
                np.int32(w),
                np.int32(h),
                labels,
                qx,
                qy,
                first,
                counts,
                ids,
                np.int32(m),
                anchor,
                coef,
                slack,
                np.float64(cells.half),
                starts,
                np.int32(0 if not on_device else 1 if kind is Depth.CHESSBOARD else 2),
                np.float64(sy),
                np.float64(sx),
                scratch,
                out_c,
                out_s,
            )
            local = FIT_GROUP
            cl.enqueue_nd_range_kernel(self._queue, kernel, (-(-2 * m // local) * local,), (local,))
            self._read(centres, out_c)
            self._read(sizes, out_s)
        finally:
            for buf in (*bufs, out_c, out_s, scratch):
                buf.release()
        return centres, sizes

    def _build(self, spec: ProgramSpec):
        """The program ``spec`` names, built quietly (PoCL's own compiler chatter goes to
        descriptor 2; PYOPENCL_COMPILER_OUTPUT=1 shows it), once the device check has
        tried it in a child process (:func:`check_device`; kept, so once per device);
        outside the kernel cache on a device whose programs lose their kernels there.  A
        program that fails to build, or comes without its kernels even outside the cache,
        raises BackendUnavailable saying why."""
        cl = self._cl
        if spec not in self._checked:  # a user's polygon: another facet count
            verdict = check_device(cl, self._device, [spec])
            if not verdict["ok"]:
                raise BackendUnavailable(f"opencl: {self.device()}: {verdict['reason']}; {INSTALL_HINT}")
            self._checked.add(spec)
        try:
            source = "\n".join(path.read_text() for path in spec.files)
        except OSError as exc:
            raise BackendUnavailable(f"opencl: kernel source missing: {exc}") from None
        shown = os.environ.get("PYOPENCL_COMPILER_OUTPUT") == "1"
        identity = device_identity(self._device)
        for _ in range(2):
            fresh = identity in _FRESH
            opts = [*spec.options, *([_fresh_option()] if fresh else [])]
            try:
                with warnings.catch_warnings(), nullcontext() if shown else c_output_silenced(2):
                    warnings.simplefilter("ignore")
                    prg = cl.Program(self._context, source).build(options=opts)
                names = set(prg.get_info(cl.program_info.KERNEL_NAMES).split(";"))
            except cl.Error as exc:
                log = " ".join(str(exc).split())[:400]
                raise BackendUnavailable(
                    f"opencl: kernel failed to build on {self.device()} ({' '.join(spec.options)}): {log}"
                ) from None
            missing = [k for k in spec.kernels if k not in names]
            if not missing:
                return prg
            if fresh:
                break
            _FRESH.add(identity)  # read back without its kernels: once more, outside the cache
        raise BackendUnavailable(
            f"opencl: {self.device()} built the suite's program ({' '.join(spec.options)}) without "
            f"its kernels ({', '.join(missing[:3])}); {INSTALL_HINT}"
        )


FIT_KERNEL_FILE = Path(__file__).with_name("opencl_fit.cl")
FIT_VECTOR = 4  # samples read at once by a work-item of the fit kernel (2, 4, 8 or 16)
FIT_GROUP = 16  # work-items per group of the fit kernel: cells of unlike cost spread over the cores


__all__ = [
    "KERNEL_FILE",
    "SEGMENT",
    "ACC_BYTES",
    "BLOCK_SIZES",
    "STRIP",
    "BLOCK_GROUP",
    "REACH_MARGIN",
    "WALL_GROUP",
    "WALL_KERNELS",
    "block_mask_words",
    "pocl_cache_dir",
    "cache_problem",
    "describe_device",
    "device_identity",
    "device_config",
    "compile_problem",
    "ProgramSpec",
    "LABEL_KERNELS",
    "label_program",
    "fit_program",
    "suite_programs",
    "check_device",
    "suite_problem",
    "verdict_path",
    "forget_verdicts",
    "INSTALL_HINT",
    "CHECK_VERSION",
    "choose_device",
    "OpenCLBackend",
    "FIT_KERNEL_FILE",
    "FIT_VECTOR",
    "FIT_GROUP",
]


if __name__ == "__main__" and sys.argv[1:] == ["--check"]:
    _check_main()
