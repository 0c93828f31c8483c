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

from skyref.sky_method import Registry

__all__ = ["REGISTRY", "METHODS", "method_class", "lut_method"]

#: Every LUT method by name.
REGISTRY = Registry("method", {"bruneton2017": ("skyref.lut.bruneton", "Bruneton2017"),
                               "elek2009": ("skyref.lut.elek", "Elek2009"),
                               "hillaire2020": ("skyref.lut.hillaire", "Hillaire2020")})
#: name -> (module, class) of every LUT method.
METHODS = REGISTRY.entries
method_class = REGISTRY.cls
#: ``lut_method(name, atmosphere, wavelengths_nm="rgb", **options)``: the method, not yet precomputed.
lut_method = REGISTRY.build
