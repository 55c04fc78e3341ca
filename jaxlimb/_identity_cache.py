"""A small cache keyed by the identity of objects (meshes, template databases, masks)."""

from __future__ import annotations

from typing import Any, Callable, Hashable


class IdentityCache:
    """Values computed from objects that are not hashed (NumPy arrays, meshes), kept for the same objects.

    An entry is keyed by the objects' ``id`` and an optional hashable ``extra``, and holds the objects themselves,
    so their ids cannot be reused by other objects while it is cached; a hit also checks identity.  The cache is
    cleared when it holds ``maxsize`` entries (the callers ask for the last few objects over and over).
    """

    def __init__(self, maxsize: int = 8) -> None:
        self.maxsize = maxsize
        self._entries: dict = {}

    def get(self, objs: tuple, make: Callable[[], Any], extra: Hashable = None) -> Any:
        """The value for ``objs`` (and ``extra``), computed by ``make()`` on a miss."""
        key = (tuple(id(o) for o in objs), extra)
        hit = self._entries.get(key)
        if hit is None or any(a is not b for a, b in zip(hit[0], objs)):
            if len(self._entries) >= self.maxsize:
                self._entries.clear()
            hit = self._entries[key] = (objs, make())
        return hit[1]

    def clear(self) -> None:
        self._entries.clear()
