"""Dotted keys (``schedule.head``) into nested mappings: the one walker for every settings path."""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

MISSING = object()  # ``get``'s answer for a path that is not there


def get(params: Mapping[str, Any], path: str) -> Any:
    """The value at ``path`` in ``params``, or ``MISSING``."""
    node: Any = params
    for key in path.split("."):
        if not isinstance(node, Mapping) or key not in node:
            return MISSING
        node = node[key]
    return node


def without(params: Mapping[str, Any], paths: tuple[str, ...]) -> dict[str, Any]:
    """``params`` less the values at ``paths``; ``params`` itself is left as it is."""
    out = dict(params)
    for path in paths:
        *parents, leaf = path.split(".")
        node = out
        for parent in parents:
            if not isinstance(node.get(parent), Mapping):
                break
            node[parent] = node = dict(node[parent])
        else:
            node.pop(leaf, None)
    return out


def assign(params: dict[str, Any], path: str, value: Any) -> None:
    """Set ``path`` in ``params`` to ``value`` in place, copying (or making) the mappings above."""
    *parents, leaf = path.split(".")
    node = params
    for parent in parents:
        node[parent] = node = dict(node.get(parent) or {})
    node[leaf] = value
