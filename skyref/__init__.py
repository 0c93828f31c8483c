"""skyref: reference skies from a spectral, unbiased atmosphere path tracer.

``skyref.atmosphere`` (the physical model) imports neither Mitsuba nor JAX; the renderer
(``skyref.render_sky``) loads Mitsuba on first use, after pointing Dr.Jit at a working libLLVM.
"""

__version__ = "0.1.0"

__all__ = ["render_sky", "load_scene", "Scene", "Sky"]


def __getattr__(name):
    # Lazy: importing skyref must not import Mitsuba (or pvlib, colour) until they are needed.
    if name == "render_sky":
        from skyref.render import render_sky

        return render_sky
    if name in ("load_scene", "Scene"):
        from skyref import scene

        return getattr(scene, name)
    if name == "Sky":
        from skyref.sky import Sky

        return Sky
    raise AttributeError(f"module 'skyref' has no attribute {name!r}")
