"""Text on rendered images (OpenCV's Hershey font: ASCII, with ``°`` and a few other symbols
spelled out): outlined labels readable on any background, and title bars above pictures made of
renders (the previews, the picker strips)."""

from __future__ import annotations

import cv2
import numpy as np

_FONT = cv2.FONT_HERSHEY_SIMPLEX
# Hershey fonts draw ASCII only: the few other symbols the project's labels use, spelled out.
_SPELLED = str.maketrans({"°": " deg", "×": "x", "–": "-", "—": "-", "θ": "theta"})


def _ascii(text: str) -> str:
    return text.translate(_SPELLED).encode("ascii", "replace").decode("ascii")


def _thickness(scale: float) -> int:
    """Stroke width (px) for a font ``scale``: about a tenth of the letters' height."""
    return max(1, round(2 * scale))


def put_text(image: np.ndarray, text: str, origin: tuple[int, int], scale: float,
             colour: tuple[int, int, int] = (255, 255, 255), outline: bool = True) -> None:
    """Draw ``text`` into ``image`` (H, W, 3) uint8 in place, its baseline starting at ``origin``
    (x, y pixels), ``colour`` with a black ``outline`` (readable on soil and on white caps alike;
    not needed on a plain banner)."""
    text, thick = _ascii(text), _thickness(scale)
    if outline:
        cv2.putText(image, text, origin, _FONT, scale, (0, 0, 0), thick + 2, cv2.LINE_AA)
    cv2.putText(image, text, origin, _FONT, scale, colour, thick, cv2.LINE_AA)


def with_title(image: np.ndarray, title: str, scale: float | None = None) -> np.ndarray:
    """``image`` (H, W, 3) uint8 below a white bar holding ``title`` in black, as a new
    (H + bar, W, 3) array; ``scale`` (OpenCV font scale) defaults to one that fits a 480-pixel
    render (0.7), shrunk until the title fits the width. The bar's height depends on ``scale``
    alone, so that pictures titled side by side stay the same height."""
    width, title = image.shape[1], _ascii(title)
    scale = 0.7 if scale is None else scale
    (_, line_h), baseline = cv2.getTextSize("Ag", _FONT, scale, _thickness(scale))
    while cv2.getTextSize(title, _FONT, scale, _thickness(scale))[0][0] > width - 16 and scale > 0.3:
        scale *= 0.9
    bar = np.full((line_h + baseline + 16, width, 3), 255, np.uint8)
    cv2.putText(bar, title, (8, 8 + line_h), _FONT, scale, (0, 0, 0), _thickness(scale), cv2.LINE_AA)
    return np.concatenate([bar, image], axis=0)
