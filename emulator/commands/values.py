"""argparse types light enough for `ctl` (here, not in options.py, which loads the simulation)."""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Callable


def whole_number(minimum: int) -> Callable[[str], int]:
    """An argparse type: a whole number of at least `minimum` (its error names both)."""

    def parse(text: str) -> int:
        try:
            value = int(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected a whole number, got {text!r}") from None
        if value < minimum:
            raise argparse.ArgumentTypeError(f"must be a whole number >= {minimum}, got {text!r}")
        return value

    parse.__name__ = f"whole number >= {minimum}"  # argparse names the type in some errors
    return parse


def bearer_token(text: str) -> str:
    """An argparse type: a token an HTTP Authorization header can carry (visible ASCII, no spaces). A
    blank one is passed on for the caller to refuse in its own words (serve: "an empty one")."""
    if text.strip() and not all("!" <= character <= "~" for character in text):
        raise argparse.ArgumentTypeError(
            f"expected visible ASCII characters without spaces (an HTTP header carries no other), got {text!r}"
        )
    return text


def named_path(text: str) -> Path:
    """An argparse type: a file named (Path('') is '.', the working directory; a FIFO is let through:
    `--events-in <(zcat log.gz)`, `--events >(jq ...)`)."""
    if not text.strip():
        raise argparse.ArgumentTypeError(f"expected a file name, got {text!r}")
    return Path(text)
