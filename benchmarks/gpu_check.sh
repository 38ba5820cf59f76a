#!/usr/bin/env bash
# The GPU half in one short run (a few minutes on one CUDA GPU), from the repository root of a
# machine where `python` has torch with CUDA and this project installed (`pip install -e '.[test]'`):
# the device tests with their CUDA variants, then the throughput benchmark on the CPU and CUDA
# (eager and compiled on CUDA). Logs go to $OUT (default: results/).
#   benchmarks/gpu_check.sh
set -euo pipefail
cd "$(dirname "$0")/.."
out="${OUT:-results}"
mkdir -p "$out"
python -c "import torch; assert torch.cuda.is_available(), 'no CUDA device is visible'; print(torch.cuda.get_device_name(0))"
OMP_NUM_THREADS=1 python -m pytest tests/test_device.py -q -p no:cacheprovider 2>&1 | tee "$out/gpu_tests.log"
OMP_NUM_THREADS=1 python benchmarks/gpu_throughput.py --devices cpu cuda --compile-on cuda --rounds 3 \
    --workers 1 2 2>&1 | tee "$out/gpu_throughput.log"
