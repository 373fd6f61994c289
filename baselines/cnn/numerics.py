"""Portable numerics for the CNNs: the same numbers on every x86-64 CPU with AVX2.

torch (ATen's vector kernels and oneDNN's convolutions), numpy's SIMD loops and its OpenBLAS each
choose their code path by the CPU they find, and the paths round differently: trained on an AVX-512
machine, the CNN rows came out up to 1.3 AP points away from an AVX2 machine's, with the same
seeds and data (the CFAR row was identical). The libraries' own switches hold them to their AVX2
paths, which every x86-64 CPU of the last decade has, so a run gives the same checkpoints and
table on all of them. They are read when the libraries load: :func:`pin_portable_numerics` runs
before numpy or torch is imported, and worker processes inherit the environment.

``zendar-bench --native-isa`` leaves the libraries free (faster on AVX-512, numbers tied to the
CPU). Without AVX2 (another architecture, or a CPU this module cannot inspect) nothing is pinned
and the run says ``native``. Variables a user has set are left as they are. Code that trains
without ``zendar-bench`` gets oneDNN's cap alone (:func:`hold_convolutions_to_avx2`, applied when
:mod:`zendar_baselines.cnn.training` is imported): oneDNN reads it at the process's first
convolution, so it still works once torch is loaded, which the other switches do not.
"""

from __future__ import annotations

import os
import platform
from collections.abc import Mapping, Sequence
from pathlib import Path

NATIVE_ISA_FLAG = "--native-isa"

#: Each library's switch to its AVX2 code path.
PORTABLE_NUMERICS_ENV: Mapping[str, str] = {
    "ATEN_CPU_CAPABILITY": "avx2",  # torch's vectorised kernels
    "ONEDNN_MAX_CPU_ISA": "AVX2",  # torch's CPU convolutions
    "MKL_CBWR": "AVX2",  # MKL, where torch uses it
    "OPENBLAS_CORETYPE": "Haswell",  # numpy's OpenBLAS
    "NPY_DISABLE_CPU_FEATURES": "X86_V4 AVX512_ICL AVX512_SPR",  # numpy's own SIMD dispatch
}

PORTABLE = "portable-avx2"
NATIVE = "native"
_ONEDNN = "ONEDNN_MAX_CPU_ISA"


def _has_avx2(cpuinfo: Path = Path("/proc/cpuinfo")) -> bool:
    if platform.machine().lower() not in ("x86_64", "amd64"):
        return False
    try:
        text = cpuinfo.read_text(errors="replace")
    except OSError:
        return False
    return any(line.startswith("flags") and " avx2" in f" {line.split(':', 1)[-1]}" for line in text.splitlines())


def pin_portable_numerics(argv: Sequence[str], environ: os._Environ | dict[str, str] = os.environ) -> str:
    """Set :data:`PORTABLE_NUMERICS_ENV` in ``environ`` unless ``--native-isa`` is in ``argv`` or the CPU lacks AVX2.

    Returns
    -------
    str
        :data:`PORTABLE` or :data:`NATIVE`: the mode the run's numbers are made in.
    """
    if NATIVE_ISA_FLAG in argv:
        environ.setdefault(_ONEDNN, "ALL")  # else the training module would cap it
        return NATIVE
    if not _has_avx2():
        return NATIVE
    for name, value in PORTABLE_NUMERICS_ENV.items():
        environ.setdefault(name, value)
    return numerics_mode(environ)


def hold_convolutions_to_avx2(environ: os._Environ | dict[str, str] = os.environ) -> None:
    """Cap oneDNN's convolutions at AVX2 unless the environment says otherwise (the training module's default)."""
    environ.setdefault(_ONEDNN, PORTABLE_NUMERICS_ENV[_ONEDNN])


def numerics_mode(environ: Mapping[str, str] = os.environ) -> str:
    """:data:`PORTABLE` when every switch holds its AVX2 value, else :data:`NATIVE` (part of every step's cache key)."""
    pinned = all(environ.get(name) == value for name, value in PORTABLE_NUMERICS_ENV.items())
    return PORTABLE if pinned else NATIVE


__all__ = [
    "NATIVE",
    "NATIVE_ISA_FLAG",
    "PORTABLE",
    "PORTABLE_NUMERICS_ENV",
    "hold_convolutions_to_avx2",
    "numerics_mode",
    "pin_portable_numerics",
]
