"""skyref: reference skies from a spectral, unbiased atmosphere path tracer.

``skyref.atmosphere`` (the physical model) imports neither Mitsuba nor JAX; the renderer
(``skyref.render_sky``) loads Mitsuba on first use, after pointing Dr.Jit at a working libLLVM.
"""

__version__ = "0.1.0"
