"""The one atomic writer: content and mode of what it writes, and nothing left behind on failure."""

from __future__ import annotations

import json
import math
import os
import stat

import pytest

from zendar_dataset.atomic_files import prepare_out_dir, write_bytes_atomic, write_json_atomic, write_text_atomic


def _mode(path) -> int:
    return stat.S_IMODE(os.stat(path).st_mode)


def test_files_follow_the_umask_unless_a_mode_is_given(tmp_path):
    old = os.umask(0o077)
    try:
        write_bytes_atomic(tmp_path / "private.bin", b"\x00\x01")
        write_bytes_atomic(tmp_path / "published.html", b"<p>", mode=0o644)
    finally:
        os.umask(old)
    assert (tmp_path / "private.bin").read_bytes() == b"\x00\x01"
    assert _mode(tmp_path / "private.bin") == 0o600
    assert _mode(tmp_path / "published.html") == 0o644


def test_a_rewrite_replaces_the_whole_file_and_leaves_no_temporary(tmp_path):
    path = tmp_path / "table.md"
    write_text_atomic(path, "a much longer first version\n")
    write_text_atomic(path, "short\n")
    assert path.read_text() == "short\n"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["table.md"]


def test_json_is_strict_and_a_refused_value_leaves_the_old_file(tmp_path):
    path = tmp_path / "results.json"
    write_json_atomic(path, {"ap": 0.5})
    assert path.read_text() == '{\n "ap": 0.5\n}\n'
    with pytest.raises(ValueError):
        write_json_atomic(path, {"ap": math.nan})
    assert json.loads(path.read_text()) == {"ap": 0.5}
    assert sorted(p.name for p in tmp_path.iterdir()) == ["results.json"]


def test_prepare_out_dir_refuses_a_file(tmp_path):
    (tmp_path / "taken").write_text("mine")
    with pytest.raises(NotADirectoryError):
        prepare_out_dir(tmp_path / "taken")
    assert prepare_out_dir(tmp_path / "new" / "dir").is_dir()
    assert (tmp_path / "taken").read_text() == "mine"
