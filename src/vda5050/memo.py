"""Values derived from immutable objects that are not hashable (pydantic models, dataclasses
holding sets), remembered by the object's identity.

The key is ``id(owner)`` and whatever hashable ``extra`` the derivation also depends on (or the
ids of two owner objects, :meth:`IdentityMemo.get_pair`); the owners themselves are kept with
the value, so that an id reused by a new object after the old one died never returns the old
value. When more than ``limit`` values are kept, all are forgotten
(the users derive a handful per fleet; the bound is against unbounded growth only).
"""

from __future__ import annotations

from collections.abc import Callable, Hashable
from typing import Generic, TypeVar

__all__ = ["IdentityMemo"]

V = TypeVar("V")


class IdentityMemo(Generic[V]):
    """``build()`` once per (owner object, extra), or per pair of owner objects."""

    def __init__(self, *, limit: int) -> None:
        self._limit = limit
        self._values: dict[Hashable, tuple[object, object, V]] = {}

    def get(self, owner: object, extra: Hashable, build: Callable[[], V]) -> V:
        """The value remembered for ``owner`` (this very object) and ``extra``, else
        ``build()``'s, remembered."""
        return self._get((id(owner), extra), owner, None, build)

    def get_pair(self, first: object, second: object, build: Callable[[], V]) -> V:
        """The value remembered for these two very objects together, else ``build()``'s."""
        return self._get((id(first), id(second)), first, second, build)

    def _get(self, key: Hashable, first: object, second: object, build: Callable[[], V]) -> V:
        known = self._values.get(key)
        if known is not None and known[0] is first and known[1] is second:
            return known[2]
        value = build()
        if len(self._values) >= self._limit:
            self._values.clear()
        self._values[key] = (first, second, value)
        return value
