"""The one picture reader (cvt/images.py) behind density, region, field and mosaic
pictures, and the other files users hand over (site CSVs, named fields)."""

from __future__ import annotations

import json

import numpy as np
import pytest
from PIL import Image

from compact_distributions.bench.commands.cli import main
from compact_distributions.cvt.errors import InputError
from compact_distributions.cvt.fields import DirectionField, parse_field_spec
from compact_distributions.cvt.mosaic.images import load_grey, load_rgb, read_picture, upright_size

from .cli_errors import one_error
from .hostile import blank_png, run_measured


def run_cli(argv, capsys):
    code = main([str(a) for a in argv])
    return code, capsys.readouterr().err


@pytest.fixture
def sideways(tmp_path):
    """A phone photo: stored 64 wide x 32 high with the left quarter blue, EXIF
    orientation 6 (turn 90° clockwise to show): shown 32 wide x 64 high, blue on top."""
    img = Image.new("RGB", (64, 32), (255, 0, 0))
    img.paste((0, 0, 255), (0, 0, 16, 32))
    exif = Image.Exif()
    exif[0x0112] = 6
    path = tmp_path / "phone.jpg"
    img.save(path, exif=exif.tobytes(), quality=95)
    return path


def test_exif_orientation_is_applied(sideways):
    with Image.open(sideways) as header:
        assert upright_size(header) == (32, 64)
    rgb = load_rgb(sideways)
    assert rgb.shape == (64, 32, 3)
    assert rgb[4, 16, 2] > 0.8 and rgb[60, 16, 0] > 0.8  # blue on top, red below


def test_a_mosaic_of_a_phone_photo_is_upright(sideways, tmp_path, capsys):
    code, err = run_cli(
        ["mosaic", sideways, "--elements", "30", "--iterations", "1", "--quiet", "--out", tmp_path / "o"],
        capsys,
    )
    assert code == 0, err
    result = json.loads((tmp_path / "o" / "result.json").read_text())
    assert result["size"] == [32, 64]
    sites, colours = np.array(result["sites"]), result["colours"]
    top = [c for (x, y), c in zip(sites, colours, strict=True) if y < 12]
    assert top and all(c[5:7] > "c0" and c[1:3] < "40" for c in top)  # #rrggbb: blue, little red


def test_large_pictures_are_decoded_at_a_reduced_size(tmp_path):
    big = tmp_path / "big.jpg"
    Image.new("RGB", (2400, 1600), (10, 200, 30)).save(big, quality=90)
    img = read_picture(big, at_least=(300, 200))
    assert 300 <= img.width < 600 and 200 <= img.height < 400  # JPEG scaled by its DCT, then reduced
    png = blank_png(tmp_path / "big.png", 3000, 2000)
    img = read_picture(png, at_least=(300, 200))
    assert 300 <= img.width < 600 and 200 <= img.height < 400
    assert read_picture(png).size == (3000, 2000)


def test_sixteen_bit_pictures_keep_their_full_scale_when_reduced(tmp_path):
    arr = np.full((400, 600), 200, dtype=np.uint16)  # dark in 16 bits (200/65535)
    path = tmp_path / "deep.png"
    Image.fromarray(arr).save(path)
    grey, full = load_grey(path, 60, 40)
    assert full == 65535 and np.allclose(grey, 200)


@pytest.mark.parametrize("option", ["--density", "--region", "--field", "mosaic"])
def test_decompression_bombs_are_refused_with_one_line(option, tmp_path, capsys):
    bomb = blank_png(tmp_path / "bomb.png", 20000, 20000)  # 400 Mpx in a few hundred kB
    argv = (
        ["mosaic", bomb] if option == "mosaic" else ["run", "--size", "64", "--elements", "10", option, bomb]
    )
    line = one_error(argv + ["--out", tmp_path / "o"], capsys)
    assert "declares 400 Mpx, more than the 179 Mpx Pillow decodes" in line
    assert not (tmp_path / "o").exists()


@pytest.mark.slow
def test_a_picture_declaring_144_mpx_makes_a_mosaic_in_bounded_memory(tmp_path):
    big = blank_png(tmp_path / "big.png", 12000, 12000, rgb=True)  # 170 kB on disk
    code, err, peak, _ = run_measured(
        ["mosaic", big, "--elements", "100", "--iterations", "1", "--quiet", "--out", tmp_path / "o"]
    )
    assert code == 0, err
    assert peak < 1000, peak  # the pixels once at 4 bytes, never as float64 at full size
    assert json.loads((tmp_path / "o" / "result.json").read_text())["size"] == [1024, 1024]


def test_a_picture_larger_than_the_memory_limit_is_refused(tmp_path, capsys):
    big = blank_png(tmp_path / "big.png", 6000, 6000, rgb=True)
    assert "--memory-limit" in one_error(
        ["mosaic", big, "--memory-limit", "150M", "--out", tmp_path / "o"], capsys
    )
    with pytest.raises(InputError, match="reading image .* needs about"):
        read_picture(big, memory_limit="150M")


