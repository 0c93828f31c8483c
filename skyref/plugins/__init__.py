"""Mitsuba plugins of skyref, and the one place that loads Mitsuba.

The plugins, registered per Mitsuba variant by :func:`register`:

- ``atmosphere`` medium (:mod:`skyref.plugins.medium`), usable by stock ``volpath``;
- ``atmosphere_phase`` phase function (:mod:`skyref.plugins.phase`);
- ``equirectangular`` and ``fisheye`` sensors (:mod:`skyref.plugins.sensors`);
- ``atmosphere`` integrator (:mod:`skyref.plugins.integrator`), the fast ground truth;
- ``skyref_sky`` emitter (:mod:`skyref.plugins.sky_emitter`): a skyref sky lights a Mitsuba scene.

They are registered for the variants of :func:`supported_variants` (``*_ad_rgb`` and
``*_ad_spectral`` of the backends this machine has) in any of these ways:

- :func:`load_mitsuba` points Dr.Jit at a working libLLVM, selects a variant (``cuda_ad_rgb``
  when a GPU is present, else ``llvm_ad_rgb``) and registers them;
- importing this package registers them for Mitsuba's current variant, if Mitsuba is imported
  and a variant is set, and from then on for every variant ``mi.set_variant`` selects (Mitsuba's
  variant callbacks, ``mi.detail.add_variant_callback``). If Mitsuba is not imported yet,
  importing this package imports neither Mitsuba nor Dr.Jit (they take ~0.4 s, which
  ``skyref --help`` does not pay) but installs an import hook that does both when the user
  imports Mitsuba. So ``import skyref.plugins; import mitsuba as mi; mi.set_variant(
  "llvm_ad_rgb"); mi.load_dict({"type": "atmosphere"})`` works, and so does importing Mitsuba
  first.

libLLVM: Dr.Jit loads libLLVM when it is imported, so :func:`~skyref._llvm.configure_libllvm` must
run before; the import hook runs it when Dr.Jit is imported after this package. If Dr.Jit was
imported first (``import mitsuba`` before ``import skyref.plugins``) it is too late: registering
for an LLVM variant then checks the libLLVM Dr.Jit loaded and raises
:class:`~skyref.errors.SkyrefSetupError` if it is one that crashes it (15, 16), saying so.

Dr.Jit and Mitsuba are imported inside the functions on purpose (see above); the plugin modules
import Mitsuba at module level.
"""

from __future__ import annotations

import importlib.abc
import importlib.util
import os
import sys

from skyref._llvm import BROKEN_MAJOR_VERSIONS, INSTALL_HINT, allow_vector_gathers, configure_libllvm
from skyref.errors import SkyrefSetupError
from skyref.validation import check_choice

__all__ = ["default_variant", "supported_variants", "register", "load_mitsuba"]

_registered_for = set()


def default_variant() -> str:
    import drjit as dr

    return "cuda_ad_rgb" if dr.has_backend(dr.JitBackend.CUDA) else "llvm_ad_rgb"


def supported_variants() -> list[str]:
    """The Mitsuba variants skyref's plugins run in here: ``*_ad_rgb`` and ``*_ad_spectral`` of
    the Dr.Jit backends (LLVM, CUDA) this machine has."""
    import drjit as dr
    import mitsuba as mi

    backends = {"llvm": dr.JitBackend.LLVM, "cuda": dr.JitBackend.CUDA}
    return [v for v in mi.variants() if v.split("_", 2)[-1] in ("rgb", "spectral") and "_ad_" in v
            and dr.has_backend(backends[v.split("_", 1)[0]])]


def _check_loaded_libllvm():
    """Raise if Dr.Jit loaded a libLLVM that crashes its LLVM backend: one the user's
    ``DRJIT_LIBLLVM_PATH`` names, or Dr.Jit's own choice when it was imported before
    :func:`configure_libllvm` could run."""
    import drjit as dr

    major = dr.detail.llvm_version()[0]
    if major in BROKEN_MAJOR_VERSIONS:
        preset = os.environ.get("DRJIT_LIBLLVM_PATH")
        why = (f"DRJIT_LIBLLVM_PATH={preset}" if preset else
               "drjit (or mitsuba) was imported before skyref could point it at a working libLLVM: import "
               "skyref.plugins, or call skyref.plugins.load_mitsuba(), before mitsuba and drjit")
        raise SkyrefSetupError(f"Dr.Jit loaded libLLVM {major}, which crashes its LLVM backend ({why}). {INSTALL_HINT}")


def register():
    """Register skyref's plugins for Mitsuba's current variant (once per variant); nothing for
    a variant outside :func:`supported_variants` or when no variant is set."""
    import mitsuba as mi

    variant = mi.variant()
    if variant is None or variant in _registered_for or variant not in supported_variants():
        return
    if variant.startswith("llvm"):
        _check_loaded_libllvm()
        allow_vector_gathers()
    from skyref.plugins import integrator, medium, phase, sensors, sky_emitter

    sensors.register_sensors()
    phase.register()
    medium.register()
    integrator.register()
    sky_emitter.register()
    _registered_for.add(variant)


def load_mitsuba(variant: str | None = None):
    """Import Mitsuba with ``variant`` (default: :func:`default_variant`), register skyref's
    plugins for it and return the ``mitsuba`` module."""
    configure_libllvm()
    import drjit as dr
    import mitsuba as mi

    variant = variant or default_variant()
    if variant.startswith("llvm") and not dr.has_backend(dr.JitBackend.LLVM):
        raise SkyrefSetupError(f"variant {variant!r} runs on Dr.Jit's LLVM backend, which has no working "
                               f"libLLVM here (a CUDA GPU would take the cuda_ad_* variants). {INSTALL_HINT}")
    variant = check_choice("variant", variant, supported_variants())
    if mi.variant() != variant:
        mi.set_variant(variant)
    register()
    return mi


def _watch_variants():
    """Register the plugins for the current variant and for each one ``mi.set_variant`` selects."""
    import mitsuba as mi

    mi.detail.add_variant_callback(lambda old, new: register())
    register()


class _ImportHook(importlib.abc.MetaPathFinder):
    """Until Mitsuba is imported: runs :func:`configure_libllvm` before Dr.Jit is imported, and
    :func:`_watch_variants` once Mitsuba is (then it removes itself)."""

    def find_spec(self, name, path=None, target=None):
        if name in ("drjit", "mitsuba"):            # Mitsuba imports Dr.Jit
            configure_libllvm()
        if name != "mitsuba":
            return None
        sys.meta_path.remove(self)
        spec = importlib.util.find_spec(name)
        if spec is not None and spec.loader is not None:
            spec.loader = _ThenWatch(spec.loader)
        return spec


class _ThenWatch(importlib.abc.Loader):
    """Mitsuba's own loader, followed by :func:`_watch_variants`."""

    def __init__(self, loader):
        self.loader = loader

    def create_module(self, spec):
        return self.loader.create_module(spec)

    def exec_module(self, module):
        self.loader.exec_module(module)
        _watch_variants()


if "mitsuba" in sys.modules:
    _watch_variants()
else:
    sys.meta_path.insert(0, _ImportHook())
