"""Small Monte Carlo helpers shared by the tests (independent of opticalstamp.raytrace.tally),
and a runner of Python code in a process of its own."""

from __future__ import annotations

import copy
import math
import os
import subprocess
import sys
import tomllib
from dataclasses import dataclass
from importlib import resources
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]


def source_env(**env) -> dict:
    """This process's environment with the repository's sources first on PYTHONPATH
    (what was there stays behind them: packages installed beside the interpreter's, as on
    a GPU machine) and ``env`` added."""
    path = os.pathsep.join(p for p in (str(ROOT / "src"), os.environ.get("PYTHONPATH")) if p)
    return os.environ | {"PYTHONPATH": path} | env


def run_python(code: str, **env) -> subprocess.CompletedProcess:
    """``python -c code`` from the repository's root with its sources on the path and
    ``env`` added to the environment (a process of its own: another device, other
    threads, a fresh import)."""
    e = source_env(**env)
    return subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, env=e, cwd=ROOT, timeout=600
    )


@dataclass
class Tally:
    """Running sums of weights for an estimate sum(w) / n_samples and its standard error."""

    s1: float = 0.0
    s2: float = 0.0
    n: int = 0

    def add(self, w: np.ndarray, n_samples: int) -> None:
        w = np.asarray(w, dtype=np.float64)
        self.s1 += float(w.sum())
        self.s2 += float((w * w).sum())
        self.n += int(n_samples)

    @property
    def value(self) -> float:
        return self.s1 / self.n

    @property
    def se(self) -> float:
        mean = self.value
        return math.sqrt(max(self.s2 / self.n - mean * mean, 0.0) / self.n)


def assert_agree(a: float, sa: float, b: float, sb: float, k: float = 4.0) -> None:
    """|a - b| within k combined standard errors."""
    tol = k * math.hypot(sa, sb)
    assert abs(a - b) <= tol, (
        f"{a} +- {sa} vs {b} +- {sb}: differ by {abs(a - b) / math.hypot(sa, sb):.2f} SE"
    )


def preset_dict(name: str) -> dict:
    """A fresh, mutable copy of a preset as read from its TOML file."""
    text = (resources.files("opticalstamp.design") / "presets" / f"{name}.toml").read_text()
    return copy.deepcopy(tomllib.loads(text))


# -- view factor between parallel rectangles ----------------------------------------------
def _corner(x: float, y: float, c: float) -> float:
    a = math.hypot(x, c)
    b = math.hypot(y, c)
    return (
        y * a * math.atan2(y, a)
        + x * b * math.atan2(x, b)
        - 0.5 * c * c * math.log(x * x + y * y + c * c)
    )


def parallel_rectangles_etendue(r1, r2, c: float) -> float:
    """Etendue (um^2 sr, index 1) between parallel rectangles a distance c apart.

    r1, r2 = (x_lo, x_hi, y_lo, y_hi). Closed form pi A1 F12 from the corner-sum formula for
    parallel rectangles of arbitrary alignment (Howell's catalogue of view factors, C-14).
    """
    s = 0.0
    for i, x in enumerate(r1[:2]):
        for j, y in enumerate(r1[2:]):
            for k, u in enumerate(r2[:2]):
                for l, v in enumerate(r2[2:]):
                    s += (-1) ** (i + j + k + l) * _corner(x - u, y - v, c)
    return 0.5 * s  # pi * A1 F12, with A1 F12 = s / (2 pi)


def _gl(a: float, b: float, n: int) -> tuple[np.ndarray, np.ndarray]:
    t, w = np.polynomial.legendre.leggauss(n)
    return 0.5 * (b - a) * t + 0.5 * (a + b), 0.5 * (b - a) * w


def quadrature_etendue(r1, r2, c: float, n: int = 16) -> float:
    """The same etendue by Gauss-Legendre quadrature of cos^2 / r^2 = c^2 / r^4 (4-D)."""
    x, wx = _gl(r1[0], r1[1], n)
    y, wy = _gl(r1[2], r1[3], n)
    u, wu = _gl(r2[0], r2[1], n)
    v, wv = _gl(r2[2], r2[3], n)
    X, Y, U, V = np.meshgrid(x, y, u, v, indexing="ij")
    W = np.einsum("i,j,k,l->ijkl", wx, wy, wu, wv)
    rr = (X - U) ** 2 + (Y - V) ** 2 + c * c
    return float((W * c * c / rr**2).sum())
