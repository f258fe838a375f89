"""A progress bar for long runs (`plot`, `record`): on a terminal only, silent when piped."""

from __future__ import annotations

import sys
from collections.abc import Iterable, Iterator
from typing import TypeVar

from tqdm import tqdm

Item = TypeVar("Item")


def progress(items: Iterable[Item], total: int, label: str) -> Iterator[Item]:
    """`items` with a bar on stderr (scans done, rate, time left) when stderr is a terminal."""
    yield from tqdm(items, total=total, desc=label, unit="scan", file=sys.stderr, leave=False,
                    disable=not sys.stderr.isatty())
