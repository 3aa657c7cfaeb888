"""The one output writer (bench/outputs.py): destinations checked before any work, a
command's folder replaced whole or left as it was, leftovers of killed writers removed,
sweeps' folders locked, files written atomically by any number of writers."""

from __future__ import annotations

import errno
import json
import os
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest

from compact_distributions.bench import outputs
from compact_distributions.bench.commands.cli import main
from compact_distributions.bench.outputs import (
    COMMAND_OUTPUTS,
    TEMP_MARK,
    OutputFolder,
    atomic_write,
    remove_leftovers,
    report_folder,
)
from compact_distributions.cvt.errors import InputError

from .hostile import CLI

RUN = ["run", "--size", "48", "--elements", "12", "--iterations", "1", "--quiet"]
RUN_FILES = ["cells.png", "elements.png", "elements.svg", "result.json", "sites.csv"]


def names(folder: Path) -> list[str]:
    return sorted(p.name for p in folder.iterdir())


def hold_lock(path: Path):
    """A child process that holds an flock on ``path`` until killed: a live writer."""
    code = (
        "import fcntl, os, sys, time; fd = os.open(sys.argv[1], os.O_RDONLY); "
        "fcntl.flock(fd, fcntl.LOCK_EX); print('locked', flush=True); time.sleep(60)"
    )
    proc = subprocess.Popen([sys.executable, "-c", code, str(path)], stdout=subprocess.PIPE)
    assert proc.stdout.readline().strip() == b"locked"
    return proc


# ---------------------------------------------------------------- a command's folder
def test_a_run_replaces_a_mosaic_folder_whole(tmp_path, capsys):
    out = tmp_path / "out"
    out.mkdir()
    for name in ("mosaic.svg", "mosaic.png", "result.json", "compare_field.png"):
        (out / name).write_text("old")
    assert main(RUN + ["--out", str(out)]) == 0
    assert names(out) == RUN_FILES  # nothing of the mosaic is left beside the run
    assert json.loads((out / "result.json").read_text())["kind"] == "run"
    assert names(tmp_path) == ["out"]  # no temporary beside it


def test_a_failing_command_leaves_the_previous_output(tmp_path, capsys, monkeypatch):
    out = tmp_path / "out"
    assert main(RUN + ["--out", str(out)]) == 0
    before = {n: (out / n).read_bytes() for n in names(out)}

    def broken(*a, **k):
        raise InputError("the method broke half-way")

    monkeypatch.setattr("compact_distributions.baselines.get_method", lambda name: broken)
    assert main(RUN + ["--out", str(out), "--seed", "3"]) == 2
    assert {n: (out / n).read_bytes() for n in names(out)} == before
    assert names(tmp_path) == ["out"]


@pytest.mark.parametrize("picture", ["cells.png", "elements.png"])
def test_a_picture_failing_beside_the_command_leaves_the_previous_output(
    tmp_path, capsys, monkeypatch, picture
):
    """The pictures are written in a thread beside the command: an error there is the
    command's error (exit 2, its one line), and the folder keeps the previous output."""
    out = tmp_path / "out"
    assert main(RUN + ["--out", str(out)]) == 0
    before = {n: (out / n).read_bytes() for n in names(out)}
    write_png = outputs.write_png

    def broken(path, image, *args):
        if Path(path).name == picture:
            raise InputError(f"{picture} broke half-way")
        write_png(path, image, *args)

    monkeypatch.setattr(outputs, "write_png", broken)
    capsys.readouterr()
    assert main(RUN + ["--out", str(out), "--seed", "3"]) == 2
    assert f"{picture} broke half-way" in capsys.readouterr().err
    assert {n: (out / n).read_bytes() for n in names(out)} == before
    assert names(tmp_path) == ["out"]


