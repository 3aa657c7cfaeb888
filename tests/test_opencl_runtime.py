"""The OpenCL device check: a device is used only once a child process has built every
program the backend builds on it, with their kernels.

A runtime can build a program "successfully" with no kernels in it and then abort the
process at exit (the PoCL wheel that pyopencl brings does so on newer processors for
every program it reads back from its kernel cache).  These tests put fake runtimes and
real child processes in its place: a program with no kernels is refused with the
reason, one that loses them only in the cache is built outside it, a child that aborts
is a device with the reason (pytest lives on), and the verdicts are kept so that the
check costs once.  The real runtime's pass is .ci/run's second run of the OpenCL tests
with only the PoCL wheel visible.
"""

import json
import os
import sys
import textwrap
import types

import numpy as np
import pytest

import compact_distributions.backends.opencl as ocl_module
from compact_distributions.backends import REFERENCE, fall_back, first_available
from compact_distributions.cvt.errors import BackendUnavailable

SUITE_KERNELS = set(ocl_module.LABEL_KERNELS) | {"fit_search"}


class FakeError(Exception):
    pass


def fake_runtime(names_by_build):
    """A stand-in for pyopencl with one CPU device whose builds hold the kernels that
    ``names_by_build(options)`` names (a list of every build's options is kept)."""
    builds = []
    platform = types.SimpleNamespace(name="Fake CL", version="OpenCL 3.0 fake 1.0")
    device = types.SimpleNamespace(
        name="fake-cpu",
        type=2,
        driver_version="1.0",
        extensions="cl_khr_int64_base_atomics cl_khr_fp64",
        platform=platform,
    )
    platform.get_devices = lambda: [device]

    class Program:
        def __init__(self, ctx, source):
            self.source = source

        def build(self, options=()):
            builds.append(list(options))
            self.names = names_by_build(list(options))
            return self

        def get_info(self, what):
            return ";".join(self.names)

    cl = types.SimpleNamespace(
        Error=FakeError,
        get_platforms=lambda: [platform],
        device_type=types.SimpleNamespace(GPU=4, CPU=2, to_string=lambda t: "CPU"),
        program_info=types.SimpleNamespace(KERNEL_NAMES="names"),
        Context=lambda devs: object(),
        Program=Program,
    )
    return cl, device, builds


@pytest.fixture(autouse=True)
def own_verdicts(tmp_path, monkeypatch):
    """Each test keeps its verdicts in its own file, with none known yet."""
    monkeypatch.setattr(ocl_module, "verdict_path", lambda: tmp_path / "verdicts.json")
    monkeypatch.setattr(ocl_module, "_VERDICTS", None)
    monkeypatch.setattr(ocl_module, "_FRESH", set())


def child_module(tmp_path, monkeypatch, body: str) -> None:
    """Make the device check's child run ``body`` (a real process: python -m)."""
    (tmp_path / "fake_check_child.py").write_text(textwrap.dedent(body))
    monkeypatch.setenv("PYTHONPATH", f"{tmp_path}{os.pathsep}{os.environ.get('PYTHONPATH', '')}")
    monkeypatch.setattr(ocl_module, "CHECK_ENTRY", "fake_check_child")


ANSWER = textwrap.dedent(f"""
    import json, os, sys
    payload = json.loads(sys.stdin.read())
    def say(verdict):
        sys.stdout.write({ocl_module.CHECK_MARK!r} + json.dumps(verdict) + "\\n")
        sys.stdout.flush()
    ok = {{"ok": True, "reason": ""}}
    empty = {{"ok": False, "empty": True, "reason": "built without its kernels"}}
""")


# ------------------------------------------------------------ in the child process
def test_a_program_built_without_its_kernels_is_refused_with_the_reason(monkeypatch):
    """The child's check, on a runtime whose programs hold no kernels: the first program
    is found empty, with the kernels it lacks; built anew (outside the cache, each with
    a build option of its own) they are still empty, and the device is refused."""
    cl, device, builds = fake_runtime(lambda opts: [])
    monkeypatch.setattr(ocl_module, "_import_pyopencl", lambda: cl)
    programs = ocl_module.suite_programs(*ocl_module.device_config(cl, device))
    payload = {
        "platform": 0,
        "device": 0,
        "identity": list(ocl_module.device_identity(device)),
        "programs": [[[str(f) for f in p.files], list(p.options), list(p.kernels)] for p in programs],
        "config": None,
        "fresh": False,
    }
    out = ocl_module._check_here(payload)
    assert not out["ok"] and out["empty"] and builds == [[], list(programs[0].options)]  # the probe, then
    assert "without its kernels (label_pixels, label_blocks, row_moments)" in out["reason"]
    assert programs[0].options[0] in out["reason"]
    # outside the cache: each build with an option no build had before
    builds.clear()
    fresh = ocl_module._check_here({**payload, "fresh": True})
    assert not fresh["ok"] and "without its kernels" in fresh["reason"]
    tags = [o for b in builds for o in b if o.startswith("-DCVT_FRESH_BUILD=")]
    assert len(builds) == 2 and len(tags) == 1


