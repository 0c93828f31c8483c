"""Real-time LUT methods: precomputed tables of atmospheric scattering, as engines use them.

Every method takes the same :class:`~skyref.atmosphere.Atmosphere` and wavelength grid as the
ground truth, precomputes its tables (:meth:`~skyref.lut.base.LutMethod.precompute`) and answers
:meth:`~skyref.lut.base.LutMethod.radiance` for view directions, so :mod:`skyref.audit` can
compare it with the path tracer.

Shared pieces: :mod:`skyref.lut.table` (GPU-texture lookups, float16/float32 storage),
:mod:`skyref.lut.planet` (r, mu ray geometry), :mod:`skyref.lut.transmittance` (Bruneton's
transmittance table, also Hillaire's).
"""

from __future__ import annotations

import importlib

from skyref.atmosphere.validation import check_choice

#: name -> (module, class) of every LUT method.
METHODS = {"bruneton2017": ("skyref.lut.bruneton", "Bruneton2017"),
           "elek2009": ("skyref.lut.elek", "Elek2009"),
           "hillaire2020": ("skyref.lut.hillaire", "Hillaire2020")}


def method_class(name: str):
    module, cls = METHODS[check_choice("method", name, tuple(METHODS))]
    return getattr(importlib.import_module(module), cls)


def lut_method(name: str, atmosphere, wavelengths_nm="rgb", **options):
    """The LUT method ``name`` (one of :data:`METHODS`) for ``atmosphere``, not yet precomputed;
    ``options`` are the method's own (resolutions, orders, precision, ...) and are kept in its
    ``options`` attribute for reports."""
    method = method_class(name)(atmosphere, wavelengths_nm, **options)
    method.options = dict(options)
    return method
