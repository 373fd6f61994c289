"""The simulator's API never hangs: the README quickstart as a plain script, jobs > 1 from an
unguarded script, a worker that dies at start-up."""

from __future__ import annotations

import pathlib
import re
import subprocess
import sys
import textwrap

import pytest

README = pathlib.Path(__file__).resolve().parents[2] / "README.md"
# Far above the seconds these take on a loaded 2-core machine; reached only by a hang.
HANG_S = 600


def _quickstart() -> str:
    text = README.read_text(encoding="utf-8")
    section = text.split("## Quickstart", 1)
    assert len(section) == 2, "README.md has no '## Quickstart' section"
    block = re.search(r"```python\n(.*?)```", section[1], re.S)
    assert block, "README.md's Quickstart has no python block"
    code = block.group(1)
    assert "synthesize_dataset(" in code and "__main__" not in code
    return re.sub(r"n_scenes=\d+", "n_scenes=1", code)


def _run_script(tmp_path: pathlib.Path, code: str, name: str = "script.py") -> subprocess.CompletedProcess:
    script = tmp_path / name
    script.write_text(code, encoding="utf-8")
    return subprocess.run([sys.executable, str(script)], cwd=tmp_path, capture_output=True, text=True, timeout=HANG_S)


@pytest.mark.slow
def test_the_readme_quickstart_runs_as_an_unguarded_script(tmp_path):
    done = _run_script(tmp_path, _quickstart(), "quickstart.py")
    assert done.returncode == 0, done.stderr[-3000:]
    assert "Traceback" not in done.stderr
    assert (tmp_path / "data" / "tiny" / "dataset.json").is_file()
    assert "scene-0000/" in done.stdout  # the frame id printed by the snippet


def test_jobs_from_an_unguarded_script_fail_at_once_with_what_to_do(tmp_path):
    code = textwrap.dedent(
        """
        from zendar_dataset.sim.generate import synthesize_dataset

        synthesize_dataset("out", "tiny", n_scenes=2, progress=False, jobs=2)
        """
    )
    done = _run_script(tmp_path, code)
    assert done.returncode == 1
    last = done.stderr.strip().splitlines()[-1]
    assert last.startswith("zendar_dataset.errors.ZendarError: synthesize_dataset(jobs=2)"), done.stderr
    assert "script.py (line 4)" in last and "if __name__ == \"__main__\":" in last and "jobs=1" in last
    # Refused before anything was written.
    assert not (tmp_path / "out").exists()


def test_guard_detection_accepts_guarded_calls_and_code_without_a_script(tmp_path):
    guarded = textwrap.dedent(
        """
        import sys
        from zendar_dataset.sim.generate import _refuse_unguarded_main

        def main():
            _refuse_unguarded_main(2)

        try:  # the guard need not be a top-level statement
            if "__main__" == __name__:
                main()
                print("accepted")
        except KeyboardInterrupt:
            pass
        """
    )
    done = _run_script(tmp_path, guarded)
    assert done.returncode == 0 and done.stdout.strip() == "accepted", done.stderr
    # python -c has no script for a worker to re-run.
    inline = subprocess.run(
        [sys.executable, "-c", "from zendar_dataset.sim.generate import _refuse_unguarded_main as r; r(2); print('ok')"],
        capture_output=True, text=True, timeout=HANG_S,
    )
    assert inline.returncode == 0 and inline.stdout.strip() == "ok", inline.stderr


@pytest.mark.slow
def test_a_worker_that_dies_at_start_up_fails_the_run(tmp_path):
    # The script removes itself, so the guard check cannot read it and each spawned worker,
    # which re-runs the main script, dies before it starts. The run must fail, not wait for ever.
    code = textwrap.dedent(
        """
        import os
        from zendar_dataset.sim.generate import SceneSynthesisError, synthesize_dataset

        os.remove(__file__)
        try:
            synthesize_dataset("out", "tiny", n_scenes=2, progress=False, jobs=2)
        except SceneSynthesisError as exc:
            print("failed:", exc)
        """
    )
    done = _run_script(tmp_path, code)
    assert done.returncode == 0, done.stderr[-3000:]
    assert re.fullmatch(r"failed: scene-000[01]: a worker process died \(.*\)\n", done.stdout), done.stdout
    scenes = tmp_path / "out" / "scenes"
    assert not scenes.exists() or [p.name for p in scenes.iterdir()] == []
