"""A small persistent map: updates copy only the buckets they touch.

Traffic state is immutable, yet one release touches a handful of resources in a table that holds
the whole fleet's reservations. Copying a dict per call would be O(fleet); this map keeps 256
buckets, so an update of k keys copies at most k small buckets and one 256-slot tuple (the idea
of :class:`vda_master.fleet.FleetView`, generalised).
"""

from __future__ import annotations

from collections.abc import Hashable, Iterable, Iterator
from typing import Final, Generic, TypeVar

_BUCKETS: Final = 256
K = TypeVar("K", bound=Hashable)
V = TypeVar("V")


class PMap(Generic[K, V]):
    """An immutable mapping whose updates share structure with the original."""

    __slots__ = ("_buckets", "_size")

    def __init__(self, buckets: tuple[dict[K, V], ...] | None = None, size: int = 0) -> None:
        # Buckets are never mutated once a map holds them.
        self._buckets: tuple[dict[K, V], ...] = buckets if buckets is not None else ({},) * _BUCKETS
        self._size = size

    def get(self, key: K) -> V | None:
        """The value of ``key``, or None."""
        return self._buckets[hash(key) % _BUCKETS].get(key)

    def values_of(self, keys: Iterable[K]) -> list[V]:
        """The values of those of ``keys`` that are present, in the keys' order."""
        buckets = self._buckets
        return [v for k in keys if (v := buckets[hash(k) % _BUCKETS].get(k)) is not None]

    def __contains__(self, key: object) -> bool:
        return key in self._buckets[hash(key) % _BUCKETS]

    def __len__(self) -> int:
        return self._size

    def __iter__(self) -> Iterator[K]:
        for bucket in self._buckets:
            yield from bucket

    def items(self) -> Iterator[tuple[K, V]]:
        """Every key and value, in no particular order."""
        for bucket in self._buckets:
            yield from bucket.items()

    def update(self, put: Iterable[tuple[K, V]] = (), remove: Iterable[K] = ()) -> PMap[K, V]:
        """A new map with ``remove`` deleted (missing keys ignored), then ``put`` set."""
        changed: dict[int, dict[K, V]] = {}
        size = self._size
        for key in remove:
            index = hash(key) % _BUCKETS
            bucket = changed.get(index)
            if bucket is None:
                bucket = changed[index] = dict(self._buckets[index])
            if bucket.pop(key, _MISSING) is not _MISSING:
                size -= 1
        for key, value in put:
            index = hash(key) % _BUCKETS
            bucket = changed.get(index)
            if bucket is None:
                bucket = changed[index] = dict(self._buckets[index])
            size += key not in bucket
            bucket[key] = value
        if not changed:
            return self
        buckets = list(self._buckets)
        for index, bucket in changed.items():
            buckets[index] = bucket
        return PMap(tuple(buckets), size)

    def set(self, key: K, value: V) -> PMap[K, V]:
        """A new map with ``key`` set to ``value``."""
        return self.update(put=((key, value),))

    def remove(self, key: K) -> PMap[K, V]:
        """A new map without ``key`` (unchanged if absent)."""
        return self.update(remove=(key,)) if key in self else self


_MISSING: Final = object()
