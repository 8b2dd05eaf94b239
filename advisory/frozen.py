"""A quicker ``__init__`` for the frozen, slotted dataclasses made at every fix (the advisory, the lights seen, the fix).

A frozen dataclass's generated ``__init__`` sets each field with ``object.__setattr__(self, name, value)`` (its own
``__setattr__`` refuses): a name looked up and a generic attribute set per field, ~0.25 us each (an ``Advice``, 11
fields: 2.7 us). :func:`quick_init` gives the class an ``__init__`` with the same parameters and defaults that sets each
slot through its descriptor (``Advice``: 1.1 us), so a fix's seven or eight such objects cost ~7 us less (issue 30:
CPU per fix). The class stays as it was: frozen (assignment raises), hashed, compared and printed by its fields.
"""

from __future__ import annotations

import dataclasses


def quick_init(cls: type) -> type:
    """``cls`` (a ``@dataclass(frozen=True, slots=True)`` whose fields all go to ``__init__``, positional or keyword,
    with plain defaults, and no ``__post_init__``) with an ``__init__`` that sets its slots through their descriptors.

    Examples
    --------
    >>> @quick_init
    ... @dataclasses.dataclass(frozen=True, slots=True)
    ... class P:
    ...     x_m: float
    ...     y_m: float = 0.0
    >>> P(1.0), P(y_m=2.0, x_m=1.0) == P(1.0, 2.0), hash(P(1.0)) == hash((1.0, 0.0))
    (P(x_m=1.0, y_m=0.0), True, True)
    >>> P(1.0).x_m = 2.0
    Traceback (most recent call last):
    dataclasses.FrozenInstanceError: cannot assign to field 'x_m'
    """
    params = cls.__dataclass_params__  # (the arguments @dataclass was given)
    fields = dataclasses.fields(cls)
    if not (params.frozen and "__slots__" in cls.__dict__) or hasattr(cls, "__post_init__"):
        raise TypeError(f"{cls.__name__}: quick_init takes a frozen, slotted dataclass without __post_init__")
    if any(not f.init or f.kw_only or f.default_factory is not dataclasses.MISSING for f in fields):
        raise TypeError(f"{cls.__name__}: quick_init takes fields that are all positional, in __init__, with plain defaults")
    scope = {f"_set_{f.name}": getattr(cls, f.name).__set__ for f in fields}
    scope.update({f"_default_{f.name}": f.default for f in fields if f.default is not dataclasses.MISSING})
    args = ", ".join(f.name if f.default is dataclasses.MISSING else f"{f.name}=_default_{f.name}" for f in fields)
    body = "".join(f"\n    _set_{f.name}(self, {f.name})" for f in fields)
    made: dict = {}
    exec(f"def __init__(self, {args}):{body}", scope, made)  # (as dataclasses writes its own __init__)
    init = made["__init__"]
    init.__qualname__ = f"{cls.__qualname__}.__init__"
    init.__doc__ = cls.__init__.__doc__
    cls.__init__ = init
    return cls
