#!/usr/bin/env bash
# The checks to run on a machine with an NVIDIA GPU, in the order of what they tell (each
# stops at its time limit, so a short loan still gets the first ones):
#   1. the estimators' z-tests (closed forms, DISORT, volpath, hard cases, sampled sunlight,
#      adaptive render, polarization, gradients) in the CUDA variants: SKYREF_TEST_BACKEND=cuda;
#   2. benchmarks/groundtruth_speed.py --variant cuda_ad_rgb --grids rgb --quick: the GPU's wall
#      time to 1% against delta tracking in the same run (kernels compiled before each timing),
#      written to results/groundtruth_speed_cuda_ad_rgb.{md,json}.
# Usage: bash benchmarks/gpu_check.sh [TESTS_SECONDS [BENCHMARK_SECONDS]]  (defaults 420, 300)
# Needs skyref importable (run.sh's .venv, or PYTHONPATH; on a machine without a package index,
# the archive of benchmarks/gpu_bundle.sh) and a CUDA driver.
set -uo pipefail
cd "$(dirname "$0")/.."
PYTHON=${PYTHON:-$( [ -x .venv/bin/python ] && echo .venv/bin/python || echo python3 )}
export PYTHONUNBUFFERED=1
# Files named one by one: given a directory too, pytest would run everything in directory order.
SKYREF_TEST_BACKEND=cuda timeout "${1:-420}" "$PYTHON" -m pytest -v -p no:cacheprovider -rfE \
    tests/test_groundtruth_closed_forms.py tests/test_groundtruth_disort.py tests/test_line_integral.py \
    tests/test_groundtruth_hard_cases.py tests/test_groundtruth_energy.py tests/test_volpath_agreement.py \
    tests/test_integrator_plugin.py tests/test_adaptive_render.py tests/test_iprt.py tests/test_polarization.py \
    tests/test_groundtruth_objects.py tests/test_groundtruth_gradients.py tests/test_sensors.py
echo "tests: exit status $? (124: stopped at the time limit)"
timeout "${2:-300}" "$PYTHON" benchmarks/groundtruth_speed.py --quick --variant cuda_ad_rgb --grids rgb
echo "benchmark: exit status $?"
