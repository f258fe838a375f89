"""Values derived from a sensor's fixed beam arrays, kept while those arrays live.

A sensor passes the same read-only arrays (angles, origins, directions,
prepared solid hits) to every scan, and objects never move, so what follows
from them alone (a fan's plane and sorted angles, the surfaces in each beam's
footprint) is computed once. Arrays are recognised by identity, checked with
weak references, so a new array that reuses a dead one's id is never mistaken
for it; writeable arrays are never kept (their contents could change).
"""

from __future__ import annotations

import weakref
from typing import Callable, Hashable, TypeVar

import numpy as np

T = TypeVar("T")


class KeptPerArrays:
    """A bounded store of values keyed by the identity of some arrays (plus any hashable extra key)."""

    def __init__(self, size: int = 64) -> None:
        self._size = size
        self._kept: dict[tuple, tuple[tuple[weakref.ref, ...], object]] = {}

    def get(self, arrays: tuple[np.ndarray, ...], extra: Hashable, compute: Callable[[], T]) -> T:
        """The value kept for these arrays and `extra`, or `compute()` (kept if every array is read-only)."""
        key = (tuple(id(array) for array in arrays), extra)
        kept = self._kept.get(key)
        if kept is not None and all(ref() is array for ref, array in zip(kept[0], arrays)):
            return kept[1]  # type: ignore[return-value]
        value = compute()
        if not any(array.flags.writeable for array in arrays):
            if len(self._kept) >= self._size:
                self._kept.clear()
            self._kept[key] = (tuple(weakref.ref(array) for array in arrays), value)
        return value
