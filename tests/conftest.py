"""Shared fixtures: Mitsuba loaded once, in the CPU RGB variant, with skyref's plugins."""

import pytest


@pytest.fixture(scope="session")
def mi():
    from skyref.plugins import load_mitsuba

    return load_mitsuba("llvm_ad_rgb")
