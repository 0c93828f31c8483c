"""Python Mitsuba plugins as classes of the current variant.

A Python plugin class derives from a Mitsuba base class (``mi.Medium``, ``mi.PhaseFunction``,
``mi.Sensor``) that exists once per variant, and Mitsuba's C++ rejects an instance whose base
belongs to another variant. nanobind classes also take a single base, so mixins are out: the
plugin's methods live in a plain class and are copied onto a class made per variant; they reach
the base through ``self._mitsuba_base`` instead of ``super()``.
"""

import mitsuba as mi

__all__ = ["variant_class", "is_instance"]

_CLASSES = {}


def variant_class(methods, name: str, base_name: str):
    """The class ``name`` deriving from ``mi.<base_name>`` of the current variant, carrying the
    methods of ``methods`` (created once per variant)."""
    key = (name, mi.variant())
    if key not in _CLASSES:
        base = getattr(mi, base_name)
        namespace = {k: v for k, v in vars(methods).items() if k not in ("__dict__", "__weakref__")}
        namespace["_mitsuba_base"] = base
        namespace["__module__"] = methods.__module__
        _CLASSES[key] = type(name, (base,), namespace)
    return _CLASSES[key]


def is_instance(obj, name: str) -> bool:
    """Whether ``obj`` is an instance of the class ``name`` made for any variant."""
    return isinstance(obj, tuple(cls for (n, _), cls in _CLASSES.items() if n == name))
