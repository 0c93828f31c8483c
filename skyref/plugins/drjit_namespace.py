"""The array namespace through which skyref's NumPy-style formulas (density profiles, phase
functions, spectra, camera projections) run on Dr.Jit arrays of the current Mitsuba variant."""

import drjit as dr


class DrJitNamespace:
    """``xp`` for Dr.Jit: the subset of NumPy's names that skyref's formulas use."""

    exp = staticmethod(dr.exp)
    log = staticmethod(dr.log)
    sqrt = staticmethod(dr.sqrt)
    sin = staticmethod(dr.sin)
    cos = staticmethod(dr.cos)
    atan2 = staticmethod(dr.atan2)
    acos = staticmethod(dr.acos)
    minimum = staticmethod(dr.minimum)
    maximum = staticmethod(dr.maximum)
    clip = staticmethod(dr.clip)
    where = staticmethod(dr.select)


xp = DrJitNamespace()