def test_a_runtime_that_loses_kernels_only_in_its_cache_is_used_outside_it(monkeypatch):
    """Built twice (the second read back from the cache): a program whose second build
    holds no kernels makes the child say "empty", and the check then builds it anew."""
    seen = set()

    def names(opts):
        key = tuple(o for o in opts if not o.startswith("-DCVT_FRESH_BUILD="))
        fresh = len(key) < len(opts)
        if key in seen and not fresh:
            return []  # read back from the cache: no kernels
        seen.add(key)
        return sorted(SUITE_KERNELS)

    cl, device, _ = fake_runtime(names)
    monkeypatch.setattr(ocl_module, "_import_pyopencl", lambda: cl)
    spec = ocl_module.label_program(False, 4, 8, True, True)
    payload = {
        "platform": 0,
        "device": 0,
        "identity": list(ocl_module.device_identity(device)),
        "programs": [[[str(f) for f in spec.files], list(spec.options), list(spec.kernels)]],
        "config": None,
        "fresh": False,
    }
    assert ocl_module._check_here(payload)["empty"]
    assert ocl_module._check_here({**payload, "fresh": True})["ok"]


def test_a_child_that_aborts_is_an_unusable_device_and_pytest_lives_on(tmp_path, monkeypatch):
    """The runtime aborts the child (as PoCL does): the device is unavailable with the
    signal and the runtime's last line, the one named is refused with the install hint,
    and this process is untouched."""
    child_module(
        tmp_path, monkeypatch, "import os, sys\nprint('LLVM ERROR: giving up', file=sys.stderr)\nos.abort()\n"
    )
    cl, device, _ = fake_runtime(lambda opts: [])
    with pytest.raises(BackendUnavailable) as err:
        ocl_module.choose_device(cl, "0:0")
    text = str(err.value)
    assert text.startswith("opencl: device=0:0 cannot run the suite's kernels (Fake CL / fake-cpu (CPU): ")
    assert "check crashed (signal SIGABRT)" in text
    assert "LLVM ERROR: giving up" in text and "apt-get install pocl-opencl-icd" in text and "\n" not in text
    # the default choice passes it over the same way: no device left, the same reason
    with pytest.raises(BackendUnavailable, match="no OpenCL device runs the suite's kernels.*SIGABRT"):
        ocl_module.choose_device(cl, None)


def test_a_verdict_said_before_the_child_dies_is_taken(tmp_path, monkeypatch):
    """PoCL aborts at exit once a program came back empty: the child's verdict line,
    printed before, is what counts."""
    child_module(tmp_path, monkeypatch, ANSWER + "say(ok)\nos.abort()\n")
    cl, device, _ = fake_runtime(lambda opts: [])
    assert ocl_module.choose_device(cl, None) is device


def test_verdicts_are_kept_so_the_check_costs_once(tmp_path, monkeypatch):
    """A second process finds the verdicts in the file and starts no child; a changed
    kernel file is a new program and is checked again."""
    child_module(tmp_path, monkeypatch, ANSWER + "say(ok)\n")
    cl, device, _ = fake_runtime(lambda opts: [])
    assert ocl_module.suite_problem(cl, device) is None
    kept = json.loads((tmp_path / "verdicts.json").read_text())
    assert [v["ok"] for v in kept.values()] == [True] and "fake-cpu" in next(iter(kept.values()))["device"]
    # a new process: its own copy read from the file; a child now would fail the device
    monkeypatch.setattr(ocl_module, "_VERDICTS", None)
    child_module(tmp_path, monkeypatch, "import os\nos.abort()\n")
    assert ocl_module.suite_problem(cl, device) is None
    edited = tmp_path / "edited.cl"
    edited.write_text(ocl_module.KERNEL_FILE.read_text() + "\n// edited\n")
    monkeypatch.setattr(ocl_module, "KERNEL_FILE", edited)
    assert "SIGABRT" in ocl_module.suite_problem(cl, device)


def test_programs_empty_from_the_cache_make_every_build_fresh(tmp_path, monkeypatch):
    """The child says empty when built as usual and whole when built anew: the device is
    usable, and this process then builds every program outside the cache."""
    child_module(
        tmp_path,
        monkeypatch,
        ANSWER + "say(ok if payload['fresh'] else empty)\n",
    )
    cl, device, _ = fake_runtime(lambda opts: [])
    assert ocl_module.suite_problem(cl, device) is None
    assert ocl_module.device_identity(device) in ocl_module._FRESH
    kept = json.loads((tmp_path / "verdicts.json").read_text())
    assert all(v["ok"] and v["fresh"] for v in kept.values())


