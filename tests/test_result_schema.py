"""One result.json schema for `cvtbench run` and `cvtbench mosaic`: both outputs validate
against the JSON Schema shipped in the package, a record that breaks it is refused, and
the site's result.json page documents every field."""

from __future__ import annotations

import json
from pathlib import Path

import jsonschema
import numpy as np
import pytest
from PIL import Image

from compact_distributions.bench.commands.cli import main
from compact_distributions.bench.results import SCHEMA_FILE, schema

ROOT = Path(__file__).resolve().parent.parent


@pytest.fixture(scope="module")
def outputs(tmp_path_factory):
    d = tmp_path_factory.mktemp("outs")
    rgb = np.zeros((60, 80, 3), np.uint8)
    rgb[:, 40:] = (200, 30, 30)
    Image.fromarray(rgb).save(d / "pic.png")
    assert (
        main(
            [
                "run",
                "--elements",
                "30",
                "--size",
                "64",
                "--iterations",
                "2",
                "--metric",
                "linf",
                "--out",
                str(d / "run"),
                "--quiet",
            ]
        )
        == 0
    )
    assert (
        main(
            [
                "mosaic",
                str(d / "pic.png"),
                "--elements",
                "40",
                "--iterations",
                "2",
                "--out",
                str(d / "mosaic"),
                "--quiet",
            ]
        )
        == 0
    )
    return {k: json.loads((d / k / "result.json").read_text()) for k in ("run", "mosaic")}


def test_the_schema_is_a_valid_json_schema():
    jsonschema.Draft202012Validator.check_schema(schema())
    assert SCHEMA_FILE.name == "result.schema.json"


@pytest.mark.parametrize("kind", ["run", "mosaic"])
def test_both_commands_write_the_one_schema(outputs, kind):
    record = outputs[kind]
    jsonschema.validate(record, schema())
    assert record["kind"] == kind
    # one word, one meaning: elements are the outlines, placed is their count
    assert isinstance(record["elements"], list) and len(record["elements"]) == record["n_elements"]
    assert record["placed"] == sum(e is not None for e in record["elements"])


@pytest.mark.parametrize(
    "change",
    [
        {"elements": 40},  # a count where outlines belong
        {"kind": "table"},
        {"coverage": 1.5},
        {"size": [64]},
        {"element": "blob"},
        {"metric": "l3"},
        {"element": "polygon:"},
    ],
)
def test_a_record_that_breaks_the_schema_is_refused(outputs, change):
    with pytest.raises(jsonschema.ValidationError):
        jsonschema.validate({**outputs["run"], **change}, schema())


@pytest.mark.parametrize(
    "change",
    [
        {"element": "hexagon", "metric": "hexagon"},
        {"element": "octagon", "metric": "octagon"},
        {"element": "polygon:pentagon.json", "metric": "polygon:pentagon.json"},
    ],
)
def test_every_shape_of_the_table_and_a_users_polygon_fit_the_schema(outputs, change):
    jsonschema.validate({**outputs["run"], **change}, schema())


def test_mosaic_fields_are_required_for_a_mosaic(outputs):
    record = dict(outputs["mosaic"])
    del record["colours"]
    with pytest.raises(jsonschema.ValidationError):
        jsonschema.validate(record, schema())


def test_the_site_documents_every_field():
    """The site's result.json page explains every field in words (its table of the schema
    itself is generated, so it could not miss one)."""
    page = (ROOT / "docs" / "guide" / "result_json.md").read_text()
    section = page[page.index("## What the fields mean") :]
    missing = [name for name in schema()["properties"] if f"`{name}`" not in section]
    assert missing == []