@pytest.mark.parametrize(
    "where,message",
    [
        ("file", "is a file, not a folder"),
        ("/dev/null", "is a character device, not a folder"),
        ("under-file", "is a file, so no folder can be made in it"),
        ("/proc/cvtbench-test-out", "cannot write in /proc"),
        ("foreign", "holds files that are not the output of a cvtbench command (notes.txt)"),
    ],
)
def test_bad_destinations_are_refused_before_any_work(where, message, tmp_path, capsys, monkeypatch):
    afile = tmp_path / "afile"
    afile.write_text("keep me")
    out = {"file": afile, "under-file": afile / "x", "foreign": tmp_path / "mine"}.get(where, Path(where))
    if where == "foreign":
        out.mkdir()
        (out / "notes.txt").write_text("keep me")
        (out / "result.json").write_text("{}")
    ran = []
    monkeypatch.setattr("compact_distributions.cvt.lloyd.lloyd", lambda *a, **k: ran.append(1))
    assert main(RUN + ["--out", str(out)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and message in err[0], err
    assert ran == []
    assert afile.read_text() == "keep me"
    if where == "foreign":
        assert names(out) == ["notes.txt", "result.json"]
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted(
        ["afile"] + (["mine"] if where == "foreign" else [])
    )


def test_parents_made_for_a_failed_command_are_removed(tmp_path, capsys):
    out = tmp_path / "a" / "b" / "out"
    assert main(RUN + ["--out", str(out), "--density", str(tmp_path / "missing.png")]) == 2
    assert not (tmp_path / "a").exists()


def test_cross_device_folders_are_swapped_file_by_file(tmp_path, capsys, monkeypatch):
    """Where the folder cannot be renamed (EXDEV, or a mount point), the files are copied
    onto its device and renamed in, result.json last; stale files of the command go."""
    out = tmp_path / "out"
    out.mkdir()
    (out / "mosaic.svg").write_text("stale")
    (out / "result.json").write_text("{}")
    real = os.rename
    order = []

    def rename(src, dst):
        if Path(src) == out:
            raise OSError(errno.EXDEV, "Invalid cross-device link")
        return real(src, dst)

    def replace(src, dst, real_replace=os.replace):
        order.append(Path(dst).name)
        return real_replace(src, dst)

    monkeypatch.setattr(outputs.os, "rename", rename)
    monkeypatch.setattr(outputs.os, "replace", replace)
    assert main(RUN + ["--out", str(out)]) == 0
    assert names(out) == RUN_FILES and order[-1] == "result.json"
    assert names(tmp_path) == ["out"]


def test_mount_points_and_the_working_folder_are_swapped_in_place(tmp_path, capsys, monkeypatch):
    out = tmp_path / "out"
    out.mkdir()
    (out / "elements.png").write_text("stale")
    monkeypatch.chdir(out)  # replacing the folder would pull it from under the shell
    assert main(RUN + ["--out", "."]) == 0
    assert names(out) == RUN_FILES and (out / "elements.png").read_bytes()[:4] == b"\x89PNG"
    monkeypatch.chdir(tmp_path)
    monkeypatch.setattr(outputs.os.path, "ismount", lambda p: Path(p) == out)
    assert main(RUN + ["--out", str(out), "--seed", "2"]) == 0
    assert names(out) == RUN_FILES and names(tmp_path) == ["out"]


def test_leftovers_of_dead_writers_go_and_live_ones_stay(tmp_path):
    dead_dir = tmp_path / f".out.abcdefgh{TEMP_MARK}"
    dead_dir.mkdir()
    (dead_dir / "result.json").write_text("{}")
    dead_file = tmp_path / f".table2.md.abcdefgh{TEMP_MARK}.md"
    dead_file.write_text("half")
    live = tmp_path / f".out.live1234{TEMP_MARK}"
    live.mkdir()
    user = tmp_path / ".out.hidden"  # not ours: never touched
    user.mkdir()
    holder = hold_lock(live)
    try:
        removed = remove_leftovers(tmp_path)
    finally:
        holder.kill()
        holder.wait()
    assert sorted(p.name for p in removed) == sorted([dead_dir.name, dead_file.name])
    assert live.exists() and user.exists()
    assert remove_leftovers(tmp_path) == [live]  # its writer is gone now


def test_a_swap_cut_between_its_renames_is_undone(tmp_path):
    """Killed after the old folder was moved aside and before the new one arrived: the
    next command puts the old one back (a folder is never lost or mixed)."""
    backup = tmp_path / f".out.abcdefgh.old{TEMP_MARK}"
    backup.mkdir()
    (backup / "result.json").write_text('{"kind": "run"}')
    staging = tmp_path / f".out.abcdefgh{TEMP_MARK}"
    staging.mkdir()
    with OutputFolder(tmp_path / "out", replaceable=COMMAND_OUTPUTS) as tmp:
        assert (tmp_path / "out" / "result.json").read_text() == '{"kind": "run"}'
        assert not backup.exists() and not staging.exists()
        (tmp / "result.json").write_text('{"kind": "mosaic"}')
    assert (tmp_path / "out" / "result.json").read_text() == '{"kind": "mosaic"}'


@pytest.mark.slow
def test_killed_runs_leave_the_previous_or_the_new_output_and_no_temporaries(tmp_path):
    out = tmp_path / "out"
    base = [
        *CLI,
        "run",
        "--size",
        "200",
        "--elements",
        "1500",
        "--iterations",
        "3",
        "--quiet",
        "--out",
        str(out),
    ]
    assert subprocess.run(base, capture_output=True).returncode == 0
    for seed, delay in enumerate((0.8, 1.3, 1.8, 2.3, 2.8), start=1):
        proc = subprocess.Popen(base + ["--seed", str(seed)], stderr=subprocess.DEVNULL)
        time.sleep(delay)
        proc.send_signal(signal.SIGKILL)
        proc.wait()
        assert names(out) == RUN_FILES  # one whole output, whichever it is
        json.loads((out / "result.json").read_text())
    assert subprocess.run(base + ["--seed", "9"], capture_output=True).returncode == 0
    assert names(tmp_path) == ["out"]
    assert json.loads((out / "result.json").read_text())["seed"] == 9


# ---------------------------------------------------------------- files
def test_concurrent_writers_of_one_file_never_collide(tmp_path):
    path = tmp_path / "report.md"
    errors = []

    def writer(k):
        try:
            for _ in range(20):
                atomic_write(path, f"writer {k}\n" * 2000)
        except Exception as exc:  # noqa: BLE001 - any failure fails the test
            errors.append(exc)

    threads = [threading.Thread(target=writer, args=(k,)) for k in range(4)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert errors == []
    text = path.read_text()
    assert len(set(text.splitlines())) == 1 and text.count("\n") == 2000  # one writer's whole file
    assert names(tmp_path) == ["report.md"]


def test_a_file_writer_removes_what_a_killed_writer_of_that_file_left(tmp_path):
    left = tmp_path / f".table2.csv.zzzzzzzz{TEMP_MARK}.csv"
    left.write_text("half a tab")
    other = tmp_path / f".other.csv.zzzzzzzz{TEMP_MARK}.csv"
    other.write_text("another file's")
    atomic_write(tmp_path / "table2.csv", "a,b\n")
    assert not left.exists() and other.exists()
    assert (tmp_path / "table2.csv").read_text() == "a,b\n"
    assert oct((tmp_path / "table2.csv").stat().st_mode & 0o044) == oct(0o044)  # readable by all


# ---------------------------------------------------------------- sweeps
def test_a_second_command_into_a_locked_folder_exits_2_naming_the_holder(tmp_path, capsys):
    code = (
        "import sys, time; from compact_distributions.bench.outputs import report_folder\n"
        "with report_folder(sys.argv[1], command='cvtbench table2 --quick'):\n"
        "    print('locked', flush=True); time.sleep(60)\n"
    )
    holder = subprocess.Popen([sys.executable, "-c", code, str(tmp_path)], stdout=subprocess.PIPE)
    try:
        assert holder.stdout.readline().strip() == b"locked"
        assert (
            main(
                [
                    "table2",
                    "--quick",
                    "--methods",
                    "ours",
                    "--backends",
                    "numpy",
                    "--shapes",
                    "square",
                    "--seeds",
                    "1",
                    "--quiet",
                    "--out",
                    str(tmp_path),
                ]
            )
            == 2
        )
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and f"pid {holder.pid}" in err[0] and "cvtbench table2 --quick" in err[0], err
        assert not (tmp_path / "raw").exists() and not (tmp_path / "table2.md").exists()
    finally:
        holder.kill()
        holder.wait()


def test_the_lock_is_reentrant_in_one_process_and_released(tmp_path):
    with report_folder(tmp_path, command="outer"):
        with report_folder(tmp_path, command="inner"):
            pass
        assert "outer" in (tmp_path / outputs.LOCK_NAME).read_text()
    assert not (tmp_path / outputs.LOCK_NAME).exists()  # given up, and gone
    probe = subprocess.run(
        [
            sys.executable,
            "-c",
            "import sys; from compact_distributions.bench.outputs import "
            "report_folder\nwith report_folder(sys.argv[1]): pass",
            str(tmp_path),
        ]
    )
    assert probe.returncode == 0


def test_reports_name_only_the_files_that_exist(tmp_path, capsys, monkeypatch):
    """A sweep where nothing ran has no picture: the report does not point to one, the
    summary does not claim one, and a picture left by an earlier sweep is removed."""
    monkeypatch.setenv("PYOPENCL_CTX", "99")  # no such platform: every opencl run is skipped
    (tmp_path / "table2.png").write_bytes(b"an older sweep's picture")
    (tmp_path / "backends.png").write_bytes(b"an older sweep's plot")
    assert (
        main(
            [
                "table2",
                "--quick",
                "--methods",
                "ours",
                "--backends",
                "opencl",
                "--shapes",
                "square",
                "--seeds",
                "1",
                "--quiet",
                "--out",
                str(tmp_path),
            ]
        )
        == 0
    )
    assert (
        main(
            [
                "backends",
                "--quick",
                "--backends",
                "opencl",
                "--metrics",
                "l2",
                "--elements",
                "100",
                "--sizes",
                "64",
                "--quiet",
                "--out",
                str(tmp_path),
            ]
        )
        == 0
    )
    err = capsys.readouterr().err
    assert "table2.png" not in err and "backends.png" not in err
    assert not (tmp_path / "table2.png").exists() and not (tmp_path / "backends.png").exists()
    assert "The picture `table2.png` shows" not in (tmp_path / "table2.md").read_text()
    assert "`backends.png`" not in (tmp_path / "backends.md").read_text()
