"""Property: whatever option values and small files a user hands `cvtbench run` and
`cvtbench mosaic`, the command either succeeds with its complete output, or exits 2 with
one line and leaves no output and no temporary behind (hypothesis, in-process)."""

from __future__ import annotations

import contextlib
import io
import json
import tempfile
from pathlib import Path

import numpy as np
from hypothesis import HealthCheck, event, given, settings
from hypothesis import strategies as st
from PIL import Image

from compact_distributions.bench.commands.cli import main
from compact_distributions.bench.outputs import TEMP_MARK

RUN_FILES = {"result.json", "sites.csv", "cells.png", "elements.svg", "elements.png"}
MOSAIC_FILES = {"result.json", "sites.csv", "mosaic.svg", "mosaic.png"}
# generous deadlines: a loaded 2-core machine must not turn a slow example into a failure
SETTINGS = settings(
    max_examples=40,
    deadline=None,
    derandomize=True,
    database=None,
    suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large],
)

weird_text = st.sampled_from(
    [
        "",
        "x",
        "nan",
        "inf",
        "-inf",
        "-1",
        "0",
        "1e308",
        "1e-300",
        "1e9",
        "0x10",
        "3.5",
        " 7 ",
        "१२",
        "--",
        "2,3",
    ]
)


hostile_number = st.one_of(
    weird_text,
    st.floats(allow_nan=True, allow_infinity=True).map(repr),
    st.integers(-(2**80), 2**80).map(str),
)
image_file = st.tuples(
    st.sampled_from(["L", "RGB", "RGBA", "P", "I;16", "1", "F"]),
    st.integers(1, 40),
    st.integers(1, 40),
    st.integers(0, 2**31 - 1),
)
bad_file = st.sampled_from(["garbage", "empty", "truncated", "folder", "missing"])


@st.composite
def options(draw, valid: dict, hostile: dict):
    """A value for every option of ``valid`` (a strategy each, None: left out), except at
    most one, drawn from ``hostile`` instead: so most examples run, and each hostile value
    meets otherwise sensible options."""
    bad = draw(st.sampled_from(list(hostile))) if draw(st.booleans()) else None
    chosen = {}
    for name, strategy in valid.items():
        chosen[name] = draw(hostile[name] if name == bad else strategy)
    return chosen


def make_picture(spec, folder: Path, name: str) -> Path:
    path = folder / name
    if spec == "folder":
        path.mkdir()
    elif spec == "empty":
        path.write_bytes(b"")
    elif spec == "garbage":
        path.write_bytes(b"not a picture at all\n" * 3)
    elif spec == "truncated":
        Image.fromarray(np.random.default_rng(1).integers(0, 255, (30, 30, 3), dtype=np.uint8)).save(
            path, "PNG"
        )
        path.write_bytes(path.read_bytes()[:200])
    elif spec != "missing":
        mode, w, h, seed = spec
        rng = np.random.default_rng(seed)
        if mode == "F":
            img = Image.fromarray(rng.random((h, w), dtype=np.float32), mode="F")
            path = path.with_suffix(".tif")
        elif mode == "I;16":
            img = Image.fromarray(rng.integers(0, 65535, (h, w), dtype=np.uint16))
        else:
            img = Image.fromarray(rng.integers(0, 255, (h, w, 3), dtype=np.uint8)).convert(mode)
        img.save(path, "TIFF" if mode == "F" else "PNG")
    return path


def check(argv, out: Path, folder: Path, files: set[str]) -> None:
    err = io.StringIO()
    with contextlib.redirect_stderr(err):
        code = main([str(a) for a in argv])
    text = err.getvalue()
    event(f"exit {code}")
    assert "Traceback" not in text
    if code == 0:
        assert {p.name for p in out.iterdir()} >= files, text
        result = json.loads((out / "result.json").read_text())
        assert len(result["sites"]) == result["n_elements"] == len(result["elements"])
    else:
        lines = text.strip().splitlines()
        assert code == 2 and len(lines) == 1 and "error" in lines[0], (code, text)
        assert not out.exists()
    assert not [p for p in folder.rglob("*") if TEMP_MARK in p.name or p.name == ".cvtbench.lock"]


