"""argparse value types shared by the ``sms3d`` subcommands: a bad value is a usage error (exit
code 2, the flag named, no traceback) before any work is done or any folder is made."""

from __future__ import annotations

import argparse

from generator.config import require_image_side
from generator.errors import ConfigError


def output_path(text: str) -> str:
    """A file or folder to write: not empty (``""`` would mean the current folder)."""
    if not text.strip():
        raise argparse.ArgumentTypeError("must not be empty")
    return text


def image_side(text: str) -> int:
    """An image width or height in pixels, within ``generator.config``'s limits."""
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected an integer, got {text!r}") from None
    try:
        return require_image_side("size", value)
    except ConfigError as exc:
        raise argparse.ArgumentTypeError(exc.message) from None
