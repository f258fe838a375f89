"""Values derived from a sensor's fixed beam arrays, kept while those arrays live.

A sensor passes the same read-only arrays (angles, origins, directions,
prepared solid hits) to every scan, and objects never move, so what follows
from them alone (a fan's plane and sorted angles, the surfaces in each beam's
footprint) is computed once. Arrays are recognised by identity, checked with
weak references, so a new array that reuses a dead one's id is never mistaken
for it; writeable arrays are never kept (their contents could change).

A store keeps a value for every sensor of a fleet-sized scene (a few per
sensor, up to the scene's 256 sensors): a worker computes every sensor in
turn, so a store smaller than the fleet lost each value before its sensor
came round again (at 140 URG-04LX under `physical`, a third of a worker's
time went into recomputing them).
"""

from __future__ import annotations

import weakref
from typing import Callable, Hashable, TypeVar

import numpy as np

T = TypeVar("T")


# Values a store keeps: a few per sensor of the largest scene (256 sensors; a URG-04LX's
# values are ≈ 0.3 MB for all stores together).
KEPT_VALUES = 1024


class KeptPerArrays:
    """A bounded store of values keyed by the identity of some arrays (plus any hashable extra key);
    when full, the value stored longest ago goes."""

    def __init__(self, size: int = KEPT_VALUES) -> None:
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
                del self._kept[next(iter(self._kept))]
            self._kept[key] = (tuple(weakref.ref(array, self._forgetter(key)) for array in arrays), value)
        return value

    def __len__(self) -> int:
        return len(self._kept)

    def _forgetter(self, key: tuple) -> Callable[[weakref.ref], None]:
        """Drops the value kept under `key` once one of its arrays dies (a sensor that casts new beams
        every scan, on a moving body, would otherwise fill the store with values nobody asks for)."""

        def forget(dead: weakref.ref) -> None:
            kept = self._kept.get(key)
            if kept is not None and any(ref is dead for ref in kept[0]):
                del self._kept[key]

        return forget
