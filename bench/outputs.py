"""Writing results: atomically (no half-written output) and in the shared formats."""

from __future__ import annotations

import errno
import fcntl
import json
import os
import platform
import re
import shutil
import stat
import struct
import sys
import tempfile
import time
import zlib
from contextlib import contextmanager
from importlib import metadata
from pathlib import Path

import numpy as np

from compact_distributions.cvt.errors import InputError

PACKAGES = ("numpy", "scipy", "shapely", "pandas", "matplotlib", "pillow", "pyopencl", "moderngl")


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
    return {
        "platform": platform.platform(),
        "processor": platform.processor() or platform.machine(),
        "cpus": os.cpu_count(),
    }


# ------------------------------------------------------------------ writing files and folders
# Every temporary the writers make carries TEMP_MARK in its name and is flock()ed by the
# process that writes it, so a later command can tell the leftovers of a killed one (no
# lock) from the work in hand of a live one (locked) and removes only the former.
TEMP_MARK = ".cvtbench-tmp"
# what `cvtbench run` and `cvtbench mosaic` write: a folder holding only these may be
# replaced by another run or mosaic
COMMAND_OUTPUTS = (
    "result.json",
    "sites.csv",
    "cells.png",
    "elements.svg",
    "elements.png",
    "mosaic.svg",
    "mosaic.png",
    "compare_field.png",
    "compare_density.png",
    "compare_edges.png",
    "compare_method.png",
)
LOCK_NAME = ".cvtbench.lock"


def _lock(fd: int, wait: bool = False) -> bool:
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | (0 if wait else fcntl.LOCK_NB))
        return True
    except BlockingIOError:
        return False


def _owner_alive(path: Path) -> bool:
    """Whether a live process holds the lock of a temporary (file or folder)."""
    try:
        fd = os.open(path, os.O_RDONLY)
    except OSError:
        return False
    try:
        return not _lock(fd)
    finally:
        os.close(fd)


def _remove(path: Path) -> None:
    if path.is_dir() and not path.is_symlink():
        shutil.rmtree(path, ignore_errors=True)
    else:
        path.unlink(missing_ok=True)


def _leftover_target(name: str) -> str | None:
    """The folder a backup ``.NAME.XXXXXXXX.old.cvtbench-tmp`` was renamed from."""
    match = re.fullmatch(r"\.(.+)\.[a-z0-9_]{8}\.old" + re.escape(TEMP_MARK), name)
    return match.group(1) if match else None


def remove_leftovers(folder, name: str | None = None, recursive: bool = False) -> list[Path]:
    """Remove the temporaries that killed commands left in ``folder`` (of the output
    ``name`` only, when given): those whose writer no longer holds their lock.  The
    backup of a replaced output folder whose replacement never arrived (a command
    killed between the two renames of its swap) is put back instead.  Temporaries are
    made and locked under a lock of their folder (:func:`_new_temporary`), which this
    holds while it looks, so it never takes one that is being made for a leftover."""
    folder = Path(folder)
    removed, below = [], []
    try:
        entries = list(folder.iterdir())
    except OSError:
        return removed
    with _locked_folder(folder):
        for entry in entries:
            if TEMP_MARK not in entry.name:
                if recursive and entry.is_dir() and not entry.is_symlink():
                    below.append(entry)
                continue
            if (name is not None and not entry.name.startswith(f".{name}.")) or _owner_alive(entry):
                continue
            backup_of = _leftover_target(entry.name)
            if backup_of is not None:
                staging = entry.with_name(entry.name.replace(".old" + TEMP_MARK, TEMP_MARK))
                if _owner_alive(staging):
                    continue
                if not (folder / backup_of).exists():
                    os.rename(entry, folder / backup_of)
                    continue
            _remove(entry)
            removed.append(entry)
    for sub in below:
        removed += remove_leftovers(sub, name, recursive=True)
    return removed


