"""Finding a libLLVM that Dr.Jit can use (without touching the real drjit import)."""

import sys

import pytest

from skyref import _llvm


@pytest.mark.parametrize("path,expected", [
    ("libLLVM-19.so", 19),
    ("libLLVM-19.so.1", 19),
    ("/usr/lib/x86_64-linux-gnu/libLLVM-15.so.1", 15),
    ("libLLVM.so.19.1", 19),
    ("/usr/lib/x86_64-linux-gnu/libLLVM.so.18.1", 18),
    ("/usr/lib/llvm-17/lib/libLLVM.so", 17),
    ("/usr/lib/llvm-16/lib/libLLVM-16.so", 16),
    ("/usr/lib/llvm-14/lib/libLLVM-14.0.6.so", 14),
    ("/opt/homebrew/opt/llvm/lib/libLLVM-20.dylib", 20),
    ("/usr/local/lib/libLLVM.so", None),
    ("/usr/lib/libfoo.so.19", None),
])
def test_major_version(path, expected):
    assert _llvm.major_version(path) == expected


def _candidates(monkeypatch, versions):
    found = [(v, f"/fake/llvm-{v}/lib/libLLVM-{v}.so") for v in versions]
    monkeypatch.setattr(_llvm, "candidate_libraries", lambda: found)


def test_working_library_skips_15_and_16(monkeypatch):
    _candidates(monkeypatch, [16, 15, 14])
    assert _llvm.working_library() is None


def test_working_library_takes_first_good_one(monkeypatch):
    _candidates(monkeypatch, [16, 15])
    assert _llvm.working_library() is None
    _candidates(monkeypatch, [19, 16, 15])
    assert _llvm.working_library() == "/fake/llvm-19/lib/libLLVM-19.so"
    _candidates(monkeypatch, [16, 17, 15])
    assert _llvm.working_library() == "/fake/llvm-17/lib/libLLVM-17.so"


def test_broken_versions_skipped_even_below_the_minimum(monkeypatch):
    # 15 and 16 are excluded for crashing Dr.Jit, not only for being old.
    monkeypatch.setattr(_llvm, "MINIMUM_MAJOR_VERSION", 1)
    _candidates(monkeypatch, [16, 15])
    assert _llvm.working_library() is None
    _candidates(monkeypatch, [16, 15, 14])
    assert _llvm.working_library() == "/fake/llvm-14/lib/libLLVM-14.so"


def test_working_library_none_found(monkeypatch):
    _candidates(monkeypatch, [])
    assert _llvm.working_library() is None


def _clear_env(monkeypatch):
    # setenv first so that monkeypatch restores the original state even if the code under test
    # sets the variable itself.
    monkeypatch.setenv("DRJIT_LIBLLVM_PATH", "placeholder")
    monkeypatch.delenv("DRJIT_LIBLLVM_PATH")


def test_configure_respects_user_setting(monkeypatch):
    monkeypatch.setenv("DRJIT_LIBLLVM_PATH", "/my/own/libLLVM.so")

    def must_not_search():
        raise AssertionError("searched although DRJIT_LIBLLVM_PATH was set")

    monkeypatch.setattr(_llvm, "working_library", must_not_search)
    monkeypatch.delitem(sys.modules, "drjit", raising=False)
    assert _llvm.configure_libllvm() == "/my/own/libLLVM.so"
    import os
    assert os.environ["DRJIT_LIBLLVM_PATH"] == "/my/own/libLLVM.so"


def test_configure_sets_the_variable(monkeypatch):
    import os

    _clear_env(monkeypatch)
    monkeypatch.delitem(sys.modules, "drjit", raising=False)
    monkeypatch.setattr(_llvm, "working_library", lambda: "/fake/libLLVM-19.so")
    assert _llvm.configure_libllvm() == "/fake/libLLVM-19.so"
    assert os.environ["DRJIT_LIBLLVM_PATH"] == "/fake/libLLVM-19.so"


def test_configure_without_a_working_library_leaves_the_llvm_backend_off(monkeypatch):
    """No working libLLVM: Dr.Jit is pointed at no library (not left to load a broken 15/16),
    so the CUDA variants still work."""
    import os

    _clear_env(monkeypatch)
    monkeypatch.delitem(sys.modules, "drjit", raising=False)
    monkeypatch.setattr(_llvm, "working_library", lambda: None)
    assert _llvm.configure_libllvm() == _llvm.NO_LIBRARY
    assert os.environ["DRJIT_LIBLLVM_PATH"] == _llvm.NO_LIBRARY
    assert not os.path.exists(_llvm.NO_LIBRARY)


def test_configure_after_drjit_import_changes_nothing(monkeypatch):
    import os

    _clear_env(monkeypatch)
    monkeypatch.setitem(sys.modules, "drjit", object())
    monkeypatch.setattr(_llvm, "working_library", lambda: "/fake/libLLVM-19.so")
    assert _llvm.configure_libllvm() == ""
    assert "DRJIT_LIBLLVM_PATH" not in os.environ


def test_candidate_libraries_on_this_machine():
    found = _llvm.candidate_libraries()
    assert found == sorted(found, reverse=True)
    for version, path in found:
        assert version == _llvm.major_version(path)
        assert "libLLVM" in path
