"""How a message quotes what a file holds: at most :data:`QUOTE_CHARS` characters of it, so that
a refusal of a crafted file (a megabyte-long env id, an error that repeats its input) stays one
short line instead of repeating the file."""

from __future__ import annotations

#: The longest text of a file's value or of a library's error quoted in a message.
QUOTE_CHARS = 200


def clipped(text: str) -> str:
    """``text`` cut to :data:`QUOTE_CHARS` characters, saying how long it was."""
    return text if len(text) <= QUOTE_CHARS else f"{text[:QUOTE_CHARS]}... ({len(text)} characters)"


def described_error(exc: BaseException) -> str:
    """``"KeyError: 'x'"``: an exception's type and text, :func:`clipped`."""
    return clipped(f"{type(exc).__name__}: {exc}")
