"""Analytic sky models: closed-form skies that a renderer evaluates in nanoseconds, audited
against skyref's ground truth.

- :mod:`skyref.analytic.hosek`: the Hosek–Wilkie (2012) model form, the 5-coefficient Perez form it
  extends, their evaluators (NumPy and JAX) for any coefficient table in the published layout,
  and the published coefficients (version 1.4a, bundled with their BSD license in ``data/``).
  :mod:`skyref.fit` fits tables of both forms to the ground truth.
- The classic models on a skyref :class:`~skyref.atmosphere.Atmosphere`, behind the interface of
  :mod:`skyref.analytic.base` (the one the audit calls): :mod:`~skyref.analytic.preetham`
  (Preetham, Shirley & Smits 1999), :mod:`~skyref.analytic.hoffman_preetham` (Hoffman &
  Preetham 2002), :mod:`~skyref.analytic.nielsen` (Nielsen 2003), :mod:`~skyref.analytic.nishita93`
  (Nishita et al. 1993), :mod:`~skyref.analytic.oneil` (O'Neil 2005) and
  :mod:`~skyref.analytic.hosek_sky` (a Hosek–Wilkie table as a sky).
"""

from __future__ import annotations

from skyref.sky_method import Registry

__all__ = ["REGISTRY", "MODELS", "model_class", "analytic_model"]

#: Every analytic sky model by name.
REGISTRY = Registry("model", {"preetham1999": ("skyref.analytic.preetham", "Preetham1999"),
                              "hoffman_preetham2002": ("skyref.analytic.hoffman_preetham", "HoffmanPreetham2002"),
                              "nielsen2003": ("skyref.analytic.nielsen", "Nielsen2003"),
                              "nishita1993": ("skyref.analytic.nishita93", "Nishita1993"),
                              "oneil2005": ("skyref.analytic.oneil", "ONeil2005"),
                              "hosek2012": ("skyref.analytic.hosek_sky", "HosekWilkie2012")})
#: name -> (module, class) of every analytic sky model.
MODELS = REGISTRY.entries
model_class = REGISTRY.cls
#: ``analytic_model(name, atmosphere, wavelengths_nm="rgb", **options)``: the model, not yet precomputed.
analytic_model = REGISTRY.build