# ------------------------------------------------------------------ in this process
def test_an_empty_program_in_process_is_built_once_more_outside_the_cache_then_refused(monkeypatch):
    """Past the check, a program that still comes without its kernels is built once
    more with a fresh cache key; empty again, the backend is unavailable, saying why."""
    cl, device, builds = fake_runtime(lambda opts: [])
    backend = object.__new__(ocl_module.OpenCLBackend)
    spec = ocl_module.label_program(True, 0, 8, True, True)
    backend._cl, backend._device, backend._context, backend._checked = cl, device, object(), {spec}
    with pytest.raises(BackendUnavailable, match="without its kernels.*apt-get install pocl-opencl-icd"):
        backend._build(spec)
    assert len(builds) == 2
    assert not any(o.startswith("-DCVT_FRESH_BUILD") for o in builds[0])
    assert any(o.startswith("-DCVT_FRESH_BUILD") for o in builds[1])


def test_a_default_that_cannot_run_falls_back_to_the_reference_saying_so_once(capsys):
    assert fall_back("no-such-backend", "its runtime is missing") == REFERENCE
    assert fall_back("no-such-backend", "its runtime is missing") == REFERENCE
    err = capsys.readouterr().err.splitlines()
    assert err == [f"note: using {REFERENCE}, as no-such-backend cannot run here: its runtime is missing"]


# ------------------------------------------------------------ on the real runtime
def test_a_real_program_without_the_suite_kernels_is_refused_before_any_step(tmp_path, monkeypatch):
    """On this machine's OpenCL: a kernel file that builds but lacks the suite's kernels
    is refused when the backend starts (by the child), with the kernels it lacks; the
    command line says it in one line with exit 2."""
    try:
        device_text = ocl_module.OpenCLBackend.probe()
    except BackendUnavailable as exc:
        pytest.skip(f"OpenCL backend unavailable: {exc}")
    other = tmp_path / "other.cl"
    other.write_text("__kernel void other(__global int *a) { a[get_global_id(0)] = K; }\n")
    monkeypatch.setattr(ocl_module, "KERNEL_FILE", other)
    with pytest.raises(BackendUnavailable, match="without its kernels") as err:
        ocl_module.OpenCLBackend()
    assert device_text.split(",")[0] in str(err.value)
    from compact_distributions.bench.commands.cli import main

    code = main(["run", "--backend", "opencl", "--device", "0:0", "--elements", "20", "--size", "32",
                 "--out", str(tmp_path / "run"), "--quiet"])  # fmt: skip
    assert code == 2 and not (tmp_path / "run" / "result.json").exists()


def test_the_check_runs_in_a_real_child(tmp_path):
    """The child entry point itself, as the backend starts it: a bad payload is a
    verdict line, never a traceback or a hang."""
    import subprocess

    proc = subprocess.run(
        [sys.executable, "-m", ocl_module.CHECK_ENTRY, "--check"],
        input="not json",
        capture_output=True,
        text=True,
        timeout=120,
    )
    line = next(ln for ln in proc.stdout.splitlines() if ln.startswith(ocl_module.CHECK_MARK))
    verdict = json.loads(line[len(ocl_module.CHECK_MARK) :])
    assert not verdict["ok"] and verdict["reason"].startswith("the device check failed: JSONDecodeError")
    assert proc.returncode == 0 and "Traceback" not in proc.stderr


def test_suite_programs_cover_every_metric_the_backend_builds():
    """The check builds what the backend builds: a label program per ball kind and
    facet count of the suite's metrics, and with float64 a fit program for each."""
    from compact_distributions.cvt.metrics import METRIC_NAMES, make_metric

    shapes = {(m.curved, ocl_module._facet_count(m)) for m in map(make_metric, METRIC_NAMES)}
    with_fit = ocl_module.suite_programs(8, True, True)
    assert len(with_fit) == 2 * len(shapes)
    assert {p.options for p in with_fit} >= {
        ocl_module.label_program(e, k, 8, True, True).options for e, k in shapes
    }
    assert len(ocl_module.suite_programs(0, False, False)) == len(shapes)
    assert all(set(p.kernels) <= SUITE_KERNELS for p in with_fit)
    assert np.all([p.files[0].exists() for p in with_fit])


def test_the_first_default_that_runs_is_chosen_else_the_reference(capsys):
    status = {"fast": (False, "no runtime"), "faster": (True, "a device"), REFERENCE: (True, "CPU")}
    assert first_available(["faster", "fast"], status) == "faster"
    assert capsys.readouterr().err == ""
    assert first_available(["fast"], status) == REFERENCE
    assert capsys.readouterr().err.strip() == f"note: using {REFERENCE}, as fast cannot run here: no runtime"
