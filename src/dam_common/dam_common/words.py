"""Counts in the suite's printed lines: "1 trial", "2 trials", never "1 trials".

Pure Python; every command line that prints a count with its noun uses :func:`counted`.
"""

from __future__ import annotations

#: Names that stay as they are (a symbol counted: "3 k_theta").
_IRREGULAR = {'k_theta': 'k_theta', 'delta_theta_p': 'delta_theta_p'}


def counted(count: int, noun: str, plural: str | None = None, *, spec: str = '') -> str:
    """``count`` and ``noun``, the noun in the plural unless the count is one.

    Parameters
    ----------
    count : how many.
    noun : the singular ("trial", "friction angle").
    plural : the plural when it is not ``noun + 's'`` ("repeats" of "repeat" is regular;
        "bodies" of "body" is not).
    spec : a format spec for the number (``','``: thousands separated).

    Returns
    -------
    str
        ``'1 trial'``, ``'2 trials'``, ``'1,024 messages'``.
    """
    many = plural if plural is not None else _IRREGULAR.get(noun, noun + 's')
    return f'{count:{spec}} {noun if count == 1 else many}'
