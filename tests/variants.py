"""The Mitsuba variants the tests render in: Dr.Jit's LLVM backend (the CPU) by default, its CUDA
backend with ``SKYREF_TEST_BACKEND=cuda`` (``SKYREF_TEST_BACKEND=cuda bash run.sh test`` on a
machine with an NVIDIA GPU). Tests about libLLVM itself keep the LLVM variants."""

import os

from skyref.validation import check_choice

BACKEND = check_choice("SKYREF_TEST_BACKEND", os.environ.get("SKYREF_TEST_BACKEND", "llvm"), ("llvm", "cuda"))
RGB = f"{BACKEND}_ad_rgb"
SPECTRAL = f"{BACKEND}_ad_spectral"
