"""Analytic sky models: closed-form skies that a renderer evaluates in nanoseconds, audited
against skyref's ground truth.

- :mod:`skyref.analytic.hosek`: the Hosek–Wilkie (2012) model form, the 5-coefficient Perez form it
  extends, their evaluators (NumPy and JAX) for any coefficient table in the published layout,
  and the published coefficients (version 1.4a, bundled with their BSD license in ``data/``).
  :mod:`skyref.fit` fits tables of both forms to the ground truth.
"""
