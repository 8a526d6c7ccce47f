"""What an error message may quote of a value it received: at most a few hundred characters.

A request, goal, command or parameter is answered, logged and published on ``/rosout``
with the value that made it wrong. A value of a million numbers (or a name of a million
characters) must not become a reply, a log line and a ``/rosout`` message of megabytes: every
message that quotes a value received from outside quotes :func:`brief_repr` of it, which is
``repr()`` up to :data:`ECHO_LIMIT` characters, then ``...`` and how long the whole is. Text
that may already hold such a value (an exception's message) goes through :func:`brief_text`.

Neither computes the ``repr()`` of the whole of a long string, list, tuple, ``array.array``
or numpy array: only of its first :data:`ECHO_LIMIT` items. Pure Python (no numpy import).
"""

from __future__ import annotations

import array

#: Longest quote of one value [characters], before the ``...`` and the length.
ECHO_LIMIT = 200
#: Longest reason or message made of quotes and words [characters] (:func:`brief_text`).
TEXT_LIMIT = 2000


def _head_and_count(value: object, limit: int) -> tuple[object, int | None, str]:
    """The part of ``value`` whose ``repr()`` is enough, its whole length and the unit
    (``None`` when the value is not a sequence cut here)."""
    if isinstance(value, str):
        return (value[:limit], len(value), 'characters') if len(value) > limit \
            else (value, None, '')
    if isinstance(value, (bytes, bytearray)):
        return (value[:limit], len(value), 'bytes') if len(value) > limit \
            else (value, None, '')
    if isinstance(value, array.array):
        head = value[:limit].tolist()  # quoted as the list of its numbers
        return head, (len(value) if len(value) > limit else None), 'values'
    if isinstance(value, (list, tuple)):
        return (value[:limit], len(value), 'values') if len(value) > limit \
            else (value, None, '')
    ndim = getattr(value, 'ndim', None)
    if isinstance(ndim, int) and ndim >= 1 and callable(getattr(value, 'tolist', None)):
        size = int(getattr(value, 'size', len(value)))  # numpy: quoted as its list
        return value[:limit].tolist(), (size if size > limit else None), 'values'
    return value, None, ''


def brief_repr(value: object, limit: int = ECHO_LIMIT) -> str:
    """``repr(value)`` of at most about ``limit`` characters.

    Parameters
    ----------
    value
        Anything; a numpy or ``array.array`` array is quoted as the list of its numbers (what
        ``arr.tolist()!r`` gives), so that a short one reads as before.
    limit
        Longest quote kept [characters].

    Returns
    -------
    str
        The whole ``repr()`` when it is at most ``limit`` long; else its first ``limit``
        characters, ``...`` and the length of the whole, e.g.
        ``[1.0, 1.0, 1.0... (1000000 values)`` or ``'xxxx... (70000 characters)``.
    """
    head, count, unit = _head_and_count(value, limit)
    text = repr(head)
    if count is None and len(text) <= limit:
        return text
    if count is None:
        count, unit = len(text), 'characters'
    return f'{text[:limit]}... ({count} {unit})'


def brief_text(text: str, limit: int = TEXT_LIMIT) -> str:
    """``text`` (a reason, an exception's message) cut to ``limit`` characters, then ``...``
    and its whole length."""
    text = str(text)
    if len(text) <= limit:
        return text
    return f'{text[:limit]}... ({len(text)} characters)'