def _new_temporary(folder: Path, prefix: str, suffix: str, directory: bool = False) -> tuple[Path, int]:
    """A temporary file (or folder) in ``folder``, made and locked under the folder's
    lock; returns its path and the descriptor that holds the lock."""
    with _locked_folder(folder):
        if directory:
            path = tempfile.mkdtemp(prefix=prefix, suffix=suffix, dir=folder)
            fd = os.open(path, os.O_RDONLY)
        else:
            fd, path = tempfile.mkstemp(prefix=prefix, suffix=suffix, dir=folder)
        _lock(fd)
    return Path(path), fd


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


@contextmanager
def atomic_path(path):
    """Yield a temporary path beside ``path`` to write to; on success rename it over
    ``path`` (readable by everyone, as a report should be), on any error remove it: the
    one way the suite writes a file, so none is ever half-written.  The temporary keeps
    the file's suffix (writers pick the format from it), has a name of its own (two
    writers never collide) and is locked while written; the leftovers of writers that
    were killed are removed here."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    remove_leftovers(path.parent, path.name)
    tmp, fd = _new_temporary(path.parent, f".{path.name}.", TEMP_MARK + path.suffix)
    try:
        yield tmp
        os.chmod(tmp, 0o666 & ~_umask())  # mkstemp makes 0600
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise
    finally:
        os.close(fd)


def atomic_write(path, data: str | bytes) -> None:
    """Write text or bytes to ``path`` atomically (:func:`atomic_path`)."""
    with atomic_path(path) as tmp:
        if isinstance(data, bytes):
            tmp.write_bytes(data)
        else:
            tmp.write_text(data)


def _kind_of(st) -> str:
    for test, name in (
        (stat.S_ISREG, "a file"),
        (stat.S_ISCHR, "a character device"),
        (stat.S_ISBLK, "a block device"),
        (stat.S_ISFIFO, "a named pipe"),
        (stat.S_ISSOCK, "a socket"),
    ):
        if test(st.st_mode):
            return name
    return "not a folder"


def _why(exc: OSError) -> str:
    return exc.strerror or str(exc)


def check_folder(path, option: str = "--out", shown=None) -> None:
    """InputError naming ``option`` unless ``path`` can be used as an output folder (or
    made: the nearest existing folder above it is writable)."""
    _, problem = folder_problem(Path(os.path.realpath(path)), option, path if shown is None else shown)
    if problem:
        raise InputError(problem)


def folder_problem(path: Path, option: str, shown) -> tuple[Path | None, str | None]:
    """(the nearest folder that exists at or above ``path``, None) or (None, why the
    folder ``path`` can be neither used nor made)."""
    probe = path
    while True:
        try:
            st = os.stat(probe)
        except (FileNotFoundError, NotADirectoryError):
            if probe.parent == probe:
                return None, f"{option} {shown}: no such folder"
            probe = probe.parent
            continue
        except OSError as exc:
            return None, f"{option} {shown}: {_why(exc)}"
        if stat.S_ISDIR(st.st_mode):
            return probe, None
        if probe == path:
            return None, f"{option} {shown} is {_kind_of(st)}, not a folder"
        return None, f"{option} {shown}: {probe} is {_kind_of(st)}, so no folder can be made in it"


class OutputFolder:
    """A command's output folder, replaced as a whole: ``with OutputFolder(out) as tmp``.

    Checked when made, before any computing: ``out`` must be a folder (or creatable),
    writable, and hold nothing but an earlier output (files named in ``replaceable``)
    so that replacing it never deletes a user's files.  The outputs are written into
    ``tmp``, a hidden folder beside ``out``; when the block ends without an error ``tmp``
    takes the place of ``out`` (two renames under a lock of the parent folder), so the
    folder holds either this command's complete output or the previous one, never a mix.
    On an error the temporary is removed and ``out`` is left as it was.  Where ``out``
    cannot be renamed (a mount point, the working folder, another device) the files are
    copied into it and renamed one by one, ``result.json`` removed first and written
    last, so a folder with a ``result.json`` always holds one complete output."""

    def __init__(self, path, option: str = "--out", replaceable=()):
        self.shown = os.fspath(path)
        self.option = option
        if not self.shown.strip():
            raise InputError(f"{option} must name a folder, got {self.shown!r}")
        self.target = Path(os.path.realpath(path))
        if self.target.parent == self.target:
            raise InputError(f"{option} {self.shown}: choose a folder below {self.target}")
        self.replaceable = set(replaceable)
        self.tmp: Path | None = None
        self._fd: int | None = None
        self._made: list[Path] = []
        existing, problem = folder_problem(self.target, option, self.shown)
        if problem:
            raise InputError(problem)
        if existing == self.target:
            self._check_contents()
        try:
            for folder in reversed([self.target.parent, *self.target.parent.parents]):
                if not folder.exists():
                    folder.mkdir()
                    self._made.append(folder)
            remove_leftovers(self.target.parent, self.target.name)
            self.tmp, self._fd = _new_temporary(
                self.target.parent, f".{self.target.name}.", TEMP_MARK, directory=True
            )
            os.chmod(self.tmp, 0o777 & ~_umask())  # mkdtemp makes 0700; an output folder is shared
            if self.target.is_dir():
                remove_leftovers(self.target)
        except OSError as exc:
            self._abandon()
            where = (
                exc.filename if exc.filename and TEMP_MARK not in str(exc.filename) else self.target.parent
            )
            raise InputError(f"{option} {self.shown}: cannot write in {where} ({_why(exc)})") from None

    def _check_contents(self) -> None:
        try:
            names = os.listdir(self.target)
        except OSError as exc:
            raise InputError(f"{self.option} {self.shown}: cannot read the folder ({_why(exc)})") from None
        foreign = sorted(n for n in names if n not in self.replaceable and TEMP_MARK not in n)
        if foreign:
            more = f" and {len(foreign) - 3} more" if len(foreign) > 3 else ""
            raise InputError(
                f"{self.option} {self.shown} holds files that are not the output of a cvtbench "
                f"command ({', '.join(foreign[:3])}{more}); give a new or an empty folder"
            )

    def __enter__(self) -> Path:
        return self.tmp

    def __exit__(self, kind, exc, tb) -> None:
        if kind is None:
            try:
                self._commit()
            except OSError as err:
                self._abandon()
                raise InputError(
                    f"{self.option} {self.shown}: cannot write the output ({_why(err)})"
                ) from None
        else:
            self._abandon()

    def _release(self) -> None:
        if self.tmp is not None:
            shutil.rmtree(self.tmp, ignore_errors=True)
        if self._fd is not None:
            os.close(self._fd)
            self._fd = None

    def _abandon(self) -> None:
        self._release()
        for folder in reversed(self._made):
            try:
                folder.rmdir()
            except OSError:
                break

    def _commit(self) -> None:
        target, tmp = self.target, self.tmp
        with _locked_folder(target.parent):
            try:
                here = Path.cwd().resolve()
            except OSError:
                here = None
            if target.exists() and (
                os.path.ismount(target) or (here is not None and (here == target or target in here.parents))
            ):
                self._commit_in_place()
            else:
                old = tmp.with_name(tmp.name.replace(TEMP_MARK, ".old" + TEMP_MARK))
                try:
                    if target.exists():
                        os.rename(target, old)
                except OSError as exc:
                    if exc.errno not in (errno.EXDEV, errno.EBUSY, errno.EPERM, errno.EACCES):
                        raise
                    self._commit_in_place()
                else:
                    try:
                        os.rename(tmp, target)
                    except OSError:
                        if old.exists():
                            os.rename(old, target)
                        raise
                    os.close(self._fd)
                    self._fd = None
                    shutil.rmtree(old, ignore_errors=True)
                    return
        self._release()

    def _commit_in_place(self) -> None:
        """Swap file by file inside ``target`` (a folder that cannot be renamed)."""
        target = self.target
        inner, fd = _new_temporary(target, ".", TEMP_MARK, directory=True)
        try:
            names = sorted(p.name for p in self.tmp.iterdir())
            for name in names:  # onto the folder's own device: a copy, then renames
                shutil.copy2(self.tmp / name, inner / name)
            first = ["result.json"] if (target / "result.json").exists() else []
            for name in first + sorted(self.replaceable - set(names) - set(first)):
                (target / name).unlink(missing_ok=True)
            for name in sorted(names, key=lambda n: n == "result.json"):
                os.replace(inner / name, target / name)
        finally:
            shutil.rmtree(inner, ignore_errors=True)
            os.close(fd)


@contextmanager
def _locked_folder(folder: Path):
    """An exclusive flock of a folder itself, held briefly (making temporaries, swaps
    and clean-ups); a folder that cannot be opened is used unlocked."""
    try:
        fd = os.open(folder, os.O_RDONLY)
    except OSError:
        yield
        return
    try:
        _lock(fd, wait=True)
        yield
    finally:
        os.close(fd)


_HELD: dict[Path, int] = {}  # folder -> depth: a process re-enters its own lock


def _take_lock_file(path: Path) -> int | None:
    """The descriptor of ``path`` locked by this process, or None when another holds it.
    The file is removed when its lock is given up, so a lock taken on a file that was
    meanwhile removed (or replaced) is given up again and the file opened anew."""
    while True:
        fd = os.open(path, os.O_RDWR | os.O_CREAT, 0o666)
        if not _lock(fd):
            os.close(fd)
            return None
        try:
            same = os.stat(path).st_ino == os.fstat(fd).st_ino
        except FileNotFoundError:
            same = False
        if same:
            return fd
        os.close(fd)


@contextmanager
def report_folder(path, option: str = "--out", command: str | None = None):
    """A sweep's report folder, checked, made if needed and locked for the whole
    command: a second command into the same folder exits 2 naming the one that holds
    it (pid, command, start), instead of mixing its rows with ours.  The leftovers of
    killed writers in the folder are removed once the lock is held.  The lock is a
    hidden file, ``.cvtbench.lock``, that holds who has it and goes when it is given up."""
    shown = os.fspath(path)
    folder = Path(os.path.realpath(path))
    if folder in _HELD:
        _HELD[folder] += 1
        try:
            yield folder
        finally:
            _HELD[folder] -= 1
        return
    check_folder(folder, option, shown)
    lock = folder / LOCK_NAME
    try:
        folder.mkdir(parents=True, exist_ok=True)
        fd = _take_lock_file(lock)
    except OSError as exc:
        raise InputError(
            f"{option} {shown}: cannot write in {exc.filename or folder} ({_why(exc)})"
        ) from None
    if fd is None:
        try:
            holder = lock.read_text(errors="replace").strip()
        except OSError:
            holder = ""
        raise InputError(
            f"{option} {shown} is in use by {holder or 'another cvtbench command'}; wait for it "
            f"to end or choose another {option}"
        )
    try:
        started = time.strftime("%Y-%m-%d %H:%M:%S")
        os.ftruncate(fd, 0)
        os.pwrite(
            fd,
            f"cvtbench pid {os.getpid()} on {platform.node()} (`{command or command_line()}`, "
            f"since {started})\n".encode(),
            0,
        )
        remove_leftovers(folder, recursive=True)
        _HELD[folder] = 1
        try:
            yield folder
        finally:
            del _HELD[folder]
            lock.unlink(missing_ok=True)  # still locked: a waiting command re-opens the path
    finally:
        os.close(fd)


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
    if hasattr(obj, "geom_type"):  # a shapely geometry: its outline, as result.json lists it
        from compact_distributions.cvt.mosaic.render import element_coordinates

        return element_coordinates([obj])[0]
    return obj


def _item_texts(value) -> list[str] | None:
    """The JSON text of each item of a list, built whole-array where the list is a
    finite float or an integer array (1-D or rows) or a list of shapely geometries and
    None (their outlines); None for anything else (converted item by item)."""
    from compact_distributions.cvt.mosaic.render import element_coordinates_json, format_rows

    if isinstance(value, np.ndarray) and value.ndim in (1, 2) and value.size:
        ints = np.issubdtype(value.dtype, np.integer)
        if not ints and not (np.issubdtype(value.dtype, np.floating) and np.isfinite(value).all()):
            return None
        field = "{}" if ints else "{!r}"  # what json writes for a Python int / float
        if value.ndim == 1:
            return list(map(str if ints else repr, value.tolist()))
        row = "[" + ", ".join([field] * value.shape[1]) + "]\n"
        return [line[:-1] for line in format_rows(row, list(value.T))]
    geoms = _geometries_or_none(value)
    if geoms is not None:
        return element_coordinates_json(geoms)
    return None


def _geometries_or_none(value) -> np.ndarray | None:
    """``value`` as an object array where it is a list of shapely geometries and None
    (element outlines), tested whole-array; None otherwise."""
    import shapely

    if not isinstance(value, (list, tuple)) or not value:
        return None
    geoms = np.empty(len(value), dtype=object)
    geoms[:] = list(value)
    return geoms if shapely.is_valid_input(geoms).all() and shapely.is_geometry(geoms).any() else None


JSON_BLOCK = 1024  # items of a long list converted at once
OUTLINE_VERTICES = 1 << 17  # vertices of element outlines converted at once (whole-array text)


def _outline_blocks(geoms: np.ndarray) -> list[slice]:
    """Consecutive slices of ``geoms`` of about :data:`OUTLINE_VERTICES` vertices each (at
    least one element): the text of a block is built whole-array in bounded memory."""
    import shapely

    ends = np.cumsum(shapely.get_num_coordinates(geoms))
    cuts = np.searchsorted(ends, np.arange(OUTLINE_VERTICES, ends[-1], OUTLINE_VERTICES), side="right")
    edges = np.unique(np.concatenate([[0], cuts, [len(geoms)]])).tolist()
    return [slice(a, b) for a, b in zip(edges[:-1], edges[1:], strict=True)]


def json_chunks(data: dict):
    """The text of :func:`dumps` piece by piece: one top-level key per line, each value
    compact; long lists (sites, element outlines) are converted a block of items at a
    time, so writing a result never holds a second copy of it."""
    yield "{\n"
    for i, (key, value) in enumerate(data.items()):
        yield from _member_chunks(i, key, value)
    yield "\n}\n"


def _member_chunks(i: int, key, value):
    """The text of the ``i``-th top-level member of :func:`json_chunks`, piece by piece."""
    yield (",\n" if i else "") + f" {json.dumps(str(key))}: "
    yield from _value_chunks(value)


def _value_chunks(value):
    """The compact JSON text of one top-level value, piece by piece (:func:`json_chunks`)."""
    from compact_distributions.cvt.mosaic.render import element_coordinates_json

    if not (isinstance(value, (list, tuple, np.ndarray)) and len(value) > 64):
        yield json.dumps(to_jsonable(value))
        return
    yield "["
    geoms = _geometries_or_none(value)
    if geoms is not None:
        blocks = _outline_blocks(geoms)
    else:
        blocks = [slice(j, j + JSON_BLOCK) for j in range(0, len(value), JSON_BLOCK)]
    for block in blocks:  # a block of items at a time
        if geoms is not None:
            items = element_coordinates_json(geoms[block])
        else:
            items = _item_texts(value[block])
        if items is None:
            items = [json.dumps(to_jsonable(item)) for item in value[block]]
        yield (", " if block.start else "") + ", ".join(items)
    yield "]"


def dumps(data: dict) -> str:
    """JSON with one top-level key per line and each value compact (site lists stay short)."""
    return "".join(json_chunks(data))


def write_json(path, data) -> None:
    write_lines(path, json_chunks(data))


def write_result_json(path, result: dict, beside: Beside) -> None:
    """``result`` written to ``path`` as :func:`write_json` writes it, once the work
    ``beside`` has finished, the time waited for it added to its
    ``stage_seconds["writing"]``.  Every other member is turned into text while that
    work runs: those before ``stage_seconds`` into the file, those after it into a
    temporary file beside it, copied in at the end (never held whole).

    Parameters
    ----------
    path : path-like
        The file written.
    result : dict
        A result record (:func:`bench.results.build_result`) with a ``stage_seconds``
        dict holding ``"writing"``; its writing time is updated in place.
    beside : Beside
        The work that counts as writing and must end first.
    """
    keys = list(result)
    at = keys.index("stage_seconds")
    with open(path, "w") as fh, tempfile.TemporaryFile("w+", dir=Path(path).parent) as rest:
        fh.write("{\n")
        for i, key in enumerate(keys):
            if i != at:
                (fh if i < at else rest).writelines(_member_chunks(i, key, result[key]))
        result["stage_seconds"]["writing"] += beside.wait()
        fh.writelines(_member_chunks(at, "stage_seconds", result["stage_seconds"]))
        rest.seek(0)
        shutil.copyfileobj(rest, fh)
        fh.write("\n}\n")


def write_lines(path, chunks) -> None:
    """Write text that comes in pieces (a generator), never held whole."""
    with open(path, "w") as fh:
        for chunk in chunks:
            fh.write(chunk)


def write_sites_csv(path, sites, angles, scales) -> None:
    from compact_distributions.cvt.mosaic.render import format_rows

    sites = np.asarray(sites, dtype=np.float64).reshape(-1, 2)
    angles, scales = np.asarray(angles, dtype=np.float64), np.asarray(scales, dtype=np.float64)
    if not len(sites) == len(angles) == len(scales):
        raise ValueError(f"{len(sites)} sites, {len(angles)} angles and {len(scales)} scales")
    rows = format_rows(
        "{:.6f},{:.6f},{:.6f},{:.6f}\n", [sites[:, 0], sites[:, 1], np.degrees(angles), scales]
    )
    Path(path).write_text("".join(["x,y,angle_deg,scale\n", *rows]))


PNG_LEVEL = 1  # zlib level of the pictures: after the Up filter, level 1 is within 5 % of 6
PNG_BAND = 1 << 22  # bytes of picture filtered and compressed at once


def _png_chunk(kind: bytes, data: bytes) -> bytes:
    return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data))


def png_chunks(image, level: int = PNG_LEVEL):
    """The bytes of an 8-bit RGB PNG of ``image`` piece by piece, a band of rows at a time.

    Every row is written with PNG's Up filter (its difference from the row above), computed
    whole-array, and deflated by zlib at ``level``: the pixels PIL's writer stores, in a
    few times less time (PIL tries five filters on every row and deflates at level 6),
    in files of about the same size for the suite's flat-coloured pictures.

    Parameters
    ----------
    image : PIL.Image.Image, numpy.ndarray or row source
        An RGB picture, an (H, W, 3) uint8 array, or an object with ``size`` (W, H)
        and ``rows(lo, hi)`` giving rows lo .. hi - 1 as (hi - lo, W, 3) uint8
        (``cvt.mosaic.render.CellRows``: the picture never whole in memory).
    level : int, optional
        zlib's compression level, 0 to 9.

    Yields
    ------
    bytes
        The signature, the header, the compressed rows and the end, in file order.
    """
    if hasattr(image, "rows") and hasattr(image, "size"):  # a source of bands of rows
        width, height = image.size

        def rows(lo: int, hi: int) -> np.ndarray:
            return np.ascontiguousarray(image.rows(lo, hi)).reshape(hi - lo, 3 * width)
    elif isinstance(image, np.ndarray):
        pixels = np.asarray(image, dtype=np.uint8)
        if pixels.ndim != 3 or pixels.shape[2] != 3:
            raise ValueError(f"a PNG needs an (H, W, 3) array, got shape {pixels.shape}")
        height, width = pixels.shape[:2]

        def rows(lo: int, hi: int) -> np.ndarray:
            return pixels[lo:hi].reshape(hi - lo, 3 * width)
    else:
        picture = image if image.mode == "RGB" else image.convert("RGB")
        width, height = picture.size

        def rows(lo: int, hi: int) -> np.ndarray:  # a band at a time: no full-size copy
            return np.asarray(picture.crop((0, lo, width, hi))).reshape(hi - lo, 3 * width)

    yield b"\x89PNG\r\n\x1a\n"
    yield _png_chunk(b"IHDR", struct.pack(">IIBBBBB", width, height, 8, 2, 0, 0, 0))
    deflate = zlib.compressobj(level)
    step = max(1, PNG_BAND // max(1, 3 * width))
    above = np.zeros(3 * width, dtype=np.uint8)
    for lo in range(0, height, step):
        band = rows(lo, min(height, lo + step))
        out = np.empty((len(band), 3 * width + 1), dtype=np.uint8)
        out[:, 0] = 2  # Up: each byte less the byte above it (modulo 256)
        np.subtract(band[:1], above, out=out[:1, 1:])
        np.subtract(band[1:], band[:-1], out=out[1:, 1:])
        above = band[-1].copy()
        data = deflate.compress(out)
        if data:
            yield _png_chunk(b"IDAT", data)
    yield _png_chunk(b"IDAT", deflate.flush())
    yield _png_chunk(b"IEND", b"")


def write_png(path, image, level: int = PNG_LEVEL) -> None:
    """Write ``image`` (a PIL RGB picture, an (H, W, 3) uint8 array or a row source) as a
    PNG file (:func:`png_chunks`)."""
    with open(path, "wb") as fh:
        for chunk in png_chunks(image, level):
            fh.write(chunk)


def command_line(argv=None) -> str:
    import shlex

    argv = sys.argv[1:] if argv is None else argv
    return "cvtbench " + shlex.join(argv)


class Beside:
    """Work run in one thread beside the command's own (writing the pictures: their
    gathers, conversions and zlib release the GIL), or at once where the process has one
    core.  ``wait()`` returns the seconds spent waiting for it and re-raises its error; leaving
    the block waits too, so no file is written after its folder is committed."""

    def __init__(self) -> None:
        from compact_distributions.cvt.threads import usable_cores

        self._pool = None
        if usable_cores() > 1:
            from concurrent.futures import ThreadPoolExecutor

            self._pool = ThreadPoolExecutor(max_workers=1, thread_name_prefix="cvtbench-writer")
        self._jobs: list = []

    def __enter__(self) -> Beside:
        return self

    def run(self, fn, *args) -> None:
        """Run ``fn(*args)`` beside (in order with the other jobs), or now."""
        if self._pool is None:
            fn(*args)
        else:
            self._jobs.append(self._pool.submit(fn, *args))

    def wait(self) -> float:
        t0 = time.perf_counter()
        jobs, self._jobs = self._jobs, []
        for job in jobs:
            job.result()
        return time.perf_counter() - t0

    def __exit__(self, *exc) -> None:
        if self._pool is not None:
            self._pool.shutdown(wait=True)


__all__ = [
    "PACKAGES",
    "versions",
    "machine",
    "TEMP_MARK",
    "COMMAND_OUTPUTS",
    "LOCK_NAME",
    "remove_leftovers",
    "atomic_path",
    "atomic_write",
    "check_folder",
    "folder_problem",
    "OutputFolder",
    "report_folder",
    "to_jsonable",
    "JSON_BLOCK",
    "OUTLINE_VERTICES",
    "json_chunks",
    "dumps",
    "write_json",
    "write_result_json",
    "write_lines",
    "write_sites_csv",
    "PNG_LEVEL",
    "PNG_BAND",
    "png_chunks",
    "write_png",
    "command_line",
    "Beside",
]
