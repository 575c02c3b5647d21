"""Values derived from immutable objects that are not hashable (pydantic models, dataclasses
holding sets), remembered by the object's identity.

The key is ``id(owner)`` and whatever hashable ``extra`` the derivation also depends on; the
owner itself is kept with the value, so that an id reused by a new object after the old one
died never returns the old value. When more than ``limit`` values are kept, all are forgotten
(the users derive a handful per fleet; the bound is against unbounded growth only).
"""

from __future__ import annotations

from collections.abc import Callable, Hashable
from typing import Generic, TypeVar

__all__ = ["IdentityMemo"]

V = TypeVar("V")


class IdentityMemo(Generic[V]):
    """``build()`` once per (owner object, extra)."""

    def __init__(self, *, limit: int) -> None:
        self._limit = limit
        self._values: dict[tuple[int, Hashable], tuple[object, V]] = {}

    def get(self, owner: object, extra: Hashable, build: Callable[[], V]) -> V:
        """The value remembered for ``owner`` (this very object) and ``extra``, else
        ``build()``'s, remembered."""
        key = (id(owner), extra)
        known = self._values.get(key)
        if known is not None and known[0] is owner:
            return known[1]
        value = build()
        if len(self._values) >= self._limit:
            self._values.clear()
        self._values[key] = (owner, value)
        return value
