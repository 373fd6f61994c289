#!/usr/bin/env bash
# Every GPU figure in one run, for a machine with a CUDA GPU (about 10 minutes; every step has a
# time limit, 48 minutes in all at worst):
# the CUDA tests, the GPU rows of the SAR, radar and CNN benchmarks, and a 5 s `paper`
# scene whose SAR images are backprojected on the GPU (whole-scene wall time, per-image
# rate). Run from the repository root after the README's install:
#
#     bash benchmarks/gpu_checks.sh [OUT_DIR]     (default: gpu-checks/)
#
# Each step writes OUT_DIR/<step>.txt; a failing step is reported and the others still run.
set -u
out=${1:-gpu-checks}
mkdir -p "$out"
python -c "import torch, sys; sys.exit(0 if torch.cuda.is_available() else 'no CUDA device visible to torch')" || exit 2
nvidia-smi > "$out/nvidia-smi.txt" 2>&1
failed=()
step() {
    local name=$1
    shift
    local start=$SECONDS
    echo "== $name: $*"
    "$@" > "$out/$name.txt" 2>&1
    local status=$?
    # pytest exits 5 when it selects no test: nothing failed.
    if ((status != 0)) && ! [[ $name == tests && $status == 5 ]]; then
        failed+=("$name (exit $status)")
    fi
    tail -n 25 "$out/$name.txt"
    echo "== $name: $((SECONDS - start)) s wall"
}
step tests timeout 300 python -m pytest -q -p no:cacheprovider -k "cuda or gpu" tests
step bench_sar timeout 600 python benchmarks/bench_sar.py --device cuda --repeats 3
step bench_radar timeout 300 python benchmarks/bench_radar.py --device cuda
step bench_models timeout 600 python benchmarks/bench_models.py --device cuda
rm -rf "$out/paper-5s"
step paper_scene timeout 900 zendar-data synth "$out/paper-5s" --profile paper --scenes 1 --duration-s 5 \
    --device cuda --quiet
step paper_fidelity timeout 180 zendar-data fidelity "$out/paper-5s" --out "$out/paper-5s-fidelity"
if ((${#failed[@]})); then
    echo "failed steps: ${failed[*]} (see $out/<step>.txt)"
    exit 1
fi
echo "all steps passed; outputs in $out/"
