"""Naming what an output folder holds that is not the command's own."""

from __future__ import annotations

from zendar_dataset.output_location import other_entries


def test_other_entries_names_five_sorted_then_counts_the_rest(tmp_path):
    for name in ("g", "b", "a", "f", "c", "e", "d", "mine"):
        (tmp_path / name).write_text("x")
    assert other_entries(tmp_path, lambda entry: entry.name == "mine") == "a, b, c, d, e and 2 more"


def test_other_entries_is_none_when_everything_is_claimed_or_the_folder_is_empty(tmp_path):
    assert other_entries(tmp_path) is None
    (tmp_path / "store").mkdir()
    assert other_entries(tmp_path, lambda entry: entry.name == "store") is None
    assert other_entries(tmp_path) == "store"