@pytest.mark.parametrize(
    "content,name",
    [
        (b"GIF89a", "truncated.gif"),
        (b"\x89PNG\r\n\x1a\n" + b"\0" * 40, "broken.png"),
        (b"hello\n", "text.png"),
    ],
)
def test_unreadable_pictures_are_one_line(content, name, tmp_path, capsys):
    path = tmp_path / name
    path.write_bytes(content)
    for argv in (["mosaic", path], ["run", "--size", "32", "--elements", "4", "--density", path]):
        assert str(path) in one_error(argv + ["--out", tmp_path / "o"], capsys)
        assert not (tmp_path / "o").exists()


def test_site_csvs_with_a_byte_order_mark_are_read(tmp_path, capsys):
    init = tmp_path / "sites.csv"
    init.write_bytes("\ufeffx,y\r\n10,10\r\n20,30\r\n40,5\r\n".encode())  # as a spreadsheet saves it
    code, err = run_cli(
        ["run", "--init", init, "--size", "64", "--iterations", "0", "--quiet", "--out", tmp_path / "o"],
        capsys,
    )
    assert code == 0, err
    assert json.loads((tmp_path / "o" / "result.json").read_text())["sites"] == [[10, 10], [20, 30], [40, 5]]


def test_a_site_just_outside_is_reported_as_it_is(tmp_path, capsys):
    init = tmp_path / "sites.csv"
    init.write_text("x,y\n10,10\n64.0000000001,5\n")
    line = one_error(["run", "--init", init, "--size", "64", "--out", tmp_path / "o"], capsys)
    assert "(64.0000000001, 5.0) is outside the 64x64 raster" in line


def test_named_fields_win_over_files_and_a_path_reads_the_file(tmp_path, capsys, monkeypatch):
    monkeypatch.chdir(tmp_path)
    Image.fromarray(np.full((32, 32), 64, np.uint8)).save(tmp_path / "radial", format="PNG")
    base = ["run", "--size", "32", "--elements", "8", "--iterations", "0", "--quiet"]
    assert run_cli(base + ["--field", "radial", "--out", "a"], capsys)[0] == 0
    named = json.loads((tmp_path / "a" / "result.json").read_text())
    assert len(set(np.round(named["angles"], 6))) > 4  # radial: every site its own angle
    assert run_cli(base + ["--field", "./radial", "--out", "b"], capsys)[0] == 0
    image = json.loads((tmp_path / "b" / "result.json").read_text())
    assert np.allclose(image["angles"], 64 / 255 * np.pi)  # the grey image: 64 -> 45.2°


@pytest.mark.parametrize(
    "spec,message",
    [
        ("radial:5", "radial takes no argument"),
        ("circular:", "circular takes no argument"),
        ("constant:nan", "constant needs an angle in degrees between -360 and 360"),
        ("constant:inf", "constant needs an angle"),
        ("constant:1e308", "constant needs an angle"),
        ("constant:", "constant needs an angle"),
        ("wave:0", "wave needs a period in pixels between 1 and 1e+06"),
        ("wave:inf", "wave needs a period"),
        ("spiral", "neither a field nor an image file"),
    ],
)
def test_bad_field_specs(spec, message, tmp_path, capsys):
    line = one_error(
        ["run", "--size", "32", "--elements", "4", "--field", spec, "--out", tmp_path / "o"], capsys
    )
    assert message in line and "--field" in line


def test_field_specs_in_python():
    assert parse_field_spec("wave") == ("wave", 200.0)
    assert parse_field_spec("constant:-30") == ("constant", -30.0)
    assert parse_field_spec("photo.png") == (None, None)
    with pytest.raises(InputError, match="field 'radial:1'"):
        DirectionField.named("radial:1", 10, 10)


@pytest.mark.parametrize(
    "values,message",
    [
        (np.full((16, 16), 1e38, np.float32), "values must lie in 0..1"),
        (np.where(np.eye(16) > 0, np.inf, 0.5).astype(np.float32), "NaN or infinite"),
    ],
)
def test_float_field_images_out_of_range(values, message, tmp_path, capsys):
    Image.fromarray(values, mode="F").save(tmp_path / "f.tif")
    assert message in one_error(
        ["run", "--size", "32", "--elements", "4", "--field", tmp_path / "f.tif", "--out", tmp_path / "o"],
        capsys,
    )


def test_a_density_of_huge_values_is_used_by_its_ratios(tmp_path, capsys):
    values = np.full((32, 32), 1e38, np.float32)
    values[:, 16:] = 3e38
    Image.fromarray(values, mode="F").save(tmp_path / "d.tif")
    code, err = run_cli(
        [
            "run",
            "--size",
            "32",
            "--elements",
            "40",
            "--iterations",
            "2",
            "--quiet",
            "--density",
            tmp_path / "d.tif",
            "--out",
            tmp_path / "o",
        ],
        capsys,
    )
    assert code == 0, err
    scales = np.array(json.loads((tmp_path / "o" / "result.json").read_text())["scales"])
    assert np.isfinite(scales).all() and scales.max() / scales.min() == pytest.approx(np.sqrt(3), rel=1e-6)
