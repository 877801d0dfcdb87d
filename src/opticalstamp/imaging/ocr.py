"""Optical character recognition of scans (Tesseract through pytesseract) and the
character error rate against a ground truth."""

from __future__ import annotations

import re
import shutil

import numpy as np


class OCRUnavailable(RuntimeError):
    pass


def tesseract_available() -> bool:
    return shutil.which("tesseract") is not None


def require_tesseract() -> None:
    """Raise :class:`OCRUnavailable` (with how to install it) if Tesseract is missing."""
    if not tesseract_available():
        raise OCRUnavailable("tesseract is not installed (Debian: apt-get install tesseract-ocr)")


def recognise(image: np.ndarray, dpi: float, psm: int = 6) -> str:
    """Text in an 8-bit-ready grey image in [0, 1] (display-encoded), via Tesseract."""
    require_tesseract()
    import pytesseract
    from PIL import Image

    im = Image.fromarray(np.round(np.clip(image, 0, 1) * 255).astype(np.uint8))
    return pytesseract.image_to_string(im, config=f"--psm {psm} --dpi {int(round(dpi))}")


def normalise(text: str) -> str:
    return re.sub(r"\s+", " ", text).strip()


def edit_distance(a: str, b: str) -> int:
    """Levenshtein distance (insertions, deletions, substitutions), O(len a * len b)."""
    if len(a) < len(b):
        a, b = b, a
    prev = np.arange(len(b) + 1)
    bb = np.frombuffer(b.encode("utf-32-le"), dtype=np.uint32) if b else np.zeros(0, np.uint32)
    for i, ca in enumerate(a, 1):
        sub = prev[:-1] + (bb != ord(ca))
        cur = np.empty_like(prev)
        cur[0] = i
        cur[1:] = np.minimum(prev[1:] + 1, sub)
        # insertions run along the row: a cumulative minimum of (cur[j] - j) + j
        cur = np.minimum.accumulate(cur - np.arange(cur.size)) + np.arange(cur.size)
        prev = cur
    return int(prev[-1])


def character_error_rate(truth: str, text: str) -> float:
    """Edit distance over the length of the (whitespace-normalised) ground truth."""
    t, o = normalise(truth), normalise(text)
    return edit_distance(t, o) / max(len(t), 1)
