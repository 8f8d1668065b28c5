"""Read node parameters into a config dataclass, rejecting bad values by name.

Pure: the parameter source is a callable ``get(name, default)`` (the nodes pass
``rospy.get_param``), so the checks are unit-tested without a master.
"""
from __future__ import annotations

import dataclasses
import math
import re
from collections.abc import Callable, Mapping
from typing import Any, TypeVar

T = TypeVar("T")
_MISSING = object()


class ParamError(ValueError):
    """A parameter has a wrong type or value; the message names the parameter."""


def _coerce(param: str, value: Any, default: Any) -> Any:
    """Check ``value`` against the type of the field's default."""
    if isinstance(default, bool):
        if not isinstance(value, bool):
            raise ParamError(f"parameter {param} must be true or false, got {value!r}")
        return value
    if isinstance(default, int):
        if isinstance(value, bool) or not isinstance(value, (int, float)) or int(value) != value:
            raise ParamError(f"parameter {param} must be an integer, got {value!r}")
        return int(value)
    if isinstance(default, float):
        if isinstance(value, bool) or not isinstance(value, (int, float)) or math.isnan(value):
            raise ParamError(f"parameter {param} must be a number, got {value!r}")
        return float(value)
    if isinstance(default, str):
        if not isinstance(value, str):
            raise ParamError(f"parameter {param} must be a string, got {value!r}")
        return value
    return value


def read_config(cls: type[T], get: Callable[[str, Any], Any], names: Mapping[str, str | tuple[str, ...]],
                **fixed: Any) -> T:
    """Build ``cls`` from parameters.

    ``names`` maps a dataclass field to its parameter name, or to a tuple of
    names tried in order (e.g. ``("~base_width", "base_width")``: private
    first, then global).  Fields not in ``names`` take ``fixed`` values or
    their defaults.  Wrong types and values rejected by ``cls`` raise
    :class:`ParamError` naming the parameter.
    """
    defaults = {f.name: f.default for f in dataclasses.fields(cls)}
    kwargs: dict[str, Any] = dict(fixed)
    used: dict[str, str] = {}
    for field, pnames in names.items():
        if isinstance(pnames, str):
            pnames = (pnames,)
        value = _MISSING
        for p in pnames:
            value = get(p, _MISSING)
            if value is not _MISSING:
                used[field] = p
                break
        if value is _MISSING:
            continue
        kwargs[field] = _coerce(used[field], value, defaults[field])
    try:
        return cls(**kwargs)
    except ValueError as exc:
        msg = str(exc)
        for field, pnames in names.items():
            pname = used.get(field, pnames if isinstance(pnames, str) else pnames[0])
            msg = re.sub(rf"\b{re.escape(field)}\b", f"parameter {pname}", msg)
        raise ParamError(msg) from exc
