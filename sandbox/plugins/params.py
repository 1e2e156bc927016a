"""The declaration of one YAML key: :class:`Param`, its types, and :func:`declare`.

Every key of the scenario format is declared once as a :class:`Param`: the sections of
the format by the scenario layer, a plug-in's keys by its registration. From that
declaration the loader reads and checks the key, the JSON Schema describes it and the
documentation lists it.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

__all__ = ["PARAM_TYPES", "REQUIRED", "SECTION_TYPES", "Param", "declare"]

#: A parameter without a default: the key must be given.
REQUIRED: Any = type("Required", (), {"__repr__": lambda self: "REQUIRED"})()
#: Parameter types a declaration may name.
PARAM_TYPES = (
    "number",
    "length",
    "integer",
    "boolean",
    "string",
    "name",
    "choice",
    "point",
    "points",
)
#: Further types the scenario layer uses for its own sections (read by its code).
SECTION_TYPES = ("text", "custom")


# ----------------------------------------------------------------------- parameters
@dataclass(frozen=True)
class Param:
    """One YAML key of a plug-in or of a section of the scenario format.

    Parameters
    ----------
    type : str
        One of :data:`PARAM_TYPES`: ``number``, ``length`` (metres or ``"3d"``),
        ``integer``, ``boolean``, ``string``, ``name`` (one plain line, usable in
        file names), ``choice`` (one of ``choices``), ``point`` (two lengths [m]),
        ``points`` (a list of at least ``min_items`` points).
    default : optional
        The value used when the key is left out; :data:`REQUIRED` (the default) makes
        the key required; ``None`` makes it optional without a value. A length's
        default may be written ``"3d"`` (a multiple of the vehicle diameter).
    unit : str
        Unit of the value (``"m"``, ``"s"``, ``"rad/s"``, ...), empty for none.
    doc : str
        One line: what the key means.
    minimum, maximum : float, optional
        Bounds (inclusive unless ``exclusive``).
    exclusive : bool
        Whether ``minimum`` itself is excluded (``> minimum``).
    choices : tuple of str
        The allowed values of a ``choice``.
    min_items : int
        Fewest points of a ``points`` value.
    schema : dict, optional
        The JSON Schema fragment of a ``custom`` key (a section of the format).
    """

    type: str = "number"
    default: Any = REQUIRED
    unit: str = ""
    doc: str = ""
    minimum: float | None = None
    maximum: float | None = None
    exclusive: bool = False
    choices: tuple[str, ...] = ()
    min_items: int = 2
    schema: dict[str, Any] | None = field(default=None, compare=False)

    def __post_init__(self) -> None:
        if self.type not in PARAM_TYPES + SECTION_TYPES:
            raise ValueError(
                f"parameter type {self.type!r} is not one of: {', '.join(PARAM_TYPES)}"
            )
        if self.type == "choice" and not self.choices:
            raise ValueError("a choice parameter needs its choices")

    @property
    def required(self) -> bool:
        """Whether the key must be given."""
        return self.default is REQUIRED

    def bounds_text(self) -> str:
        """The bounds in words, e.g. ``> 0`` or ``from 1 to 10000`` (empty if none)."""
        lo, hi = self.minimum, self.maximum
        if lo is not None and hi is not None:
            return f"from {lo:g} to {hi:g}"
        if lo is not None:
            return f"{'>' if self.exclusive else '>='} {lo:g}"
        if hi is not None:
            return f"<= {hi:g}"
        return ""


def declare(params: Mapping[str, Any] | None) -> dict[str, Param]:
    """Turn a ``params=`` argument into :class:`Param` declarations, in order.

    A value that is a :class:`Param` is used as is; any other value is a default and
    its type gives the parameter's: a float (or None) a ``number``, an int an
    ``integer``, a bool a ``boolean``, a str a ``string``, two numbers a ``point``.

    >>> declare({"gain": 1.0, "count": 3})["count"].type
    'integer'
    """
    out: dict[str, Param] = {}
    for name, value in (params or {}).items():
        if not isinstance(name, str) or not name.isidentifier():
            raise ValueError(f"parameter name {name!r} is not an identifier")
        if isinstance(value, Param):
            out[name] = value
        elif isinstance(value, bool):
            out[name] = Param("boolean", value)
        elif isinstance(value, int):
            out[name] = Param("integer", value)
        elif value is None or isinstance(value, float):
            out[name] = Param("number", value)
        elif isinstance(value, str):
            out[name] = Param("string", value)
        elif isinstance(value, list | tuple) and len(value) == 2:
            out[name] = Param("point", tuple(float(v) for v in value), unit="m")
        else:
            raise ValueError(
                f"parameter {name!r}: cannot tell the type of the default {value!r} "
                "(give a Param(...))"
            )
    return out
