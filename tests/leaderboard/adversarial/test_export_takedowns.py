"""``render`` rebuilds the static export from scratch: takedowns leave the published folder, and a
folder the export did not write is never emptied."""

from __future__ import annotations

import json

import pytest

from tests.leaderboard.adversarial.scored_store import board_with
from zendar_leaderboard.cli import main
from zendar_leaderboard.export import MANIFEST_NAME, render_site

AP = {"near": 0.5, "mid": 0.4, "far": 0.3, "all": 0.4}


def site_text(out) -> str:
    return "\n".join(path.read_text() for path in sorted(out.rglob("*")) if path.is_file())


def test_hidden_and_deleted_entries_leave_the_export_on_the_next_render(tmp_path, capsys):
    store = board_with(tmp_path, [("Radar Lab", "kept method", AP), ("Rivals", "leaked method", AP),
                                  ("Third", "withdrawn method", AP)])
    kept, hidden, deleted = (entry.id for entry in store.submissions())
    out = tmp_path / "site"
    db = str(store.path)
    assert main(["render", "--db", db, str(out)]) == 0
    assert {p.name for p in (out / "entry").iterdir()} == {f"{kept}.html", f"{hidden}.html", f"{deleted}.html"}

    assert main(["hide", str(hidden), "--db", db]) == 0
    assert main(["delete", str(deleted), "--db", db]) == 0
    assert main(["render", "--db", db, str(out)]) == 0
    assert {p.name for p in (out / "entry").iterdir()} == {f"{kept}.html"}
    text = site_text(out)
    assert "kept method" in text
    assert "leaked method" not in text and "withdrawn method" not in text and "Rivals" not in text
    board = json.loads((out / "leaderboard.json").read_text())
    assert [entry["id"] for entry in board["entries"]] == [kept]
    # Nothing of the build is left beside the export.
    assert sorted(p.name for p in tmp_path.iterdir() if p.name.startswith(".")) == []


def test_a_folder_that_is_not_an_export_is_refused_untouched(tmp_path, capsys):
    store = board_with(tmp_path, [("Radar Lab", "m", AP)])
    out = tmp_path / "home"
    out.mkdir()
    (out / "notes.txt").write_text("mine")
    (out / "index.html").write_text("my own page")
    assert main(["render", "--db", str(store.path), str(out)]) == 2
    err = capsys.readouterr().err
    assert "not a leaderboard export" in err and str(out) in err and "Traceback" not in err
    assert sorted(p.name for p in out.iterdir()) == ["index.html", "notes.txt"]
    assert (out / "index.html").read_text() == "my own page"


@pytest.mark.parametrize("manifest", [b"{not json", b'{"generator": "zendar-leaderboard render"}', b"[1, 2]"])
def test_an_export_whose_manifest_is_unreadable_is_refused_untouched_saying_so(tmp_path, capsys, manifest):
    store = board_with(tmp_path, [("Radar Lab", "m", AP)])
    out = tmp_path / "site"
    render_site(store, out)
    (out / MANIFEST_NAME).write_bytes(manifest)
    before = {p: p.read_bytes() for p in out.rglob("*") if p.is_file()}
    assert main(["render", "--db", str(store.path), str(out)]) == 2
    err = capsys.readouterr().err
    assert f"holds a {MANIFEST_NAME} that cannot be read" in err and str(out) in err
    assert f"no {MANIFEST_NAME} in it" not in err  # it is there
    assert {p: p.read_bytes() for p in out.rglob("*") if p.is_file()} == before


def test_an_export_holding_foreign_files_is_refused_untouched(tmp_path, capsys):
    store = board_with(tmp_path, [("Radar Lab", "m", AP)])
    out = tmp_path / "site"
    render_site(store, out)
    (out / "CNAME").write_text("board.example.org")
    before = {p: p.read_bytes() for p in out.rglob("*") if p.is_file()}
    assert main(["render", "--db", str(store.path), str(out)]) == 2
    err = capsys.readouterr().err
    assert "files the export did not write (CNAME)" in err
    assert {p: p.read_bytes() for p in out.rglob("*") if p.is_file()} == before


@pytest.mark.parametrize("existing", ["missing", "empty"])
def test_a_new_or_empty_folder_gets_the_export_and_its_manifest(tmp_path, existing):
    store = board_with(tmp_path, [("Radar Lab", "m", AP)])
    out = tmp_path / "site"
    if existing == "empty":
        out.mkdir()
    written = render_site(store, out)
    manifest = json.loads((out / MANIFEST_NAME).read_text())
    assert sorted(manifest["files"]) == sorted(p.relative_to(out).as_posix() for p in written)
    assert sorted(p.relative_to(out).as_posix() for p in out.rglob("*") if p.is_file()) == sorted(
        manifest["files"] + [MANIFEST_NAME])


def test_without_an_atomic_exchange_the_rebuild_still_replaces_the_export(tmp_path, monkeypatch):
    from zendar_leaderboard import export

    store = board_with(tmp_path, [("Radar Lab", "kept method", AP), ("Rivals", "withdrawn method", AP)])
    kept, withdrawn = (entry.id for entry in store.submissions())
    out = tmp_path / "site"
    render_site(store, out)
    monkeypatch.setattr(export, "_exchange", lambda first, second: False)
    store.delete(withdrawn)
    render_site(store, out)
    assert {p.name for p in (out / "entry").iterdir()} == {f"{kept}.html"}
    assert "withdrawn method" not in site_text(out)
    assert [p.name for p in tmp_path.iterdir() if p.name.startswith(".")] == []
