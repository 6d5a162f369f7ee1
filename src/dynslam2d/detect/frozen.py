"""Fast constructors of frozen slots dataclasses (the tracker's reports: :class:`dynslam2d.types.Track`, ``Box``).

The ``__init__`` that :mod:`dataclasses` generates for a frozen class sets every field through
``object.__setattr__`` (its ``__setattr__`` raises), a few µs per object; a tracker step reports every live
track, and on a recording with much clutter (``negative_2``: ≈ 35 live tracks per scan) building the
reports was the largest single cost of the step. :func:`fast_init` returns a function that takes the same
arguments as the class and sets the slots directly: on an instance of an unfrozen twin class with the same slots
(plain attribute stores, the fastest way to fill slots from Python), which then becomes an instance of the class
by ``__class__`` assignment (allowed between classes of the same slot layout), else through the slots'
descriptors; the object is the same (same type, same field values, frozen afterwards). Classes it cannot handle
(no ``__slots__``, a ``__post_init__``, a field with a ``default_factory`` or ``init=False``) get the class itself back.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from typing import Any


def _layout_twin_ok(cls: type) -> bool:
    """An instance of a plain class with the slots of ``cls`` (same names, same order: the same instance layout)
    can become an instance of ``cls`` by ``__class__`` assignment (False where Python refuses it)."""
    if cls.__bases__ != (object,):
        return False
    twin = type(f"_{cls.__name__}Twin", (), {"__slots__": tuple(cls.__slots__)})
    try:
        object.__new__(twin).__class__ = cls
    except TypeError:
        return False
    return True


def fast_init(cls: type) -> Callable[..., Any]:
    """A constructor of the frozen slots dataclass ``cls`` with the signature of ``cls(...)`` (positional or
    keyword, defaults kept); ``cls`` itself where a direct slot assignment would not be the same object."""
    if not dataclasses.is_dataclass(cls) or not hasattr(cls, "__slots__") or hasattr(cls, "__post_init__") \
            or not cls.__dataclass_params__.init:
        return cls
    fields = dataclasses.fields(cls)
    names = [f.name for f in fields]
    if set(names) != set(cls.__slots__) or any(
            not f.init or f.default_factory is not dataclasses.MISSING or f.name.startswith("_fi_") for f in fields):
        return cls
    env: dict[str, Any] = {"_fi_new": object.__new__, "_fi_cls": cls}
    params = []
    for i, f in enumerate(fields):
        env[f"_fi_set{i}"] = cls.__dict__[f.name].__set__  # the slot's member descriptor
        if f.default is dataclasses.MISSING:
            params.append(f.name)
        else:
            env[f"_fi_dflt{i}"] = f.default
            params.append(f"{f.name}=_fi_dflt{i}")
    if _layout_twin_ok(cls):
        # an instance of an unfrozen twin class with the same slots, its fields stored by plain attribute stores, then
        # made an instance of cls (``__class__`` assignment: the same layout, the values stay). A function, not the
        # twin's ``__init__``: calling a class goes through type.__call__, tp_new and slot_tp_init's look-up of
        # ``__init__``, ≈ 0.3 µs per object more than a Python function call and ``object.__new__`` (docs/speed.md,
        # pass trk22)
        env["_fi_twin"] = type(f"_{cls.__name__}Twin", (), {"__slots__": tuple(cls.__slots__)})
        body = "".join(f"    _fi_obj.{n} = {n}\n" for n in names)
        src = (f"def make({', '.join(params)}):\n    _fi_obj = _fi_new(_fi_twin)\n{body}"
               f"    _fi_obj.__class__ = _fi_cls\n    return _fi_obj\n")
    else:
        body = "".join(f"    _fi_set{i}(_fi_obj, {n})\n" for i, n in enumerate(names))
        src = f"def make({', '.join(params)}):\n    _fi_obj = _fi_new(_fi_cls)\n{body}    return _fi_obj\n"
    exec(src, env)  # noqa: S102 (the same technique as dataclasses' own generated __init__)
    make = env["make"]
    make.__doc__ = f"{cls.__name__}(...) with its slots set directly (detect.frozen.fast_init)."
    return make

__all__ = ["fast_init"]
