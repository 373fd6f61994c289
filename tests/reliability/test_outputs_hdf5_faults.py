"""Faults while HDF5 writes a scene, without a small disk: a write that fails with ENOSPC and a Ctrl-C
inside a write. HDF5 must never see either (it crashes closing a file whose write failed, h5py
issue 914); the writer raises in Python, removes its temporary, and the process exits normally.

Each case runs in a child process so that a crash by signal shows as its exit status.
"""

from __future__ import annotations

import pathlib
import subprocess
import sys
import textwrap

import pytest

SCRIPT = textwrap.dedent(
    """
    import errno, io, os, pathlib, sys
    import numpy as np
    from tests.format.conftest import ENU_ORIGIN, make_calibration, write_scene
    from zendar_dataset.format import guarded_file
    from zendar_dataset.format.writer import SceneWriter

    FAULT, LIMIT = sys.argv[1], int(sys.argv[2])

    class Faulty(io.FileIO):
        # Fails the first write that would take the file past LIMIT bytes.
        written = 0
        fired = False

        def write(self, data):
            size = memoryview(data).nbytes
            if not Faulty.fired and Faulty.written + size > LIMIT:
                Faulty.fired = True
                if FAULT == "enospc":
                    raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))
                raise KeyboardInterrupt
            Faulty.written += size
            return super().write(data)

    guarded_file.open = lambda path, mode, buffering: Faulty(path, "x+")
    out = pathlib.Path(sys.argv[3])
    try:
        with SceneWriter(out / "s0.h5", "s0", enu_origin=ENU_ORIGIN, calibration=make_calibration()) as scene:
            write_scene(scene, np.random.default_rng(0), n_frames=60)
    except OSError as exc:
        print("raised", type(exc).__name__, exc.errno, exc.filename)
    except KeyboardInterrupt:
        print("raised KeyboardInterrupt")
    else:
        print("no error")
    print("left", sorted(p.name for p in out.iterdir()))
    """
)


@pytest.mark.parametrize(
    ("fault", "expected"),
    [("enospc", "raised OSError 28 "), ("interrupt", "raised KeyboardInterrupt")],
)
@pytest.mark.parametrize("limit", [4096, 200_000])
def test_a_failed_or_interrupted_hdf5_write_raises_in_python_and_leaves_nothing(tmp_path, fault, expected, limit):
    result = subprocess.run(
        [sys.executable, "-c", SCRIPT, fault, str(limit), str(tmp_path)],
        capture_output=True, text=True, timeout=300, cwd=pathlib.Path(__file__).parents[2],
    )
    assert result.returncode == 0, (result.returncode, result.stderr[-2000:])
    assert "Traceback" not in result.stderr and "Exception ignored" not in result.stderr, result.stderr[-2000:]
    lines = result.stdout.splitlines()
    assert lines[0].startswith(expected), lines
    if fault == "enospc":
        assert ".s0.h5.tmp-" in lines[0]  # the message names the file
    assert lines[1] == "left []"
