"""``zendar-leaderboard`` as a user runs it: exit statuses, printed problems, tokens, export."""

from __future__ import annotations

import csv
import io
import json
import shutil
import socket
import subprocess
import sys
from dataclasses import dataclass

import pytest

from tests.leaderboard.conftest import start_server, submission
from tests.leaderboard.helpers import expected_ap
from zendar_leaderboard.cli import main
from zendar_leaderboard.ground_truth import divide_frames
from zendar_leaderboard.scoring import format_ap_percent
from zendar_leaderboard.store import Store

COMMAND = [shutil.which("zendar-leaderboard")] if shutil.which("zendar-leaderboard") else [
    sys.executable, "-m", "zendar_leaderboard.cli"]


def run(*args, timeout=300):
    """The installed command in a fresh process."""
    return subprocess.run(COMMAND + [str(a) for a in args], capture_output=True, text=True, timeout=timeout)


@dataclass
class Completed:
    returncode: int
    stdout: str
    stderr: str


def run_here(capsys, *args) -> Completed:
    """``main`` in this process (no interpreter start-up): the same code path after argv."""
    capsys.readouterr()
    code = main([str(a) for a in args])
    out, err = capsys.readouterr()
    return Completed(code, out, err)


def test_check_lists_every_problem_and_exits_2(tmp_path, gt_file, capsys):
    gt_path, gt = gt_file
    good = tmp_path / "good.json"
    good.write_text(json.dumps(submission(gt)))
    completed = run_here(capsys, "check", good, "--gt", gt_path)
    assert completed.returncode == 0, completed.stderr
    assert f"valid ({len(gt['frames'])} frames" in completed.stdout
    bad_document = submission(gt, method="m" * 41)
    bad_document["results"].pop(next(iter(gt["frames"])))
    bad = tmp_path / "bad.json"
    bad.write_text(json.dumps(bad_document))
    completed = run("check", bad, "--gt", gt_path)
    assert completed.returncode == 2 and "Traceback" not in completed.stderr
    assert "2 problems found" in completed.stderr and "'method' has 41 characters" in completed.stderr
    # Without --gt the frames are not compared, and it says so.
    completed = run_here(capsys, "check", bad)
    assert completed.returncode == 2 and "'method' has 41" in completed.stderr and "missing from" not in completed.stderr
    assert run_here(capsys, "check", tmp_path / "missing.json").returncode == 2
    assert run_here(capsys, "check", good, "--max-bytes", "10").returncode == 2


def test_add_team_prints_the_token_once_and_stores_only_its_hash(tmp_path, capsys):
    db = tmp_path / "board.db"
    completed = run("add-team", "Radar Lab", "--db", db)
    assert completed.returncode == 0
    token = completed.stdout.strip()
    assert len(token) >= 40 and "\n" not in token
    assert Store(db).team_for_token(token).name == "Radar Lab"
    for path in tmp_path.iterdir():
        assert token.encode() not in path.read_bytes()
    again = run_here(capsys, "add-team", "Radar Lab", "--db", db)
    assert again.returncode == 2 and "already exists" in again.stderr
    assert run_here(capsys, "add-team", "x", "--db", tmp_path / "nowhere" / "b.db").returncode == 2


@pytest.mark.slow
def test_submit_waits_and_prints_the_table_and_render_exports_it(tmp_path, gt_file):
    gt_path, gt = gt_file
    db = tmp_path / "board.db"
    token = Store(db).add_team("cli-team")
    document = submission(gt, seed=3, method="=HYPERLINK(\"http://x\")")
    path = tmp_path / "pred.json"
    path.write_text(json.dumps(document))
    server = start_server(db, gt_path)
    try:
        completed = run("submit", path, "--server", server.url, "--token", token)
        assert completed.returncode == 0, completed.stderr
        ap = expected_ap(gt, document, divide_frames(list(gt["frames"]))[0])
        assert "scored on the public part" in completed.stdout
        line = next(l for l in completed.stdout.splitlines() if l.startswith("all "))
        assert format_ap_percent(ap["all"]) in line.split()  # the printed table is in percent
        refused = run("submit", path, "--server", server.url, "--token", "wrong")
        assert refused.returncode == 2 and "(401)" in refused.stderr
        document["results"].pop(next(iter(gt["frames"])))
        path.write_text(json.dumps(document))
        refused = run("submit", path, "--server", server.url, "--token", token)
        assert refused.returncode == 2 and "(422)" in refused.stderr and "is missing from predictions" in refused.stderr
    finally:
        server.stop()
    assert server.process.returncode == 130  # Ctrl-C
    out = tmp_path / "site"
    completed = run("render", "--db", db, out)
    assert completed.returncode == 0, completed.stderr
    board = json.loads((out / "leaderboard.json").read_text())
    (entry,) = board["entries"]
    assert entry["ap"] == ap and entry["rank"] == 1  # fractions in [0, 1], as the API serves them
    assert all(v is None or 0.0 <= v <= 1.0 for v in entry["ap"].values())
    rows = list(csv.DictReader(io.StringIO((out / "leaderboard.csv").read_text())))
    assert len(rows) == 1 and float(rows[0]["ap_all"]) == ap["all"]
    assert rows[0]["ap_all"] == repr(ap["all"])  # written as the fraction itself, no float artefacts
    assert rows[0]["method"].startswith("'=")  # a spreadsheet shows it as text, not a formula
    index = (out / "index.html").read_text()
    assert f'<td class="num ap">{format_ap_percent(ap["all"])}' in index  # the static page shows percent
    assert f'href="entry/{entry["id"]}.html"' in index and "=HYPERLINK(&quot;http://x&quot;)" in index
    assert "http://127.0.0.1" not in index  # works from disk: no link back to the server
    assert (out / "entry" / f"{entry['id']}.html").read_text().count('href="../index.html"') == 1


def test_environment_failures_exit_1_and_bad_ground_truth_exits_2(tmp_path, gt_file, capsys):
    gt_path, _ = gt_file
    gone = run_here(capsys, "submit", gt_path, "--server", "http://127.0.0.1:9", "--token", "t")
    assert gone.returncode == 1 and "cannot reach http://127.0.0.1:9" in gone.stderr
    bad_gt = tmp_path / "bad_gt.json"
    bad_gt.write_text('{"frames": {"s/1": [{"x": "near"}]}}')
    completed = run_here(capsys, "serve", "--gt", bad_gt, "--db", tmp_path / "b.db", "--port", "0")
    assert completed.returncode == 2 and "Traceback" not in completed.stderr and "'x' must be a number" in completed.stderr
    with socket.socket() as busy:
        busy.bind(("127.0.0.1", 0))
        busy.listen()
        port = busy.getsockname()[1]
        completed = run_here(capsys, "serve", "--gt", gt_path, "--db", tmp_path / "b.db", "--port", port)
    assert completed.returncode == 1 and f"cannot listen on 127.0.0.1:{port}" in completed.stderr
    assert run_here(capsys, "render", "--db", tmp_path / "none.db", tmp_path / "out").returncode == 2
