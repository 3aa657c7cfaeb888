"""`cvtbench run` end to end, and every bad input: one line, exit 2, no output."""

import json
import subprocess
import sys

import numpy as np
import pytest
from PIL import Image

from compact_distributions.bench.commands.cli import main


def run_cli(argv, capsys):
    code = main(argv)
    out, err = capsys.readouterr()
    return code, out, err


@pytest.fixture
def images(tmp_path):
    d = {}
    grad = np.tile(np.linspace(10, 250, 64, dtype=np.uint8), (48, 1))
    Image.fromarray(grad).save(tmp_path / "density.png")
    d["density"] = tmp_path / "density.png"
    Image.fromarray(np.zeros((48, 64), np.uint8)).save(tmp_path / "zero.png")
    d["zero"] = tmp_path / "zero.png"
    disc = np.zeros((80, 80), np.uint8)
    yy, xx = np.mgrid[0:80, 0:80]
    disc[(xx - 40) ** 2 + (yy - 40) ** 2 < 30**2] = 255
    Image.fromarray(disc).save(tmp_path / "disc.png")
    d["disc"] = tmp_path / "disc.png"
    d["text"] = tmp_path / "notes.png"
    d["text"].write_text("this is not an image\n")
    full = tmp_path / "full.png"
    noise = np.random.default_rng(0).integers(0, 255, (64, 64), dtype=np.uint8)
    Image.fromarray(noise).save(full)
    d["trunc"] = tmp_path / "trunc.png"
    d["trunc"].write_bytes(full.read_bytes()[: len(full.read_bytes()) // 2])
    return d


def test_run_writes_result_sites_and_cells(tmp_path, capsys):
    out = tmp_path / "run"
    code, _, err = run_cli(
        [
            "run",
            "--elements",
            "60",
            "--size",
            "96x64",
            "--iterations",
            "3",
            "--metric",
            "linf-axial",
            "--aspect",
            "0.7",
            "--seed",
            "4",
            "--field",
            "constant:30",
            "--out",
            str(out),
        ],
        capsys,
    )
    assert code == 0, err
    r = json.loads((out / "result.json").read_text())
    for key in (
        "backend",
        "device",
        "metric",
        "aspect",
        "size",
        "sites",
        "angles",
        "scales",
        "iterations",
        "energy",
        "seconds",
        "versions",
        "command",
    ):
        assert key in r, key
    assert r["backend"] == "numpy" and r["metric"] == "linf-axial" and r["aspect"] == 0.7
    assert r["size"] == [96, 64] and r["iterations"] == 3
    assert len(r["sites"]) == 60 and len(r["energy"]) == 3 and len(r["seconds"]) == 3
    np.testing.assert_allclose(r["angles"], np.radians(30))
    assert r["command"].startswith("cvtbench run --elements 60")
    csv = (out / "sites.csv").read_text().splitlines()
    assert csv[0].startswith("x,y") and len(csv) == 61
    with Image.open(out / "cells.png") as im:
        assert im.size == (96, 64)
        assert len(np.unique(np.asarray(im).reshape(-1, 3), axis=0)) > 30


def test_init_csv_round_trip_and_zero_iterations(tmp_path, capsys):
    init = tmp_path / "init.csv"
    init.write_text("x,y\n10.5,20.25\n40,30\n70.125,5\n")
    code, _, err = run_cli(
        ["run", "--init", str(init), "--size", "80x40", "--iterations", "0", "--out", str(tmp_path / "o")],
        capsys,
    )
    assert code == 0, err
    r = json.loads((tmp_path / "o" / "result.json").read_text())
    assert r["sites"] == [[10.5, 20.25], [40.0, 30.0], [70.125, 5.0]]
    assert r["iterations"] == 0 and r["energy"] == []


def test_density_region_and_image_field(tmp_path, images, capsys):
    code, _, err = run_cli(
        [
            "run",
            "--elements",
            "40",
            "--size",
            "80x80",
            "--iterations",
            "2",
            "--density",
            str(images["density"]),
            "--region",
            str(images["disc"]),
            "--field",
            str(images["density"]),
            "--out",
            str(tmp_path / "o"),
        ],
        capsys,
    )
    assert code == 0, err  # density of another size is resampled, as documented
    r = json.loads((tmp_path / "o" / "result.json").read_text())
    sites = np.array(r["sites"])
    assert (np.hypot(sites[:, 0] - 40, sites[:, 1] - 40) < 31).all()
    assert r["region_pixels"] < 80 * 80 and len(set(np.round(r["scales"], 6))) > 5


@pytest.mark.parametrize(
    "pictures,size,raster",
    [
        (("density",), "96", [96, 72]),  # the density's 64x48: 4:3
        (("disc",), "64", [64, 64]),  # the region's 80x80
        (("disc", "density"), "96", [96, 72]),  # --density before --region, however given
        (("density",), "30x50", [30, 50]),  # WxH is what it says
        ((), "96", [96, 96]),  # no picture: a square
    ],
)
def test_a_single_size_follows_the_first_pictures_aspect(pictures, size, raster, tmp_path, images, capsys):
    options = {"density": "--density", "disc": "--region"}
    given = [a for name in pictures for a in (options[name], str(images[name]))]
    code, _, err = run_cli(
        ["run", "--elements", "20", "--size", size, "--iterations", "1", "--quiet", *given]
        + ["--out", str(tmp_path / "o")],
        capsys,
    )
    assert code == 0, err
    r = json.loads((tmp_path / "o" / "result.json").read_text())
    assert r["size"] == raster
    with Image.open(tmp_path / "o" / "elements.png") as png:
        assert list(png.size) == raster


BAD = [
    (["--metric", "l3"], "unknown --metric 'l3'"),
    (["--backend", "vulkan"], "unknown backend 'vulkan'"),
    (["--elements", "0"], "--elements must be a whole number between 1 and 4096"),
    (["--elements", "many"], "--elements must be a whole number"),
    (["--elements", "5000", "--size", "64"], "between 1 and 4096, got '5000'"),
    (["--size", "0"], "size '0'"),
    (["--size", "40000"], "size '40000'"),
    (["--size", "10x"], "size must be W or WxH"),
    (["--iterations", "-1"], "--iterations must be a whole number between 0 and 100000"),
    (["--aspect", "0", "--metric", "l2-axial"], "--aspect must be a finite number between 0.01 and 100"),
    (["--aspect", "-2", "--metric", "linf-axial"], "--aspect must be a finite number between 0.01 and 100"),
    (["--field", "spiral"], "--field 'spiral' is neither a field nor an image file"),
    (["--field", "constant:abc"], "constant needs an angle"),
    (["--method", "magic"], "unknown method 'magic'"),
]


@pytest.mark.parametrize("extra,message", BAD)
def test_bad_arguments(extra, message, tmp_path, capsys):
    out = tmp_path / "out"
    argv = ["run", "--elements", "20", "--size", "64", "--iterations", "1", "--out", str(out)]
    code, _, err = run_cli(argv + extra, capsys)
    assert code == 2
    lines = err.strip().splitlines()
    assert len(lines) == 1 and message in lines[0] and "Traceback" not in err
    assert not out.exists()


@pytest.mark.parametrize(
    "option,which,message",
    [
        ("--density", "zero", "all zero"),
        ("--density", "text", "not an image file"),
        ("--density", "trunc", "cannot read image"),
        ("--density", "missing", "image file not found"),
        ("--region", "zero", "is empty"),
        ("--region", "text", "not an image file"),
    ],
)
def test_bad_images(option, which, message, images, tmp_path, capsys):
    path = images.get(which, tmp_path / "nope.png")
    out = tmp_path / "out"
    code, _, err = run_cli(
        ["run", "--elements", "10", "--size", "48", option, str(path), "--out", str(out)], capsys
    )
    assert code == 2 and message in err and len(err.strip().splitlines()) == 1
    assert not out.exists()


@pytest.mark.parametrize(
    "content,message",
    [
        ("a,b\n1,2\n", "needs columns x and y"),
        ("x,y\n1,nan\n", "NaN or infinite"),
        ("x,y\n1,oops\n", "must be numbers"),
        ("x,y\n10,10\n100,5\n", "outside the 64x64 raster"),
        ("x,y\n", "has no sites"),
    ],
)
def test_bad_init_csv(content, message, tmp_path, capsys):
    init = tmp_path / "init.csv"
    init.write_text(content)
    out = tmp_path / "out"
    code, _, err = run_cli(["run", "--init", str(init), "--size", "64", "--out", str(out)], capsys)
    assert code == 2 and message in err, err
    assert not out.exists()


def test_info_lists_every_backend(capsys):
    code, out, _ = run_cli(["info"], capsys)
    assert code == 0
    for name in ("numpy", "opencl", "gl"):
        assert f"  {name} " in out
    assert "numpy   available" in out


def test_console_script_end_to_end(tmp_path):
    """The installed entry point, as a user runs it (subprocess, real exit status)."""
    exe = [sys.executable, "-m", "compact_distributions.bench.commands.cli"]
    ok = subprocess.run(
        exe + ["run", "--elements", "30", "--size", "64", "--iterations", "2", "--out", str(tmp_path / "o")],
        capture_output=True,
        text=True,
    )
    assert ok.returncode == 0, ok.stderr
    assert (tmp_path / "o" / "result.json").exists()
    bad = subprocess.run(exe + ["run", "--metric", "nope"], capture_output=True, text=True)
    assert bad.returncode == 2 and "Traceback" not in bad.stderr and "unknown --metric" in bad.stderr


def test_one_commands_parser_says_what_every_parser_says():
    """The parser built for ``argv`` alone (only the named command's options; the others
    by their help) prints what the parser of every command prints: the list of commands,
    each command's help, and the error of an unknown command or option."""
    import contextlib
    import io

    from compact_distributions.bench.commands.cli import SUBCOMMANDS, build_parser

    def said(parser, argv):
        out, err = io.StringIO(), io.StringIO()
        with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err), pytest.raises(SystemExit):
            parser.parse_args(argv)
        return out.getvalue(), err.getvalue()

    every = build_parser()
    names = [m.rsplit(".", 1)[1] for m in SUBCOMMANDS]
    cases = [["--help"], [], ["bogus"], ["--version"]]
    cases += [[name, extra] for name in names for extra in ("--help", "--no-such-option")]
    for argv in cases:
        assert said(build_parser(argv), argv) == said(every, argv), argv


def test_help_lists_every_command_without_loading_the_methods():
    """``cvtbench --help`` names every command with its help, and builds no command's
    options: neither the method registry nor scipy is loaded."""
    from compact_distributions.bench.commands.cli import SUBCOMMANDS, command_help

    probe = (
        "import sys\n"
        "from compact_distributions.bench.commands.cli import main\n"
        "code = main(['--help'])\n"
        "registry = sys.modules.get('compact_distributions.cvt.registry')\n"
        "print(['scipy'] * ('scipy' in sys.modules) + ['methods'] * bool(registry and registry._load.cache_info().currsize))\n"
        "sys.exit(code)\n"
    )
    done = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True)
    assert done.returncode == 0, done.stderr
    assert done.stdout.strip().splitlines()[-1] == "[]"
    for module in SUBCOMMANDS:
        name, text = command_help(module)
        assert name == module.rsplit(".", 1)[1]
        assert " ".join(f"{name} {text}".split()) in " ".join(done.stdout.split())