RUN_VALID = {
    "size": st.one_of(
        st.integers(8, 40).map(str),
        st.tuples(st.integers(8, 40), st.integers(8, 40)).map(lambda t: f"{t[0]}x{t[1]}"),
    ),
    "sites": st.integers(1, 60).map(str),
    "iterations": st.integers(0, 3).map(str),
    "seed": st.integers(0, 10**6).map(str),
    "metric": st.sampled_from(["l2", "l1", "linf", "linf-axial", "l2-axial", "triangle"]),
    "aspect": st.one_of(st.none(), st.floats(0.05, 20).map(str)),
    "gap": st.one_of(st.none(), st.floats(0, 4).map(str)),
    "element": st.one_of(
        st.none(), st.sampled_from(["square", "circle", "rectangle", "ellipse", "triangle"])
    ),
    "field": st.one_of(
        st.none(), st.sampled_from(["radial", "circular", "constant:30", "wave:9"]), image_file
    ),
    "density": st.one_of(st.none(), image_file),
    "region": st.one_of(st.none(), image_file),
}
RUN_HOSTILE = {
    "size": st.one_of(weird_text, st.sampled_from(["40000", "0x5", "5x", "x5", "3x4x5"])),
    "sites": st.one_of(hostile_number, st.just("100000")),
    "iterations": hostile_number,
    "seed": hostile_number,
    "metric": st.sampled_from(["l3", "L2", ""]),
    "aspect": hostile_number,
    "gap": hostile_number,
    "element": st.sampled_from(["hexagon", "", "Square"]),
    "field": st.one_of(
        st.sampled_from(["radial:5", "constant:nan", "wave:0", "constant:", "spiral"]), bad_file
    ),
    "density": bad_file,
    "region": bad_file,
}


def as_path(value, folder: Path, name: str):
    """A file spec made into a file; any other value as it is."""
    if isinstance(value, tuple) or value in ("garbage", "empty", "truncated", "folder", "missing"):
        return make_picture(value, folder, name)
    return value


def run_command(command: str, opts: dict, files: set[str]) -> None:
    """``cvtbench COMMAND`` with ``opts`` (``image`` is the positional picture; True is a
    flag) in a fresh folder, checked by :func:`check`."""
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        out = folder / "out"
        argv = [command, "--quiet", "--out", out]
        if "image" in opts:
            argv.insert(1, as_path(opts.pop("image"), folder, "picture.png"))
        for name, value in opts.items():
            if value is True:
                argv.append(f"--{name}")
            elif value is not None and value is not False:
                argv.append(f"--{name}={as_path(value, folder, name + '.png')}")
        check(argv, out, folder, files)


@SETTINGS
@given(opts=options(RUN_VALID, RUN_HOSTILE))
def test_run_succeeds_completely_or_fails_in_one_line(opts):
    run_command("run", opts, RUN_FILES)


MOSAIC_VALID = {
    "image": image_file,
    "elements": st.integers(1, 300).map(str),
    "size": st.one_of(st.none(), st.integers(16, 48).map(str)),
    "element": st.one_of(
        st.none(), st.sampled_from(["square", "circle", "rectangle", "ellipse", "triangle"])
    ),
    "aspect": st.one_of(st.none(), st.floats(0.05, 20).map(str)),
    "contrast": st.one_of(st.none(), st.floats(1, 100).map(str)),
    "png-scale": st.one_of(st.none(), st.floats(0.05, 3).map(str)),
    "gap": st.one_of(st.none(), st.floats(0, 3).map(str)),
    "grout": st.sampled_from(["#383838", "white", "navy"]),
    "iterations": st.integers(0, 2).map(str),
    "compare": st.sampled_from([None, "field", "density"]),
    "no-field": st.booleans(),
    "no-density": st.booleans(),
}
MOSAIC_HOSTILE = {
    "image": bad_file,
    "elements": st.one_of(hostile_number, st.just("5000")),
    "size": st.one_of(weird_text, st.just("40000")),
    "element": st.sampled_from(["hexagon", ""]),
    "aspect": hostile_number,
    "contrast": hostile_number,
    "png-scale": st.one_of(hostile_number, st.just("100")),
    "gap": hostile_number,
    "grout": st.sampled_from(["nope", "#12345", ""]),
    "iterations": hostile_number,
    "compare": st.sampled_from(["both", ""]),
    "no-field": st.booleans(),
    "no-density": st.booleans(),
}


@SETTINGS
@given(opts=options(MOSAIC_VALID, MOSAIC_HOSTILE))
def test_mosaic_succeeds_completely_or_fails_in_one_line(opts):
    compare = opts["compare"] if opts["compare"] in ("field", "density") else None
    run_command("mosaic", opts, MOSAIC_FILES | ({f"compare_{compare}.png"} if compare else set()))
