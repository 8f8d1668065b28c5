"""Read node parameters into a config dataclass, rejecting bad values by name.

Pure: the parameter source is a callable ``get(name, default)`` (the nodes pass
``rospy.get_param``), so the checks are unit-tested without a master.

Every node declares what it reads as module-level :class:`ParamSpec` objects
(a config dataclass + the parameter name(s) of its fields) listed in its
``PARAMS`` tuple; ``main()`` reads through those same objects
(``SPEC.read(rospy.get_param)``) and ``tools/gen_node_docs.py`` documents them,
so the README's parameter table is what the node reads.  Units and meanings come
from the comment on each dataclass field (``rate: float = 10.0  # Hz: ...``).
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
    """Check ``value`` against the type of the field's default (``_MISSING``: no check)."""
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
    # a union annotation (``device: int | str``) or a list/dict default: the dataclass checks the value
    defaults = {f.name: _MISSING if "|" in str(f.type) else f.default for f in dataclasses.fields(cls)}
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


@dataclasses.dataclass(frozen=True)
class ParamSpec:
    """What a node reads into one config dataclass: ``names`` maps each field read from the
    parameter server to its name, or to names tried in order (see :func:`read_config`).

    Fields not in ``names`` are not parameters (``read(get, field=value)`` sets them).
    """

    cls: type
    names: Mapping[str, str | tuple[str, ...]]

    def read(self, get: Callable[[str, Any], Any], **fixed: Any) -> Any:
        """``read_config(self.cls, get, self.names, **fixed)``; ``fixed`` values are the defaults
        of fields in ``names`` too (a parameter that is set wins)."""
        return read_config(self.cls, get, self.names, **fixed)


def private_spec(cls: type, prefix: str = "", skip: tuple[str, ...] = (),
                 **names: str | tuple[str, ...]) -> ParamSpec:
    """ParamSpec reading every field of ``cls`` as ``~<prefix><field>``, except the fields in
    ``skip``; ``names`` gives other names for some fields."""
    return ParamSpec(cls, {f.name: names.get(f.name, f"~{prefix}{f.name}")
                           for f in dataclasses.fields(cls) if f.name not in skip})
