"""Accuracy audits: a sky method (a LUT method, an analytic model) against the ground truth
rendered for the same atmosphere, wavelengths and view directions.

- :mod:`skyref.audit.regions`: where on the sky an error lies (horizon band, around the sun,
  anti-solar region, the rest, the ground);
- :mod:`skyref.audit.metrics`: error maps and statistics, each beside the ground truth's own
  noise on the same statistic;
- :mod:`skyref.audit.groundtruth`: ground truth rendered (and cached) until its noise is small
  enough to measure the error;
- :mod:`skyref.audit.audit`: one audit from method + scene to a report.
"""
