"""Find a libLLVM that Dr.Jit's LLVM backend can use, before drjit is imported.

Dr.Jit loads libLLVM at import time. Debian 12's default libLLVM 15 and 16 make it abort
("LLVM ERROR: Cannot select ... fminimum"); libLLVM 17 or newer works (19 is the one tested).
:func:`configure_libllvm` sets ``DRJIT_LIBLLVM_PATH`` to the newest working library it finds.
Where there is none it sets :data:`NO_LIBRARY` instead, so that Dr.Jit's LLVM backend stays off
rather than loading a library that crashes it: the CUDA variants still work (a GPU machine needs
no libLLVM), and :func:`skyref.plugins.load_mitsuba` says what to install when an LLVM variant
is asked for.

Once Dr.Jit is loaded, :func:`allow_vector_gathers` lets LLVM emit AVX2 gather instructions on
CPUs whose LLVM tuning scalarizes them (AMD Zen): a scalarized gather splits the kernel into a
basic block per lane, and compiling the line integral's kernels then took 4x longer
(docs/design.md, "libLLVM").
"""

from __future__ import annotations

import ctypes
import glob
import os
import re
import subprocess
import sys

#: Major versions of libLLVM that crash Dr.Jit 1.5 on these machines (see docs/design.md).
BROKEN_MAJOR_VERSIONS = frozenset({15, 16})
#: Set to 0 to keep LLVM's own choice of gather instructions (:func:`allow_vector_gathers`).
FAST_GATHER_VARIABLE = "SKYREF_LLVM_FAST_GATHER"

#: Oldest major version known to work.
MINIMUM_MAJOR_VERSION = 17

_SEARCH_GLOBS = (
    "/usr/lib/llvm-*/lib/libLLVM*.so*",
    "/usr/lib/*-linux-gnu/libLLVM*.so*",
    "/lib/*-linux-gnu/libLLVM*.so*",
    "/usr/lib64/libLLVM*.so*",
    "/usr/local/lib/libLLVM*.so*",
    "/opt/homebrew/opt/llvm/lib/libLLVM*.dylib",
    "/usr/local/opt/llvm/lib/libLLVM*.dylib",
)

#: What ``DRJIT_LIBLLVM_PATH`` is set to when no working libLLVM is found: no file, so Dr.Jit's
#: LLVM backend stays inactive.
NO_LIBRARY = "none (skyref found no working libLLVM)"

INSTALL_HINT = (
    "Dr.Jit needs libLLVM 17 or newer (Debian's libLLVM 15/16 crash it). "
    "On Debian 12 run: apt-get install libllvm19 "
    "(or set DRJIT_LIBLLVM_PATH to a working libLLVM.so)."
)


def major_version(path: str) -> int | None:
    """Major version encoded in a libLLVM file name (``libLLVM-19.so.1``, ``libLLVM.so.19.1``)."""
    name = os.path.basename(path)
    match = re.match(r"libLLVM(?:-(\d+))?\.(?:so|dylib)(?:\.(\d+))?", name)
    if match and (match.group(1) or match.group(2)):
        return int(match.group(1) or match.group(2))
    match = re.search(r"llvm-(\d+)", path)
    return int(match.group(1)) if match else None


def candidate_libraries() -> list[tuple[int, str]]:
    """All libLLVM files on this machine with their major versions, newest first."""
    paths = set()
    for pattern in _SEARCH_GLOBS:
        paths.update(glob.glob(pattern))
    try:
        listing = subprocess.run(["ldconfig", "-p"], capture_output=True, text=True, timeout=10).stdout
        paths.update(re.findall(r"=>\s*(\S*libLLVM\S*)", listing))
    except (OSError, subprocess.SubprocessError):
        pass
    found = {}
    for path in paths:
        version = major_version(path)
        if version is not None and os.path.exists(path):
            found.setdefault(os.path.realpath(path), (version, path))
    return sorted(found.values(), reverse=True)


def working_library() -> str | None:
    """Path of the newest libLLVM whose major version is known to work, or None."""
    for version, path in candidate_libraries():
        if version >= MINIMUM_MAJOR_VERSION and version not in BROKEN_MAJOR_VERSIONS:
            return path
    return None


def configure_libllvm() -> str:
    """Point Dr.Jit at a working libLLVM; return its path (:data:`NO_LIBRARY` when none was
    found: Dr.Jit's LLVM backend is then left inactive).

    A ``DRJIT_LIBLLVM_PATH`` already set by the user is respected. Must run before ``drjit`` is
    imported; if drjit is already loaded the current setting is returned unchanged.
    """
    preset = os.environ.get("DRJIT_LIBLLVM_PATH")
    if preset:
        return preset
    if "drjit" in sys.modules:
        return ""
    path = working_library() or NO_LIBRARY
    os.environ["DRJIT_LIBLLVM_PATH"] = path
    return path


def _llvm_target():
    """drjit-core's functions that read and set its LLVM target (cpu, features, vector width,
    set_target), typed; None where Dr.Jit has no LLVM backend or lacks them."""
    import drjit as dr

    if not dr.has_backend(dr.JitBackend.LLVM):
        return None
    try:
        core = ctypes.CDLL(os.path.join(os.path.dirname(dr.__file__), "libdrjit-core.so"))
        cpu, features = core._Z19jit_llvm_target_cpuv, core._Z24jit_llvm_target_featuresv
        width, set_target = core._Z21jit_llvm_vector_widthv, core._Z19jit_llvm_set_targetPKcS0_j
    except (OSError, AttributeError):
        return None
    cpu.restype = features.restype = ctypes.c_char_p
    width.restype = ctypes.c_uint32
    set_target.argtypes = [ctypes.c_char_p, ctypes.c_char_p, ctypes.c_uint32]
    return cpu, features, width, set_target


def llvm_target_features() -> list[str]:
    """The features (``+avx2``, ``-xop``, ...) Dr.Jit's LLVM backend compiles for; [] where it
    has none."""
    target = _llvm_target()
    return [] if target is None else (target[1]() or b"").decode().split(",")


def allow_vector_gathers() -> bool:
    """Let Dr.Jit's LLVM backend compile gathers (table lookups) to AVX2 gather instructions;
    return whether the target was changed.

    LLVM emits them only on CPUs it tunes as having fast gathers (Intel since Skylake, any
    AVX-512 CPU); elsewhere (AMD Zen) it turns each vector gather into one branch per lane. The
    line integral's kernels hold thousands of lookups, and splitting them into blocks cost most of
    their compile time: the hard-case test's clear-sky kernels compiled in 362 s as LLVM tuned
    them, 87 s with gathers, and ran no slower (same radiance to the last bit;
    ``benchmarks/kernel_compile.py`` measures it).

    Adds ``+fast-gather`` to the target's features where AVX2 is present and neither
    ``+fast-gather`` nor ``+prefer-no-gather`` (a security mitigation) is; a no-op otherwise, on a
    Dr.Jit without its ``jit_llvm_set_target``, or with ``SKYREF_LLVM_FAST_GATHER=0``. Applies to
    every kernel compiled afterwards in this process."""
    if os.environ.get(FAST_GATHER_VARIABLE, "1") == "0":
        return False
    target = _llvm_target()
    features = llvm_target_features()
    if target is None or "+avx2" not in features or "+fast-gather" in features or "+prefer-no-gather" in features:
        return False
    cpu, _, width, set_target = target
    set_target(cpu(), ",".join(features + ["+fast-gather"]).encode(), width())
    return True


if __name__ == "__main__":  # `python -m skyref._llvm`: exit 0 when a working libLLVM is present
    sys.exit(0 if working_library() else 1)
