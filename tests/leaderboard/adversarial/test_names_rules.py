"""Names that would be drawn as something else are refused; look-alike team names collide; pages
show the registered team, never what a submission claims."""

from __future__ import annotations

import json

import pytest

from tests.leaderboard.adversarial.scored_store import add_scored
from tests.leaderboard.conftest import ground_truth, submission
from zendar_leaderboard.cli import main
from zendar_leaderboard.export import render_site
from zendar_leaderboard.meta import MAX_METHOD_CHARS, clean_meta, meta_problems
from zendar_leaderboard.store import Store
from zendar_leaderboard.submission import check_submission

ZALGO = "a" + "\u0301" * 38 + "b"


def add_team(capsys, db, name) -> tuple[int, str]:
    capsys.readouterr()
    code = main(["add-team", name, "--db", str(db)])
    return code, capsys.readouterr().err


def team_names(db) -> list[str]:
    return sorted({row[0] for row in Store(db)._connection().execute("SELECT name FROM teams")})


@pytest.mark.parametrize("name", [
    "Radar Lab ", " Radar Lab", "Radar\u00a0Lab", "Radar  Lab", "R\u0430dar Lab", "R\u0410DAR LAB", "radar lab",
    "Rad\u00e1r Lab", "\uff32adar Lab", "Radar L\u0430b",
])
def test_add_team_refuses_a_name_that_looks_like_an_existing_team(tmp_path, capsys, name):
    db = tmp_path / "board.db"
    assert add_team(capsys, db, "Radar Lab")[0] == 0
    code, err = add_team(capsys, db, name)
    assert code == 2, err
    assert "'Radar Lab'" in err and "Traceback" not in err
    assert team_names(db) == ["Radar Lab"]


@pytest.mark.parametrize("name, refused", [
    ("Radar\u200bLab", "U+200B"), ("\u202eRadar Lab", "U+202E"), ("Radar \u2066Lab\u2069", "U+2066"),
    ("Radar Lab\x1b[2J", "U+001B"), ("Radar\nLab", "U+000A"), ("Radar\tLab", "U+0009"),
    ("Radar \ue000Lab", "U+E000"), ("Radar\u2028Lab", "U+2028"), (ZALGO, "38 combining marks"),
    ("\u0301Radar", "starts with a combining mark"),
])
def test_add_team_refuses_invisible_control_and_stacked_characters(tmp_path, capsys, name, refused):
    db = tmp_path / "board.db"
    code, err = add_team(capsys, db, name)
    assert code == 2 and refused in err and "Traceback" not in err, err
    assert team_names(db) == []


def test_add_team_stores_the_normalised_name(tmp_path, capsys):
    db = tmp_path / "board.db"
    code, err = add_team(capsys, db, "  Radar\u00a0\u00a0Lab\u3000")
    assert code == 0 and "'Radar Lab' registered" in err
    assert team_names(db) == ["Radar Lab"]
    # Names that only look alike to a careless reader are still distinct teams.
    assert add_team(capsys, db, "Radar Lab 2")[0] == 0
    assert add_team(capsys, db, "Sonar Lab")[0] == 0


@pytest.mark.parametrize("field, value, refused", [
    ("method", ZALGO, "38 combining marks"),
    ("method", "\u202eten teN", "U+202E"),
    ("method", "net\u200b", "U+200B"),
    ("team", "Radar Lab\u2067", "U+2067"),
    ("hardware", "GPU \ue123", "U+E123"),
    ("description", "fine\n" + ZALGO, "38 combining marks"),
    ("description", "text \u202a embedded", "U+202A"),
    ("url", "https://example.org/\u202e", "U+202E"),
    ("method", "\ufdfa" * 3, f"more than the limit of {MAX_METHOD_CHARS}"),  # NFKC: 18 characters each
])
def test_a_submission_with_a_spoofing_text_is_refused_naming_the_field(field, value, refused):
    gt = ground_truth(n_scenes=2, frames_per_scene=2)
    document = submission(gt, **{field: value})
    checked = check_submission(json.dumps(document).encode(), list(gt["frames"]))
    assert not checked.ok
    assert [p for p in checked.problems if f"'{field}'" in p and refused in p], checked.problems
    assert len(checked.problems) == 1, checked.problems


def test_a_description_keeps_its_lines_and_names_are_normalised():
    gt = ground_truth(n_scenes=2, frames_per_scene=2)
    document = submission(gt, method="\uff23FAR  net ", description="line one\n\tline two", hardware="1\u00a0GPU")
    checked = check_submission(json.dumps(document).encode(), list(gt["frames"]))
    assert checked.ok, checked.problems
    assert checked.meta["method"] == "CFAR net" and checked.meta["hardware"] == "1 GPU"
    assert checked.meta["description"] == "line one\n\tline two"
    assert meta_problems(clean_meta(document["meta"])) == []


def test_pages_and_exports_show_the_registered_team_never_meta_team(tmp_path):
    store = Store(tmp_path / "board.db")
    store.add_team("Radar Lab")
    rival = store.add_team("Rivals")
    add_scored(store, rival, {"near": 0.9, "mid": 0.9, "far": 0.9, "all": 0.9}, method="borrowed glory",
               team="Radar Lab")
    out = tmp_path / "site"
    written = render_site(store, out)
    for path in written:
        text = path.read_text()
        assert "Radar Lab" not in text, path.name
    entry_page = next(p for p in written if p.parent.name == "entry").read_text()
    assert "Rivals" in entry_page and "Rivals" in (out / "index.html").read_text()
    board = json.loads((out / "leaderboard.json").read_text())
    assert board["entries"][0]["team"] == "Rivals" and "team" not in board["entries"][0]["meta"]
