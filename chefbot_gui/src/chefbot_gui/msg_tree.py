"""A ROS message as a tree of (field, type, value) for the Topic Monitor.

Pure (no rospy, no Qt): it walks any genpy message by its ``__slots__`` and
``_slot_types`` (what every generated Python message class has), so it works
for every type without knowing it.  Long arrays are shortened to their first
``max_items`` elements plus a ``…`` row, byte arrays (``uint8[]``) to a hex
preview, long strings to ``max_chars``; nesting stops at ``max_depth``.
"""
from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

MAX_ITEMS = 16       # array elements shown
MAX_CHARS = 200      # string characters shown
MAX_BYTES = 16       # bytes of a uint8[] shown in hex
MAX_DEPTH = 12       # nested message levels


class DecodeError(RuntimeError):
    """A topic's last message cannot be shown as fields (type not installed, bad bytes); says why."""


@dataclass(frozen=True)
class TreeNode:
    """One row: field ``name``, ROS ``type``, ``value`` text ('' for a nested message) and children."""

    name: str
    type: str
    value: str = ""
    children: tuple[TreeNode, ...] = ()

    def find(self, path: str) -> TreeNode | None:
        """The node at a dotted path (``pose.position.x``, ``data[3]``), or None."""
        node: TreeNode | None = self
        for part in _split_path(path):
            node = next((c for c in node.children if c.name == part), None) if node else None
        return node


def _split_path(path: str) -> list[str]:
    parts: list[str] = []
    for p in path.split("."):
        name, _, rest = p.partition("[")
        if name:
            parts.append(name)
        while rest:
            idx, _, rest = rest.partition("]")
            parts.append(f"[{idx}]")
            rest = rest.lstrip("[")
    return parts


def fmt_scalar(v: object, max_chars: int = MAX_CHARS) -> str:
    """Display text of one primitive field value."""
    if isinstance(v, bool):
        return str(v).lower()
    if isinstance(v, float):
        return f"{v:.6g}" if math.isfinite(v) else str(v)
    if isinstance(v, str):
        return repr(v if len(v) <= max_chars else v[:max_chars]) + ("…" if len(v) > max_chars else "")
    if _is_time(v):
        signed = int(v.secs) * 1_000_000_000 + int(v.nsecs)
        total = abs(signed)
        return f"{'-' if signed < 0 else ''}{total // 1_000_000_000}.{total % 1_000_000_000:09d}"
    return str(v)


def _is_time(v: object) -> bool:
    # genpy Time/Duration (TVal): secs + nsecs and to_nsec(); generated messages have no to_nsec
    return hasattr(v, "secs") and hasattr(v, "nsecs") and hasattr(v, "to_nsec")


def _is_message(v: object) -> bool:
    return hasattr(v, "__slots__") and hasattr(v, "_slot_types")


def _base_type(typ: str) -> tuple[str, bool]:
    """``float64[]`` → (``float64``, True); ``Header`` → (``Header``, False)."""
    i = typ.find("[")
    return (typ[:i], True) if i >= 0 else (typ, False)


def _bytes_preview(b: bytes | bytearray, max_bytes: int) -> str:
    head = " ".join(f"{x:02x}" for x in b[:max_bytes])
    return f"{len(b)} bytes: {head}" + (" …" if len(b) > max_bytes else "")


def message_tree(msg: object, name: str = "", typ: str = "", *, max_items: int = MAX_ITEMS,
                 max_chars: int = MAX_CHARS, max_bytes: int = MAX_BYTES, max_depth: int = MAX_DEPTH) -> TreeNode:
    """The tree of ``msg`` (a genpy message, or any value of a field of type ``typ``)."""
    return _node(msg, name, typ or getattr(msg, "_type", ""), 0,
                 (max_items, max_chars, max_bytes, max_depth))


def _node(v: object, name: str, typ: str, depth: int, lim: tuple[int, int, int, int]) -> TreeNode:
    max_items, max_chars, max_bytes, max_depth = lim
    base, is_array = _base_type(typ)
    if is_array or (isinstance(v, (list, tuple, bytes, bytearray)) and not typ):
        if isinstance(v, (bytes, bytearray)):
            return TreeNode(name, typ, _bytes_preview(v, max_bytes))
        if not isinstance(v, Sequence):
            return TreeNode(name, typ, f"<{type(v).__name__}, expected an array>")
        n = len(v)
        if depth >= max_depth:
            return TreeNode(name, typ, f"{n} items (too deep to show)")
        kids = [_node(x, f"[{i}]", base, depth + 1, lim) for i, x in enumerate(v[:max_items])]
        if n > max_items:
            kids.append(TreeNode("…", "", f"{n - max_items} more, {n} in all"))
        return TreeNode(name, typ, f"{n} items", tuple(kids))
    if _is_time(v):
        return TreeNode(name, typ, fmt_scalar(v, max_chars))
    if _is_message(v):
        if depth >= max_depth:
            return TreeNode(name, typ, "(too deep to show)")
        kids = tuple(_node(getattr(v, s, None), s, t, depth + 1, lim)
                     for s, t in zip(v.__slots__, v._slot_types, strict=False))
        return TreeNode(name, typ or getattr(v, "_type", ""), "", kids)
    return TreeNode(name, typ, fmt_scalar(v, max_chars))
