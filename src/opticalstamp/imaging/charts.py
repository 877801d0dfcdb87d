"""Built-in test documents (linear reflectance in [0, 1], arrays [row = y, col = x]).

- ``bars``: blocks of vertical bars (varying along x) at the paper's 100, 150, 200 and
  247 dpi (periods 508, 339, 254, 206 um; paper Fig. 11, 12), any list accepted;
- ``edge``: a dark square tilted by 5 degrees (slanted-edge SFR, ISO 12233);
- ``text``: 8-pt text (paper Fig. 8) with its ground-truth string; any size, in a sans
  (Pillow's built-in font) or a serif face (DejaVu Serif, shipped with matplotlib);
- ``lines``: fine line work, a guilloche rosette with micro-lines (a paper-currency-like
  pattern, paper Fig. 9 analogue).
Charts are drawn by exact area coverage (supersampling), at ``dpi`` (default 1200).
"""

from __future__ import annotations

import math

import numpy as np

from ..units import mm_to_um, period_of_dpi, pitch_of_dpi

KINDS = ("bars", "edge", "text", "lines")
#: Type faces of :func:`text_chart`.
FACES = ("sans", "serif")
#: The serif face: a TrueType file that matplotlib (a dependency) ships in mpl-data.
SERIF_FILE = "DejaVuSerif.ttf"

TEXT = (
    "The lensless image scanner keeps a document sharp",
    "up to 3.5 mm above the glass without any lens.",
    "Three aperture layers stop the oblique rays,",
    "so that each pixel sees only a small spot.",
    "Quick brown foxes jump over 12 lazy dogs: 0123456789",
)


def _px(dpi: float) -> float:
    if not 10 <= dpi <= 10_000:
        raise ValueError(f"dpi must lie in [10, 10000] (got {dpi})")
    return pitch_of_dpi(dpi)


#: The bar chart's blocks by default (chart resolutions, dpi): the paper's Fig. 11 charts.
BAR_BLOCKS_DPI = (100.0, 150.0, 200.0, 247.0)


def bar_chart(
    dpi: float = 1200.0,
    chart_dpi=BAR_BLOCKS_DPI,
    block_mm: float = 6.0,
    gap_mm: float = 2.0,
    height_mm: float = 8.0,
    margin_mm: float = 2.0,
    shift_um: float = 0.0,
    supersample: int = 8,
) -> np.ndarray:
    """Blocks of black (0) and white (1) bars of equal width, one block per chart dpi."""
    px = _px(dpi)
    periods = [period_of_dpi(d) for d in chart_dpi]
    width = 2 * margin_mm + len(periods) * block_mm + (len(periods) - 1) * gap_mm
    nx = int(round(width * 1000 / px))
    ny = int(round((height_mm + 2 * margin_mm) * 1000 / px))
    xs = (np.arange(nx * supersample) + 0.5) / supersample * px
    row = np.ones(xs.size)
    x0 = margin_mm * 1000
    for p in periods:
        sel = (xs >= x0) & (xs < x0 + block_mm * 1000)
        row[sel] = ((xs[sel] - x0 - shift_um) % p) >= p / 2  # starts with a black bar
        x0 += (block_mm + gap_mm) * 1000
    row = row.reshape(nx, supersample).mean(axis=1)
    img = np.ones((ny, nx))
    m = int(round(margin_mm * 1000 / px))
    img[m : ny - m] = row
    return img


def edge_chart(
    dpi: float = 1200.0, size_mm: float = 10.0, angle_deg: float = 5.0, supersample: int = 4
) -> np.ndarray:
    """A black square (half the field) tilted by ``angle_deg`` on white."""
    px = _px(dpi)
    n = int(round(size_mm * 1000 / px))
    f = (np.arange(n * supersample) + 0.5) / supersample - n / 2
    yy, xx = np.meshgrid(f, f, indexing="ij")
    a = np.radians(angle_deg)
    u = xx * np.cos(a) + yy * np.sin(a)
    v = -xx * np.sin(a) + yy * np.cos(a)
    inside = (np.abs(u) < n / 4) & (np.abs(v) < n / 4)
    img = 1.0 - inside.reshape(n, supersample, n, supersample).mean(axis=(1, 3))
    return img


class FontUnavailable(RuntimeError):
    """The serif face's TrueType file is not where matplotlib ships it."""


def serif_font_path() -> str:
    """The path of DejaVu Serif in matplotlib's ``mpl-data/fonts/ttf`` folder.

    Found from the installed package's location, without importing matplotlib (only the
    plotting code may; tests/test_architecture.py); no system font folder is used, so the
    face is the same on every machine that has the project's dependencies.
    """
    import importlib.util
    import os

    spec = importlib.util.find_spec("matplotlib")
    for root in (spec.submodule_search_locations or []) if spec is not None else []:
        path = os.path.join(root, "mpl-data", "fonts", "ttf", SERIF_FILE)
        if os.path.isfile(path):
            return path
    raise FontUnavailable(
        f"the serif face needs {SERIF_FILE}, which matplotlib ships in mpl-data/fonts/ttf; "
        "it was not found (reinstall matplotlib: pip install --force-reinstall matplotlib)"
    )