def test_a_command_runs_with_a_larger_first_generation_and_leaves_it_as_it_was(monkeypatch, capsys):
    """While a command runs the collector's first generation is at least
    GC_FIRST_GENERATION objects (the full collections it spares walk every object the
    imports left); after it, and after a command that fails, it is what it was."""
    import gc

    from compact_distributions.bench.commands import cli, info

    seen = []

    def recorded(args):
        seen.append(gc.get_threshold())
        if len(seen) == 2:
            raise cli.InputError("a bad argument")
        return 0

    monkeypatch.setattr(info, "run", recorded)
    before = gc.get_threshold()
    assert before[0] < cli.GC_FIRST_GENERATION  # the interpreter's own (700)
    assert main(["info"]) == 0
    assert gc.get_threshold() == before
    assert main(["info"]) == 2
    assert gc.get_threshold() == before
    assert [t[0] for t in seen] == [cli.GC_FIRST_GENERATION] * 2
    assert all(t[1:] == before[1:] for t in seen)


@pytest.mark.parametrize("region", [False, True])
def test_run_streams_elements_png_with_the_pixels_of_the_picture_drawn_whole(
    region, tmp_path, images, capsys, monkeypatch
):
    """`cvtbench run` draws elements.png as its rows are read (beside the measures):
    the file holds, pixel for pixel, the picture drawn whole from the same elements."""
    from compact_distributions.cvt.mosaic import render

    calls = []
    drawn = render.draw_elements

    def spy(*args, **kwargs):
        calls.append((args, dict(kwargs)))
        return drawn(*args, **kwargs)

    monkeypatch.setattr(render, "draw_elements", spy)
    out = tmp_path / "out"
    argv = ["run", "--elements", "150", "--size", "80", "--method", "ours-compact", "--out", str(out)]
    code, _, err = run_cli(argv + (["--region", str(images["disc"])] if region else []), capsys)
    assert code == 0, err
    ((args, kwargs),) = calls
    assert kwargs.get("as_rows") is True
    whole = np.asarray(drawn(*args, **{**kwargs, "as_rows": False}))
    written = np.asarray(Image.open(out / "elements.png").convert("RGB"))
    assert whole.shape == (80, 80, 3) and len(np.unique(whole.reshape(-1, 3), axis=0)) > 20  # elements drawn
    np.testing.assert_array_equal(written, whole)
