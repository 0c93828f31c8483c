"""Differentiable inversion: the atmosphere behind a sky image.

Given an image (spectral or RGB EXR, or an 8-bit PNG/JPEG), its camera and the sun's position,
:func:`invert` fits aerosol optical depth, Angstrom exponent, Cornette–Shanks g, ozone, ground
albedo (and optionally the Rayleigh scale and the aerosol's single-scattering albedo) plus an
exposure scale, with the ground-truth path tracer as the forward model and its forward-mode
automatic derivatives as the Jacobian. Modules: :mod:`.inputs` (images, camera, sun, masks,
checks), :mod:`.parameters` (the unknowns, bounds, mapping to the integrator), :mod:`.model`
(forward model and Jacobian), :mod:`.optimizer` (Levenberg–Marquardt, uncertainties,
identifiability), :mod:`.result` (JSON, plots, EXR).

    from skyref.invert import read_image, observation, ParameterSet, invert
    obs = observation(read_image("sky.exr"), camera={"type": "fisheye"}, sun=Sun(40, 120))
    result = invert(obs, ParameterSet(preset("bruneton2017")), progress=True)
    result.write("fit/")
"""

from skyref.invert.inputs import (Observation, SkyImage, estimate_sun, image_from_sky, observation,
                                  read_exclusion_mask, read_image, sun_from_arguments)
from skyref.invert.optimizer import InversionSettings, invert
from skyref.invert.parameters import DEFAULT_FREE, UNKNOWNS, ParameterSet
from skyref.invert.result import InversionResult

__all__ = ["DEFAULT_FREE", "UNKNOWNS", "InversionResult", "InversionSettings", "Observation", "ParameterSet",
           "SkyImage", "estimate_sun", "image_from_sky", "invert", "observation", "read_exclusion_mask",
           "read_image", "sun_from_arguments"]