def text_chart(
    dpi: float = 1200.0,
    points: float = 8.0,
    lines=TEXT,
    margin_mm: float = 2.0,
    face: str = "sans",
) -> tuple[np.ndarray, str]:
    """Text of ``points`` points (8 pt: paper Fig. 8) and its ground truth.

    ``face``: ``sans``, Pillow's built-in scalable font (Aileron), or ``serif``, DejaVu Serif
    from matplotlib's fonts (:func:`serif_font_path`; :class:`FontUnavailable` if absent).
    The font size is the em of ``points`` at ``dpi`` (at least 6 pixels).
    """
    from PIL import Image, ImageDraw, ImageFont

    _px(dpi)
    if face not in FACES:
        raise ValueError(f"face must be one of {', '.join(FACES)} (got {face!r})")
    if not (math.isfinite(points) and 1 <= points <= 72):
        raise ValueError(f"points must lie in [1, 72] (got {points})")
    size = max(6, int(round(points / 72 * dpi)))
    if face == "sans":
        font = ImageFont.load_default(size=size)
    else:
        font = ImageFont.truetype(serif_font_path(), size)
    line_h = int(size * 1.35)
    m = int(round(mm_to_um(margin_mm) / pitch_of_dpi(dpi)))
    width = max(int(font.getlength(t)) for t in lines) + 2 * m
    height = line_h * len(lines) + 2 * m
    im = Image.new("L", (width, height), 255)
    draw = ImageDraw.Draw(im)
    for i, t in enumerate(lines):
        draw.text((m, m + i * line_h), t, fill=0, font=font)
    return np.asarray(im, dtype=np.float64) / 255.0, "\n".join(lines)


def line_chart(
    dpi: float = 1200.0,
    size_mm: float = 16.0,
    line_um: float = 50.0,
    n_curves: int = 8,
    supersample: int = 2,
) -> np.ndarray:
    """Guilloche rosette of thin lines (width ``line_um``) inside a frame, with a band of
    micro-lines at 150-300 um pitch: fine line work like a banknote (paper Fig. 9)."""
    px = _px(dpi)
    n = int(round(size_mm * 1000 / px))
    f = ((np.arange(n * supersample) + 0.5) / supersample - n / 2) * px  # um
    yy, xx = np.meshgrid(f, f, indexing="ij")
    r = np.hypot(xx, yy)
    th = np.arctan2(yy, xx)
    ink = np.zeros(r.shape, bool)
    r0 = size_mm * 1000 * 0.28
    for k in range(n_curves):
        rc = r0 * (1 + 0.3 * np.sin(5 * th + 2 * np.pi * k / n_curves))
        ink |= np.abs(r - rc) < line_um / 2
    band = (np.abs(yy) > size_mm * 1000 * 0.38) & (np.abs(yy) < size_mm * 1000 * 0.46)
    pitch = 150 + 150 * (xx - f[0]) / (f[-1] - f[0])  # 150 -> 300 um across
    ink |= band & ((xx % pitch) < line_um)
    frame = np.maximum(np.abs(xx), np.abs(yy))
    ink |= np.abs(frame - size_mm * 1000 * 0.48) < line_um
    img = 1.0 - ink.reshape(n, supersample, n, supersample).mean(axis=(1, 3))
    return img


def make_chart(
    kind: str,
    dpi: float = 1200.0,
    points: float = 8.0,
    face: str = "sans",
    blocks: tuple[float, ...] = BAR_BLOCKS_DPI,
) -> tuple[np.ndarray, str | None]:
    """A chart by name, with the ground-truth text for ``text`` (of ``points`` in ``face``);
    the bar chart has one block for each chart resolution of ``blocks`` (dpi)."""
    if kind == "bars":
        return bar_chart(dpi, chart_dpi=tuple(blocks)), None
    if kind == "edge":
        return edge_chart(dpi), None
    if kind == "text":
        return text_chart(dpi, points, face=face)
    if kind == "lines":
        return line_chart(dpi), None
    raise ValueError(f"chart kind must be one of {', '.join(KINDS)} (got {kind!r})")


def clear_crop(doc: np.ndarray, factor: float, rows: slice, cols: slice, white: float = 0.98):
    """A crop of a scan of ``doc`` that cuts no letter: the scan-pixel slices ``rows`` and
    ``cols`` widened outward to the nearest rows (within the columns asked for) and then
    columns (within those rows) where the document is blank (every document pixel there
    over ``white``). ``factor``: document pixels per scan pixel (1200 / 300 = 4 for the
    report's scans); ``doc`` (ny, nx) in [0, 1], white = 1. Returns (rows, cols) slices
    in scan pixels."""
    dark = doc < white

    def edges(n_doc: int) -> np.ndarray:
        return np.floor(np.arange(int(n_doc / factor) + 1) * factor).astype(int)

    def to_doc(s: slice) -> slice:
        return slice(int(s.start * factor), int(np.ceil(s.stop * factor)))

    def blank(ink: np.ndarray) -> np.ndarray:  # ink per document row or column
        e = edges(ink.size)
        return np.array([not ink[a:b].any() for a, b in zip(e[:-1], e[1:], strict=True)])

    def widen(s: slice, free: np.ndarray) -> slice:
        a, b = max(s.start or 0, 0), min(s.stop if s.stop is not None else free.size, free.size)
        while a > 0 and not free[a]:
            a -= 1
        while b < free.size and not free[b - 1]:
            b += 1
        return slice(a, b)

    rows = widen(rows, blank(dark[:, to_doc(cols)].any(axis=1)))
    cols = widen(cols, blank(dark[to_doc(rows), :].any(axis=0)))
    return rows, cols
