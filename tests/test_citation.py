"""CITATION.cff is valid CFF 1.2.0 and cites the paper."""

import json
from pathlib import Path

import jsonschema
import yaml

ROOT = Path(__file__).resolve().parents[1]
# The official CFF 1.2.0 JSON schema (citation-file-format.github.io/1.2.0/schema.json).
SCHEMA = Path(__file__).parent / "data" / "citation-cff-1.2.0.schema.json"


def _load():
    return yaml.safe_load((ROOT / "CITATION.cff").read_text())


def test_citation_validates_against_cff_schema():
    schema = json.loads(SCHEMA.read_text())
    # YAML parses the date into datetime.date; the schema expects the string form.
    cff = json.loads(json.dumps(_load(), default=str))
    jsonschema.validate(cff, schema)


def test_citation_prefers_the_paper():
    cff = _load()
    assert cff["cff-version"] == "1.2.0"
    paper = cff["preferred-citation"]
    assert paper["title"] == "High Resolution Radar Dataset for Semi-Supervised Learning of Dynamic Objects"
    assert [a["family-names"] for a in paper["authors"]] == ["Mostajabi", "Wang", "Ranjan", "Hsyu"]
    assert paper["year"] == 2020


def test_schema_rejects_a_broken_citation():
    schema = json.loads(SCHEMA.read_text())
    broken = json.loads(json.dumps(_load(), default=str))
    del broken["authors"]
    try:
        jsonschema.validate(broken, schema)
    except jsonschema.ValidationError:
        return
    raise AssertionError("a citation without authors must not validate")
