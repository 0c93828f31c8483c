"""Mitsuba plugins of skyref, and the one place that loads Mitsuba.

:func:`load_mitsuba` points Dr.Jit at a working libLLVM, selects a variant (``cuda_ad_rgb``
when a GPU is present, else ``llvm_ad_rgb``) and registers skyref's plugins:

- ``atmosphere`` medium (:mod:`skyref.plugins.medium`), usable by stock ``volpath``;
- ``atmosphere_phase`` phase function (:mod:`skyref.plugins.phase`);
- ``equirectangular`` and ``fisheye`` sensors (:mod:`skyref.plugins.sensors`);
- ``atmosphere`` integrator (:mod:`skyref.plugins.integrator`), the fast ground truth.

Dr.Jit and Mitsuba are imported inside the functions on purpose: Dr.Jit loads libLLVM when it is
imported, so :func:`~skyref._llvm.configure_libllvm` must run first, and the plugin modules
import Mitsuba at module level.
"""

from __future__ import annotations

from skyref._llvm import configure_libllvm
from skyref.validation import check_choice

__all__ = ["default_variant", "load_mitsuba"]

_registered_for = set()


def default_variant() -> str:
    import drjit as dr

    return "cuda_ad_rgb" if dr.has_backend(dr.JitBackend.CUDA) else "llvm_ad_rgb"


def load_mitsuba(variant: str | None = None):
    """Import Mitsuba with ``variant`` (default: :func:`default_variant`), register skyref's
    plugins for it and return the ``mitsuba`` module."""
    configure_libllvm()
    import drjit as dr
    import mitsuba as mi

    backends = {"llvm": dr.JitBackend.LLVM, "cuda": dr.JitBackend.CUDA}
    supported = [v for v in mi.variants() if v.split("_", 2)[-1] in ("rgb", "spectral") and "_ad_" in v
                 and dr.has_backend(backends[v.split("_", 1)[0]])]
    variant = check_choice("variant", variant or default_variant(), supported)
    if mi.variant() != variant:
        mi.set_variant(variant)
    if variant not in _registered_for:
        from skyref.plugins import integrator, medium, phase, sensors

        sensors.register_sensors()
        phase.register()
        medium.register()
        integrator.register()
        _registered_for.add(variant)
    return mi
