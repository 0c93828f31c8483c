"""The array namespace through which skyref's NumPy-style formulas (density profiles, phase
functions, spectra, camera projections) run on Dr.Jit arrays of the current Mitsuba variant."""

import drjit as dr

__all__ = ["DrJitNamespace", "xp", "channel_mean"]


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
    abs = staticmethod(dr.abs)
    cbrt = staticmethod(dr.cbrt)
    copysign = staticmethod(dr.copysign)

    @staticmethod
    def interp(x, xs, ys):
        """np.interp for a Float ``x`` and device tables ``xs`` (increasing) and ``ys``: linear
        between the bracketing entries, clamped to the ends."""
        table = type(xs)
        n = dr.width(xs)
        i = dr.binary_search(0, n - 2, lambda j: dr.gather(table, xs, j + 1) < x)
        x0, x1 = dr.gather(table, xs, i), dr.gather(table, xs, i + 1)
        y0, y1 = dr.gather(table, ys, i), dr.gather(table, ys, i + 1)
        return dr.lerp(y0, y1, dr.clip((x - x0) / (x1 - x0), 0.0, 1.0))


xp = DrJitNamespace()


def channel_mean(values):
    """The mean of a per-channel array's entries (its outer dimension: the K channels of an
    ``ArrayXf``, a ``Spectrum``'s), lane by lane. Not ``dr.mean(values, axis=0)``: Dr.Jit 1.5
    computes that as the sum times (lanes / values), two literals that bake the lane count into
    the kernel, so that every new number of samples per launch compiled the path tracer again
    (3-24 s for the line integral at RGB and 21 wavelengths)."""
    return dr.sum(values, axis=0) * (1.0 / len(values))
