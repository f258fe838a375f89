"""Writing a figure to the file a user named, in the format its suffix names.

Every format matplotlib writes works (png, svg, pdf, jpg, webp, ...); any other
suffix is a one-line UserError before anything is computed. The figure is
written to a new file beside the target and renamed over it once complete, so
a failed write never leaves a broken file (nor touches one already there).
"""

from __future__ import annotations

import contextlib
import os
from pathlib import Path
from typing import Any

from emulator.errors import UserError

DEFAULT_FORMAT = "png"
# No version or date stamps: the same figure gives the same bytes.
REPRODUCIBLE_METADATA: dict[str, dict[str, None]] = {
    "png": {"Software": None},
    "svg": {"Date": None},
    "svgz": {"Date": None},
    "pdf": {"CreationDate": None},
}


def supported_formats() -> list[str]:
    """The file formats matplotlib can write here (its own names: the suffixes)."""
    from matplotlib.backend_bases import FigureCanvasBase

    return sorted(FigureCanvasBase.get_supported_filetypes())


def output_format(out: Path) -> str:
    """The format `out`'s suffix names (png without one), or a UserError naming those there are."""
    suffix = out.suffix[1:].lower()
    if not suffix:
        return DEFAULT_FORMAT
    formats = supported_formats()
    if suffix not in formats:
        raise UserError(f"--out {out}: cannot write .{suffix} files (known: {', '.join(formats)})")
    return suffix


def save_figure(figure: Any, out: Path, **savefig: Any) -> None:
    """`figure.savefig` into `out` in its suffix's format, whole or not at all."""
    out = Path(out)
    fmt = output_format(out)
    partial = out.with_name(f".{out.name}.{os.getpid()}.part")
    try:
        descriptor = os.open(partial, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o666)
    except OSError as error:
        raise UserError(f"cannot write {out}: {error.strerror or error}") from None
    try:
        with os.fdopen(descriptor, "wb") as file:
            metadata = {"metadata": REPRODUCIBLE_METADATA[fmt]} if fmt in REPRODUCIBLE_METADATA else {}
            figure.savefig(file, format=fmt, **metadata, **savefig)
        os.replace(partial, out)
    except OSError as error:
        raise UserError(f"cannot write {out}: {error.strerror or error}") from None
    except (RuntimeError, ValueError) as error:  # e.g. pgf without a LaTeX installation
        raise UserError(f"cannot write {out} as {fmt}: {str(error).splitlines()[0] if str(error) else error}") from None
    finally:
        with contextlib.suppress(FileNotFoundError):
            os.unlink(partial)
