"""Fitting analytic sky models to skyref's ground truth (JAX + optimistix).

- :mod:`skyref.fit.training`: training skies (from a ``skyref batch`` dataset, or synthesized);
- :mod:`skyref.fit.forms`: bounds and scale of each model form;
- :mod:`skyref.fit.fitter`: the fit (per configuration, Bezier curves, joint refinement);
- :mod:`skyref.fit.evaluate`: errors of a table against training skies, how it blends between its
  stored configurations, evaluation speed;
- :mod:`skyref.fit.export`: ``.npz``, JSON and C headers in the published layout, and reading
  them back; ``c/hosek_eval.c`` evaluates those headers in C;
- :mod:`skyref.fit.cli`: ``skyref fit``.
"""
