"""Writing results: atomically (no half-written output) and in the shared formats."""

from __future__ import annotations

import json
import os
import platform
import shutil
import sys
import tempfile
from contextlib import contextmanager
from importlib import metadata
from pathlib import Path

import numpy as np

PACKAGES = ("numpy", "scipy", "shapely", "pandas", "matplotlib", "pillow", "pyopencl",
            "moderngl")


def versions() -> dict:
    out = {"python": platform.python_version()}
    for name in PACKAGES:
        try:
            out[name] = metadata.version(name)
        except metadata.PackageNotFoundError:
            pass
    try:
        out["compact-distributions"] = metadata.version("compact-distributions")
    except metadata.PackageNotFoundError:
        pass
    return out


def machine() -> dict:
    return {"platform": platform.platform(), "processor": platform.processor() or platform.machine(),
            "cpus": os.cpu_count()}


@contextmanager
def staged_dir(out_dir):
    """Yield a temporary folder beside ``out_dir``; on success move its files into
    ``out_dir`` (created if needed), on any error remove it: never a partial result."""
    out_dir = Path(out_dir)
    parent = out_dir.resolve().parent
    parent.mkdir(parents=True, exist_ok=True)
    tmp = Path(tempfile.mkdtemp(prefix=f".{out_dir.name}.", dir=parent))
    try:
        yield tmp
        out_dir.mkdir(parents=True, exist_ok=True)
        for f in tmp.iterdir():
            os.replace(f, out_dir / f.name)
    finally:
        shutil.rmtree(tmp, ignore_errors=True)


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


@contextmanager
def atomic_path(path):
    """Yield a temporary path beside ``path`` to write to; on success rename it over
    ``path`` (readable by everyone, as a report should be), on any error remove it: the
    one way the suite writes a file, so none is ever half-written."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.stem}.", suffix=path.suffix, dir=path.parent)
    os.close(fd)
    try:
        yield Path(tmp)
        os.chmod(tmp, 0o666 & ~_umask())  # mkstemp makes 0600
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


def atomic_write(path, data: str | bytes) -> None:
    """Write text or bytes to ``path`` atomically (:func:`atomic_path`)."""
    with atomic_path(path) as tmp:
        if isinstance(data, bytes):
            tmp.write_bytes(data)
        else:
            tmp.write_text(data)


def to_jsonable(obj):
    if isinstance(obj, dict):
        return {str(k): to_jsonable(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [to_jsonable(v) for v in obj]
    if isinstance(obj, np.ndarray):
        return to_jsonable(obj.tolist())
    if isinstance(obj, np.generic):
        return obj.item()
    if isinstance(obj, float) and not np.isfinite(obj):
        return None
    return obj


def dumps(data: dict) -> str:
    """JSON with one top-level key per line and each value compact (site lists stay short)."""
    data = to_jsonable(data)
    body = ",\n".join(f" {json.dumps(k)}: {json.dumps(v)}" for k, v in data.items())
    return "{\n" + body + "\n}\n"


def write_json(path, data) -> None:
    Path(path).write_text(dumps(data))


def write_sites_csv(path, sites, angles, scales) -> None:
    lines = ["x,y,angle_deg,scale"]
    for (x, y), a, s in zip(sites, angles, scales, strict=True):
        lines.append(f"{x:.6f},{y:.6f},{np.degrees(a):.6f},{s:.6f}")
    Path(path).write_text("\n".join(lines) + "\n")


def command_line(argv=None) -> str:
    import shlex

    argv = sys.argv[1:] if argv is None else argv
    return "cvtbench " + shlex.join(argv)
