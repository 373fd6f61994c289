"""zendar-bench's portable numerics: the libraries held to their AVX2 paths, so CNN numbers do not
depend on whether the CPU has AVX-512."""

from __future__ import annotations

import subprocess
import sys
import textwrap

import pytest

from zendar_baselines.cnn import numerics
from zendar_baselines.cnn.numerics import (
    NATIVE,
    PORTABLE,
    PORTABLE_NUMERICS_ENV,
    hold_convolutions_to_avx2,
    numerics_mode,
    pin_portable_numerics,
)

AVX2 = numerics._has_avx2()

_TRAIN = textwrap.dedent(
    """
    import hashlib, json, numpy as np, torch
    torch.manual_seed(0)
    torch.set_num_threads(1)
    net = torch.nn.Sequential(torch.nn.Conv2d(8, 16, 3, padding=1), torch.nn.BatchNorm2d(16), torch.nn.ReLU(),
                              torch.nn.Conv2d(16, 1, 3, padding=1))
    x = torch.randn(4, 8, 64, 32)
    opt = torch.optim.Adam(net.parameters(), 1e-3)
    for _ in range(5):
        opt.zero_grad()
        net(x).square().mean().backward()
        opt.step()
    digest = hashlib.sha256(b"".join(p.detach().numpy().tobytes() for p in net.parameters())).hexdigest()
    from numpy._core._multiarray_umath import __cpu_features__ as features  # as numpy's dispatch sees the CPU
    print(json.dumps({"torch": torch.backends.cpu.get_cpu_capability(), "digest": digest,
                      "numpy_avx512": any(features.get(name) for name in ("X86_V4", "AVX512_ICL", "AVX512_SPR"))}))
    """
)


def _train_in(env: dict[str, str]) -> dict:
    import json
    import os

    done = subprocess.run([sys.executable, "-c", _TRAIN], env={**os.environ, **env}, capture_output=True, text=True,
                          timeout=300, check=True)
    return json.loads(done.stdout.strip().splitlines()[-1])


def test_pinning_sets_every_switch_keeps_the_users_and_says_the_mode(monkeypatch):
    monkeypatch.setattr(numerics, "_has_avx2", lambda: True)
    environ: dict[str, str] = {}
    assert pin_portable_numerics(["run"], environ) == PORTABLE
    assert environ == dict(PORTABLE_NUMERICS_ENV)
    assert numerics_mode(environ) == PORTABLE

    mine = {"OPENBLAS_CORETYPE": "SkylakeX"}
    assert pin_portable_numerics([], mine) == NATIVE  # the user's choice stands, and the run says so
    assert mine["OPENBLAS_CORETYPE"] == "SkylakeX"

    native: dict[str, str] = {}
    assert pin_portable_numerics(["--native-isa"], native) == NATIVE
    assert native == {"ONEDNN_MAX_CPU_ISA": "ALL"}  # explicitly free: the training module caps it otherwise

    alone: dict[str, str] = {}
    hold_convolutions_to_avx2(alone)
    assert alone == {"ONEDNN_MAX_CPU_ISA": "AVX2"}
    assert numerics_mode(alone) == NATIVE  # oneDNN's cap alone is not the portable mode

    monkeypatch.setattr(numerics, "_has_avx2", lambda: False)
    assert pin_portable_numerics([], {}) == NATIVE


@pytest.mark.skipif(not AVX2, reason="the AVX2 paths need an x86-64 CPU with AVX2")
def test_pinned_libraries_run_their_avx2_paths():
    pinned = _train_in(dict(PORTABLE_NUMERICS_ENV))
    assert pinned["torch"] == "AVX2"
    assert not pinned["numpy_avx512"]
    # The same training twice under the pins: the same bytes (the pins add no nondeterminism).
    assert _train_in(dict(PORTABLE_NUMERICS_ENV))["digest"] == pinned["digest"]


def test_the_bench_command_pins_before_numpy_and_torch_load():
    import os

    probe = textwrap.dedent(
        """
        import sys
        sys.argv = ["zendar-bench", "--help"]
        from zendar_baselines.bench import cli
        def show():
            import os, torch
            print({name: os.environ.get(name) for name in %r})
            print(torch.backends.cpu.get_cpu_capability())
            return 0
        cli.main = show
        from zendar_baselines.entry import zendar_bench
        sys.exit(zendar_bench())
        """
        % (list(PORTABLE_NUMERICS_ENV),)
    )
    env = {k: v for k, v in os.environ.items() if k not in PORTABLE_NUMERICS_ENV}
    done = subprocess.run([sys.executable, "-c", probe], env=env, capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr
    if AVX2:
        assert str(dict(PORTABLE_NUMERICS_ENV)) in done.stdout
        assert done.stdout.strip().splitlines()[-1] == "AVX2"
