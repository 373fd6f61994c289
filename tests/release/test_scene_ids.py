"""Scene ids from the whole path, and a re-import told apart by the content of the source streams."""

from __future__ import annotations

import json
import shutil

from tests.release import encoder as enc
from tests.release.fixture import T0_S, build_release
from tests.release.test_import import run
from zendar_dataset.format import open_dataset


def _tracklog_scene(folder, t0_s: float) -> None:
    enc.write_stream(folder / "vn200.pbs", [enc.position_record(t0_s + k * 0.01, (1, 0, 0, 0), (6.4e6, 0, 0), k) for k in range(5)])


def test_one_scene_folder_at_a_time_keeps_its_date_and_two_dates_do_not_collide(tmp_path, capsys):
    src = tmp_path / "release"
    _tracklog_scene(src / "2020-02-21_0900" / "001", T0_S)
    _tracklog_scene(src / "2020-02-22_1015" / "001", T0_S + 86400)
    out = tmp_path / "out"
    for date in ("2020-02-21_0900", "2020-02-22_1015"):
        status, stdout, err = run("import-release", src / date / "001", out, capsys=capsys)
        assert status == 0, err
        assert f"scene {date}_001 (imported)" in stdout
    assert sorted(open_dataset(out).scene_ids()) == ["2020-02-21_0900_001", "2020-02-22_1015_001"]


def test_a_different_recording_under_an_existing_id_is_an_error_a_moved_copy_is_not(tmp_path, capsys):
    first, second, out = tmp_path / "a", tmp_path / "b", tmp_path / "out"
    build_release(first, "2020")
    build_release(second, "2021")  # the same folders, another recording
    status, _, err = run("import-release", first, out, capsys=capsys)
    assert status == 0, err
    recorded = json.loads((out / "release_import.json").read_text())["scenes"][0]["fingerprint"]
    assert recorded.startswith("sha256:")
    before = sorted(p.name for p in (out / "scenes").iterdir())

    status, stdout, err = run("import-release", second, out, capsys=capsys)
    assert status == 2 and "Traceback" not in err
    assert "scene '2020-02-03_2252_001' already holds a different recording" in err and str(first) in err
    assert "already imported" not in stdout
    assert sorted(p.name for p in (out / "scenes").iterdir()) == before

    moved = tmp_path / "elsewhere" / "copy"
    shutil.copytree(first, moved)
    (moved / "2020-02-03_2252" / "001" / "vn200.pbs").rename(moved / "2020-02-03_2252" / "001" / "tracklog.pbs")
    status, stdout, err = run("import-release", moved / "2020-02-03_2252" / "001", out, capsys=capsys)
    assert status == 0, err
    assert "scene 2020-02-03_2252_001 (already imported)" in stdout
