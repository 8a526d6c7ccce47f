"""Where a command writes a picture: a file name whose extension names a format matplotlib
writes (issue 34: ``lift_map --out x.jpgg`` wrote PNG data under that name).

The commands with an output picture (``lift_map``, ``scale_map``, ``csm_dependence``,
``bag plot``, ``sweep_plot``) read their ``--out``/``-o`` with :func:`picture_path`: the file's
extension decides the format (``.png``, ``.pdf``, ``.svg``, ``.jpg``, ...), and a name without
one, or with one matplotlib cannot write, is refused with the list of those it can. matplotlib
is imported only when such a name is read (its backend base, not pyplot).
"""

from __future__ import annotations

import argparse
from pathlib import Path

#: Formats matplotlib names but cannot write here without more software (pgf: LaTeX).
_NEEDS_MORE = frozenset({'pgf'})


def picture_formats() -> list[str]:
    """The file extensions (without the dot) matplotlib's Agg canvas writes, sorted."""
    from matplotlib.backend_bases import FigureCanvasBase  # noqa: PLC0415 - slow import

    return sorted(set(FigureCanvasBase.get_supported_filetypes()) - _NEEDS_MORE)


def picture_format(path: str | Path) -> str:
    """The format of the picture file ``path``: its extension, lower case, without the dot.

    Raises
    ------
    ValueError
        No extension, or one matplotlib cannot write (the message lists those it can).
    """
    suffix = Path(path).suffix.lower().lstrip('.')
    formats = picture_formats()
    if suffix in formats:
        return suffix
    what = f'extension .{suffix}' if suffix else 'no extension'
    raise ValueError(f'{str(path)!r} has {what}: a picture is written as one of '
                     f'{", ".join("." + f for f in formats)}')


def picture_path(text: str) -> Path:
    """An argparse ``type=``: a picture file name whose extension names its format.

    Raises
    ------
    argparse.ArgumentTypeError
        As :func:`picture_format` (argparse names the option and exits with status 2).
    """
    try:
        picture_format(text)
    except ValueError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None
    return Path(text)


picture_path.__name__ = 'picture file'
