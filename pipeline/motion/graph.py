"""The scene graph: parent links between objects, and an evaluation order over them.

Objects may name an object as `parent`; cameras and lights may too, but nothing can be
parented to them. Scene validation already rejected unknown parents and cycles; this
module still refuses them, so a hand-built scene cannot loop forever.
"""

from __future__ import annotations

from typing import Mapping

from ..errors import MotionError


class ParentCycleError(MotionError):
    """The parent links form a cycle (normally caught by scene validation)."""


def evaluation_order(parents: Mapping[str, str | None]) -> list[str]:
    """Names ordered so every parent comes before its children (file order otherwise).

    >>> evaluation_order({"hand": "arm", "arm": "body", "body": None, "cup": None})
    ['body', 'arm', 'hand', 'cup']
    """
    order: list[str] = []
    state: dict[str, int] = {}  # 1: on the current chain, 2: done
    for start in parents:
        chain: list[str] = []
        node: str | None = start
        # walk up to the first ancestor already placed (or the root)
        while node is not None and state.get(node) != 2:
            if state.get(node) == 1:
                raise ParentCycleError("parent cycle: " + " -> ".join([*chain, node]))
            if node not in parents:
                raise MotionError(f"unknown parent '{node}' (parents are objects)")
            state[node] = 1
            chain.append(node)
            node = parents[node]
        for name in reversed(chain):
            state[name] = 2
            order.append(name)
    return order


def depth(parents: Mapping[str, str | None], name: str) -> int:
    """Number of ancestors of `name` (0 for a root)."""
    n = 0
    node = parents.get(name)
    while node is not None:
        n += 1
        node = parents.get(node)
    return n
