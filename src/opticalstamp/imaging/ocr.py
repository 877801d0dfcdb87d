"""Optical character recognition of scans (the Tesseract program) and the character error
rate against a ground truth."""

from __future__ import annotations

import os
import re
import shutil
import subprocess
import tempfile

import numpy as np


class OCRUnavailable(RuntimeError):
    pass


class TesseractError(RuntimeError):
    """Tesseract ran and failed: its exit status and what it wrote to stderr."""

    def __init__(self, status: int, message: str) -> None:
        super().__init__(status, message)
        self.status = status
        self.message = message


def tesseract_available() -> bool:
    return shutil.which("tesseract") is not None


def require_tesseract() -> None:
    """Raise :class:`OCRUnavailable` (with how to install it) if Tesseract is missing."""
    if not tesseract_available():
        raise OCRUnavailable("tesseract is not installed (Debian: apt-get install tesseract-ocr)")


def recognise(image: np.ndarray, dpi: float, psm: int = 6) -> str:
    """Text in an 8-bit-ready grey image in [0, 1] (display-encoded), via Tesseract.

    Tesseract runs as a program on a PNG of the image (what pytesseract's
    ``image_to_string`` does, with the same arguments and output), with one OpenMP thread:
    its child environment gets ``OMP_THREAD_LIMIT=1`` (this process's is not changed). More
    threads do not change the text, only cost CPU time the rest of a report can use.
    """
    require_tesseract()
    from PIL import Image

    im = Image.fromarray(np.round(np.clip(image, 0, 1) * 255).astype(np.uint8))
    cmd = shutil.which("tesseract")
    env = {**os.environ, "OMP_THREAD_LIMIT": "1"}
    with tempfile.TemporaryDirectory(prefix="tess_") as tmp:
        src = os.path.join(tmp, "input.PNG")
        base = os.path.join(tmp, "output")
        im.save(src, format="PNG")
        args = [cmd, src, base, "--psm", str(psm), "--dpi", str(int(round(dpi))), "txt"]
        try:
            proc = subprocess.run(
                args, env=env, stdin=subprocess.DEVNULL, capture_output=True, check=False
            )
        except FileNotFoundError as e:  # removed since the check above
            raise OCRUnavailable(f"tesseract could not be run: {e}") from e
        if proc.returncode:
            msg = " ".join(proc.stderr.decode("utf-8", "replace").splitlines()).strip()
            raise TesseractError(proc.returncode, msg)
        with open(base + ".txt", "rb") as f:
            return f.read().decode("utf-8")


def recognise_all(
    items: list[tuple[np.ndarray, float]], psm: int = 6, workers: int | None = None
) -> list[str]:
    """:func:`recognise` of each (image, dpi), in that order, with up to ``workers``
    Tesseract processes at once (default: one per core): each is a program of its own, so
    the threads here only wait for them. Raises as :func:`recognise` (the first error)."""
    from concurrent.futures import ThreadPoolExecutor

    if not items:
        return []
    require_tesseract()
    n = max(1, min(len(items), workers or os.cpu_count() or 1))
    with ThreadPoolExecutor(n) as pool:
        return list(pool.map(lambda item: recognise(item[0], item[1], psm), items))


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
