"""How many times each pixel's rays are traced: the count behind "each pixel traced once".

A :class:`~opticalstamp.raytrace.pixel.PixelTracer` records every launch it makes (its
pilots and its rays, never a chunk it hands out again from its replay memory) in a
:class:`TracePasses`, which the tracers made from it share. A run that builds one tracer
and hands it to every traced analysis (the report) can then say, per pixel and random
stream, how many times each ray was traced: :meth:`TracePasses.passes` is the most times
any one ray of that stream was traced (1: each ray once, however the analyses split the
stream into spans). The rays of a stream are a pure function of the ray index, the seed,
the stream, the Fresnel option and the pilot's hole weights (which depend on the seed,
the Fresnel option and the two precision targets), so those make the key; a second trace
of the same rays is a second pass, a trace of further rays of the stream is not.

The count lives on the object, never at module level: it is as long-lived as the tracers
that share it.
"""

from __future__ import annotations

from collections import Counter
from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class StreamKey:
    """Which rays: a pixel (row, k) of a design (its fingerprint) and the random stream
    under one sampling (seed, Fresnel option, the pilot's precision targets). ``stream``
    0 is the analyses' rays, 1 the pilot's (:func:`~opticalstamp.raytrace.pixel.allocate_holes`)."""

    design: str
    row: int
    k: int
    stream: int
    seed: int
    fresnel: bool
    rse_own: float
    rse_ghost: float

    @property
    def pixel(self) -> tuple[int, int]:
        return (self.row, self.k)


class TracePasses:
    """The launches of a set of tracers, as ray spans per :class:`StreamKey`."""

    def __init__(self) -> None:
        self._spans: dict[StreamKey, list[tuple[int, int]]] = {}

    def add(self, key: StreamKey, first_id: int, count: int) -> None:
        """Record that rays ``first_id`` ... ``first_id + count - 1`` of ``key`` were
        traced (generated and sent through the stack)."""
        if count > 0:
            self._spans.setdefault(key, []).append((int(first_id), int(count)))

    def keys(self) -> list[StreamKey]:
        """Every stream traced, in the order first traced."""
        return list(self._spans)

    def spans(self, key: StreamKey) -> list[tuple[int, int]]:
        """The (first ray, count) of each launch of ``key``, in launch order."""
        return list(self._spans.get(key, ()))

    def launches(self) -> int:
        """Launches recorded, over every stream."""
        return sum(len(v) for v in self._spans.values())

    def rays(self, key: StreamKey) -> int:
        """Rays of ``key`` traced at least once (the union of its spans)."""
        return int(sum(hi - lo for lo, hi, _ in _depths(self._spans.get(key, ())) if _ > 0))

    def passes(self, key: StreamKey | None = None) -> int | dict[StreamKey, int]:
        """The most times one ray of ``key`` was traced (0 for a stream never traced);
        without ``key``, that for every stream traced."""
        if key is None:
            return {k: self.passes(k) for k in self._spans}
        return max((d for _, _, d in _depths(self._spans.get(key, ()))), default=0)

    def by_pixel(self, stream: int = 0) -> dict[tuple[str, int, int], Counter]:
        """Per (design, row, k): how many distinct samplings traced its ``stream``, as a
        Counter of (seed, fresnel, rse_own, rse_ghost) -> passes."""
        out: dict[tuple[str, int, int], Counter] = {}
        for k in self._spans:
            if k.stream == stream:
                c = out.setdefault((k.design, k.row, k.k), Counter())
                c[(k.seed, k.fresnel, k.rse_own, k.rse_ghost)] = self.passes(k)
        return out


def _depths(spans) -> list[tuple[int, int, int]]:
    """The ray-index line cut at every span's ends: (lo, hi, spans covering [lo, hi))."""
    if not spans:
        return []
    edges = np.array([(a, +1) for a, _ in spans] + [(a + n, -1) for a, n in spans])
    order = np.lexsort((edges[:, 1], edges[:, 0]))  # an end before a start at one index
    pos, step = edges[order, 0], edges[order, 1]
    depth = np.cumsum(step)
    return [
        (int(pos[i]), int(pos[i + 1]), int(depth[i]))
        for i in range(len(pos) - 1)
        if pos[i + 1] > pos[i]
    ]
