"""A used pixel as a reverse-traced source: the one preamble of every traced analysis.

Every traced analysis of a pixel (ghost paths, spots, folded line-spread functions, the
scan's responsivity maps) does the same: the stack from the sensor up
(:func:`~opticalstamp.raytrace.stack.reverse_path`), the pixel's sensitive area as a
Lambertian virtual source (paper Fig. 4, :func:`pixel_source`), a pilot run that weights
the first mask's holes for importance sampling (:func:`allocate_holes`), the launch, the
pixel's angular response (:func:`acceptance`) and the own-path test. :class:`PixelTracer`
does it once, for all of them; its batches (:class:`PixelBatch`) carry what the analyses
tally. :class:`Sampling` is the one value that says how many rays, which random streams,
whether Fresnel losses apply and what precision the pilot aims at.

The pilot of a pixel depends on the design, the pixel, the seed, the Fresnel option and
the two precision targets, never on the ray count or the chunk size. A tracer keeps each
pilot it computes; analyses that are handed the same tracer (``tracer=``) reuse it, so a
report that runs several analyses of one pixel runs its pilot once.
"""

from __future__ import annotations

import copy
from collections.abc import Iterator
from dataclasses import dataclass, replace
from functools import cached_property

import numpy as np

from ..defaults import RSE_GHOST, RSE_OWN
from ..design import Design
from ..device import run_device
from ..validate import InputError, check_number, check_seed
from .launch import BLOCK, RayBatch, launch
from .passes import StreamKey, TracePasses
from .sampling import DEFENSIVE_SHARE, Source, geometric_q_per_area, site_index
from .stack import Path, lattice_of, pixel_center, reverse_path
from .tally import is_own_path, object_plane

#: Rays of the pilot run of :func:`allocate_holes` (its own random stream, 1).
PILOT_RAYS = 1 << 18


def pixel_source(design: Design, row: int, k: int) -> Source:
    """The sensitive area of used pixel (row, k) as a Lambertian virtual source.

    Parameters
    ----------
    design : Design
    row, k : the pixel's row (0 = A, 1 = B) and index (k = 0 is mid-array)

    Returns
    -------
    Source
        A rectangle centred on the pixel's axis, of the sensitive area's size.
    """
    cx, cy = pixel_center(design, row, k)
    s = design.sensor
    return Source(cx, cy, s.sensitive_width_um, s.sensitive_height_um)


def acceptance_s2(design: Design, n0: float) -> float:
    """The largest |s|^2 of the pixel's acceptance cone in the medium n0 (inf: all rays).

    Parameters
    ----------
    design : Design, whose sensor gives the acceptance half-angle (deg, in the medium n0)
    n0 : refractive index of the medium next to the pixel
    """
    cut = design.sensor.acceptance_half_angle_deg
    return float("inf") if cut >= 90.0 else float((n0 * np.sin(np.radians(cut))) ** 2)


def acceptance(design: Design, n0: float, sx: np.ndarray, sy: np.ndarray) -> np.ndarray:
    """Pixel angular response (0 or 1) for invariant directions s in the medium n0.

    Parameters
    ----------
    design : Design, whose sensor gives the acceptance half-angle (deg, in the medium n0)
    n0 : refractive index of the medium next to the pixel
    sx, sy : invariant directions n0 sin(theta) (cos phi, sin phi) of the rays

    Returns
    -------
    np.ndarray
        1.0 where the ray is inside the acceptance cone, else 0.0 (float64, shape of sx).
    """
    return _within(sx, sy, acceptance_s2(design, n0))


def _within(sx: np.ndarray, sy: np.ndarray, s2_max: float) -> np.ndarray:
    """1.0 where |s|^2 <= s2_max, else 0.0 (float64)."""
    return (sx * sx + sy * sy <= s2_max).astype(np.float64)


def allocate_holes(
    design: Design,
    path: Path,
    src: Source,
    row: int,
    k: int,
    seed: int,
    fresnel: bool,
    rse_own: float = RSE_OWN,
    rse_ghost: float = RSE_GHOST,
    device: str | None = None,
) -> np.ndarray:
    """Weights over the first mask's holes for importance sampling (from a pilot run).

    A pilot of 2^18 rays (its own random stream, geometric table q) measures, for each
    first-mask hole j, the sums S_j of the squared own-path and ghost weights. Within each
    tally, holes get samples in proportion to sqrt(S_j) (the variance-minimising
    allocation); the split a between the two tallies minimises the rays needed to reach
    both relative standard errors, predicted by reweighting the pilot:
    E'[w'^2] = sum_j (q_j / q'_j) S_j / N.

    Parameters
    ----------
    design : Design
    path : the design's reverse path
    src : the pixel as a source (:func:`pixel_source`)
    row, k : the pixel
    seed, fresnel : random seed (the pilot uses stream 1) and Fresnel losses
    rse_own, rse_ghost : relative standard errors the allocation aims at
    device : where the pilot is traced (:func:`~opticalstamp.device.run_device`; the
        weights do not depend on it)

    Returns
    -------
    np.ndarray or None
        One weight per lattice site (see :func:`~opticalstamp.raytrace.sampling.site_index`);
        None where the pilot saw no light at all (the geometric table is then used).
    """
    m0 = int(path.slabs[path.first_mask_slab, 2])
    n_sites = path.lattice.n_rows * (path.lattice.k_hi - path.lattice.k_lo + 1)
    s1 = np.zeros((2, n_sites))
    s2 = np.zeros((2, n_sites))
    n0 = path.slabs[0, 1]
    for b in launch(path, src, PILOT_RAYS, seed, stream=1, fresnel=fresnel, device=device):
        w = b.w * acceptance(design, n0, b.sx, b.sy)
        site = site_index(path, b.hole_row[:, m0], b.hole_k[:, m0])
        g = (~is_own_path(b, row, k)).astype(np.int64)
        np.add.at(s1, (g, site), w)
        np.add.at(s2, (g, site), w * w)
    q = geometric_q_per_area(path, src) * path.hole_area(m0)
    alloc = [np.sqrt(s) / np.sqrt(s).sum() if s.sum() > 0 else None for s in s2]
    if alloc[1] is None or alloc[0] is None:
        return alloc[0] if alloc[1] is None else alloc[1]
    best, best_n = 0.5, np.inf
    for a in np.linspace(0.05, 0.95, 19):
        qn = DEFENSIVE_SHARE * q + (1 - DEFENSIVE_SHARE) * (a * alloc[0] + (1 - a) * alloc[1])
        need = 0.0
        for t, rse in ((0, rse_own), (1, rse_ghost)):
            m1 = s1[t].sum() / PILOT_RAYS
            m2 = (q / qn * s2[t]).sum() / PILOT_RAYS
            need = max(need, (m2 / m1**2 - 1) / rse**2)
        if need < best_n:
            best, best_n = a, need
    return best * alloc[0] + (1 - best) * alloc[1]


def _integer(value: object, name: str, lo: int, hi: float) -> int:
    if isinstance(value, np.integer):
        value = int(value)
    return int(check_number(value, name, lo, hi, integer=True))


@dataclass(frozen=True)
class Sampling:
    """How a traced analysis samples its pixel: one value instead of six parameters.

    Parameters
    ----------
    n_rays : rays to trace; None: the analysis's default (for
        :func:`~opticalstamp.analysis.ghosts.analyse_ghosts`: until ``rse_own`` and
        ``rse_ghost`` are reached, at most ``max_rays``). 1 to 1e12.
    seed : random seed, 0 to 2^63 - 1 (the rays are stream 0, the pilot stream 1)
    fresnel : apply Fresnel transmission losses (unpolarised)
    chunk : rays per traced chunk: bounds memory, never changes a result
    rse_own, rse_ghost : relative standard errors, in (0, 1), that the pilot's hole
        allocation aims at for the own path and the ghost paths (and that a
        precision-driven run stops at)
    max_rays : most rays of a precision-driven run

    Raises
    ------
    InputError
        For a value out of its range or of the wrong type, naming the field.
    """

    n_rays: int | None = None
    seed: int = 0
    fresnel: bool = False
    chunk: int = 1 << 21
    rse_own: float = RSE_OWN
    rse_ghost: float = RSE_GHOST
    max_rays: int = 1 << 27

    def __post_init__(self) -> None:
        if self.n_rays is not None:
            object.__setattr__(self, "n_rays", _integer(self.n_rays, "n_rays", 1, 1e12))
        object.__setattr__(self, "seed", int(check_seed(self.seed)))
        if not isinstance(self.fresnel, bool | np.bool_):
            raise InputError(f"fresnel: expected true or false (got {self.fresnel!r})")
        object.__setattr__(self, "fresnel", bool(self.fresnel))
        object.__setattr__(self, "chunk", _integer(self.chunk, "chunk", 1, 1 << 30))
        object.__setattr__(self, "max_rays", _integer(self.max_rays, "max_rays", 1, 1e12))
        for name in ("rse_own", "rse_ghost"):
            value = getattr(self, name)
            value = float(value) if isinstance(value, np.floating) else value
            check_number(value, name, 0.0, 1.0, lo_open=True, hi_open=True)
            object.__setattr__(self, name, float(value))

    def or_rays(self, n_rays: int | None) -> Sampling:
        """This sampling, with ``n_rays`` as its ray count where it has none."""
        return self if self.n_rays is not None else replace(self, n_rays=n_rays)

    @property
    def pilot_key(self) -> tuple:
        """What a pixel's pilot allocation depends on, besides the design and the pixel."""
        return (self.seed, self.fresnel, self.rse_own, self.rse_ghost)


@dataclass(frozen=True)
class PixelBatch:
    """One chunk of rays traced from a pixel to the object side of the stack.

    Attributes
    ----------
    rays : the traced rays that left the stack, in launch order (a
        :class:`~opticalstamp.raytrace.launch.DeviceRayBatch` where a GPU traced them)
    row, k : the pixel
    s2_max : the pixel's acceptance, |s|^2 <= s2_max (:func:`acceptance_s2`)
    x0, y0 : the pixel's axis (um)
    n_obj : refractive index of the object medium
    w : (n,) weights (etendue, um^2 sr) with the pixel's angular response applied
    own : (n,) bool, whether each ray passed the pixel's own hole in every mask
    on_device : (w, own) as device arrays, in the device's order of ``rays.device``,
        for tallies on the GPU (only where ``rays.device`` is not None)
    """

    rays: RayBatch
    row: int
    k: int
    s2_max: float
    x0: float
    y0: float
    n_obj: float

    @cached_property
    def w(self) -> np.ndarray:
        b = self.rays
        if b.device is not None:
            w = b.device.to_host(self.on_device[0], b.device.order())
        else:
            w = b.w * _within(b.sx, b.sy, self.s2_max)
        w.flags.writeable = False
        return w

    @cached_property
    def own(self) -> np.ndarray:
        own = is_own_path(self.rays, self.row, self.k)
        own.flags.writeable = False
        return own

    @cached_property
    def on_device(self) -> tuple:
        return self.rays.device.accept(self.s2_max, self.row, self.k)

    def offsets(self, z_um: float) -> tuple[np.ndarray, np.ndarray]:
        """(dx, dy) from the pixel's axis where the rays meet the object plane z_um (um).

        ``z_um`` is measured above the reference plane.
        """
        xo, yo = object_plane(self.rays, z_um, self.n_obj)
        return xo - self.x0, yo - self.y0


class PixelTracer:
    """Reverse tracer of a design's used pixels, with each pixel's pilot computed once.

    Parameters
    ----------
    design : Design
    sampling : Sampling, how to sample (default: ``Sampling()``)
    replay : keep the batch of every traced chunk and hand its rays out again (read-only)
        to a later trace that asks for them: rays of the same pixel, stream, seed, Fresnel
        option and pilot. A kept chunk is handed out whole, or cut on a
        :data:`~opticalstamp.raytrace.launch.BLOCK` edge (the ledger of the rays it lost
        is kept per block), and only the rays not traced yet are launched. The rays of a
        pixel depend on nothing else, so analyses of one pixel (a report's ghost analysis,
        spots, folded LSFs, wave light, ray-vs-wave side and scan kernels; a study's ghost
        analysis and RMTF of a design) trace each ray once, however many rays each asks
        for. It holds the rays that leave the stack (about 11 MB per 2^20 rays launched
        for the paper's prototype) as long as the tracer lives; where a GPU traced them,
        in the GPU's memory (with their weights and own-path flags: handed out whole only,
        a cut of one is traced again).
    device : where the rays are traced: auto, cpu or cuda, resolved once here
        (:func:`~opticalstamp.device.run_device`; None: the device of the run in
        progress, the CPU outside one) and kept as :attr:`device` (``cpu`` or ``cuda``).
        Every launch of the tracer, pilots included, goes there; the rays and every
        result are the same on either device.
    passes : where the tracer records each launch it makes, its pilots included (a
        :class:`~opticalstamp.raytrace.passes.TracePasses`; default a new one), as
        :attr:`passes`: how many times each pixel's rays were traced. A batch handed out
        again by ``replay`` is not a launch. Tracers made by :meth:`with_sampling` and
        :meth:`with_device` share it, so one count covers every analysis given the
        tracer (the report's "each pixel traced once", tests/passcount.py).

    Notes
    -----
    The pilot allocations (:func:`allocate_holes`) are kept per pixel and per
    :attr:`Sampling.pilot_key` in a memo that :meth:`with_sampling` shares: tracers made
    from one another reuse each other's pilots where they agree, and compute a new one
    where they do not. Nothing is kept at module level: the memo lives as long as the
    tracers that share it. The same holds for the kept batches of ``replay``.
    """

    def __init__(
        self,
        design: Design,
        sampling: Sampling | None = None,
        *,
        replay: bool = False,
        device: str | None = None,
        passes: TracePasses | None = None,
    ) -> None:
        self.device = run_device(device)
        self.passes = TracePasses() if passes is None else passes
        self.design = design
        self.sampling = Sampling() if sampling is None else sampling
        self.path = reverse_path(design)
        self.n0 = float(self.path.slabs[0, 1])
        self.s2_max = acceptance_s2(design, self.n0)
        self.n_obj = float(design.index(design.object_medium))
        self._pilots: dict[tuple, np.ndarray | None] = {}
        self._replays: dict[tuple, PixelBatch] | None = {} if replay else None
        self._kept_again: dict[tuple, list[PixelBatch]] = {}
        self._fingerprint: str | None = None
        self._scratch: dict = {}  # the CPU kernel's buffers between launches (launch())

    def with_sampling(self, sampling: Sampling) -> PixelTracer:
        """A tracer of the same design under ``sampling``, sharing this one's pilots."""
        other = copy.copy(self)  # shallow: the path and the memos are shared
        other.sampling = sampling
        return other

    def with_device(self, device: str) -> PixelTracer:
        """A tracer of the same design and sampling on ``device``, sharing this one's
        pilots (they do not depend on the device); batches kept for ``replay`` are kept
        per device (a GPU deals rays into other chunks)."""
        other = copy.copy(self)
        other.device = run_device(device)
        if other.device != self.device and self._replays is not None:
            other._replays, other._kept_again = {}, {}
        return other

    def source(self, pixel: tuple[int, int]) -> Source:
        """Used pixel (row, k) as a Lambertian virtual source; InputError if none."""
        row, k = pixel
        lat = lattice_of(self.design)
        if not (0 <= row < self.design.sensor.rows and lat.k_lo <= k <= lat.k_hi):
            raise InputError(
                f"pixel: no used pixel ({row}, {k}); rows 0 to {self.design.sensor.rows - 1},"
                f" k {lat.k_lo} to {lat.k_hi}"
            )
        return pixel_source(self.design, row, k)

    def hole_weights(self, pixel: tuple[int, int]) -> np.ndarray | None:
        """The pixel's first-mask hole weights under this sampling (read-only).

        Computed by :func:`allocate_holes` on first use, then reused by every tracer that
        shares this one's pilots and agrees on :attr:`Sampling.pilot_key`.
        """
        row, k = int(pixel[0]), int(pixel[1])
        s = self.sampling
        key = (row, k, *s.pilot_key)
        if key not in self._pilots:
            src = self.source(pixel)
            self.passes.add(self._stream_key(pixel, 1), 0, PILOT_RAYS)
            w = allocate_holes(
                self.design,
                self.path,
                src,
                row,
                k,
                s.seed,
                s.fresnel,
                s.rse_own,
                s.rse_ghost,
                device=self.device,
            )
            if w is not None:  # None: no light reaches the object side in the pilot
                w.flags.writeable = False
            self._pilots[key] = w
        return self._pilots[key]

    def _stream_key(self, pixel: tuple[int, int], stream: int) -> StreamKey:
        """The pass counter's key of the pixel's ``stream`` under this sampling."""
        if self._fingerprint is None:
            self._fingerprint = self.design.fingerprint()
        s = self.sampling
        return StreamKey(self._fingerprint, int(pixel[0]), int(pixel[1]), int(stream), *s.pilot_key)

    def trace(
        self,
        pixel: tuple[int, int],
        n_rays: int | None = None,
        *,
        first_id: int = 0,
        stream: int = 0,
        progress: bool = False,
    ) -> Iterator[PixelBatch]:
        """Trace rays first_id ... first_id + n_rays - 1 of the pixel, chunk by chunk.

        Parameters
        ----------
        pixel : (row, k), the used pixel
        n_rays : rays to trace (default: the sampling's ``n_rays``)
        first_id : index of the first ray (a run continued in steps stays one stream)
        stream : random stream (0: the analyses' rays; 1 is the pilot's)
        progress : show a progress bar

        Yields
        ------
        PixelBatch
            The rays of each chunk that left the stack, with accepted weights and the
            own-path mask.
        """
        s = self.sampling
        n = s.n_rays if n_rays is None else n_rays
        if n is None:
            raise InputError("n_rays: a ray count is needed to trace")
        if self._replays is None:
            yield from self._trace(pixel, n, first_id, stream, progress)
            return
        # every chunk traced is kept (key: the rays' pixel, stream and sampling, then its
        # first ray and count; the kept spans never overlap); the rays asked for are handed
        # out of the kept chunks where traced (whole, or cut on a block edge), and only the
        # rays not traced yet are launched
        self.source(pixel)  # InputError for a pixel that is not used, as _trace
        base = (int(pixel[0]), int(pixel[1]), int(stream), *s.pilot_key)
        kept = {key[-2]: pb for key, pb in self._replays.items() if key[:-2] == base}
        p, hi = int(first_id), int(first_id) + int(n)
        while p < hi:
            hit = next((f for f, pb in kept.items() if f <= p < f + pb.rays.n_samples), None)
            if hit is not None:
                pb = kept[hit]
                end = min(hi, hit + pb.rays.n_samples)
                piece = _cut(pb, hit, p - hit, end - hit)
                if piece is not None:
                    yield piece
                else:  # a GPU's chunk, or not on a block edge: these rays traced again
                    yield from self._again(pixel, base, p, end - p, stream, progress)
                p = end
                continue
            end = min([hi] + [f for f in kept if f > p])  # up to the next kept chunk
            at = p
            for pb in self._trace(pixel, end - p, p, stream, progress):
                kept[at] = pb = _read_only(pb)
                self._replays[(*base, at, pb.rays.n_samples)] = pb
                at += pb.rays.n_samples
                yield pb
            p = end

    def _again(
        self, pixel: tuple[int, int], base: tuple, first: int, n: int, stream: int, progress: bool
    ) -> Iterator[PixelBatch]:
        """Rays first ... first + n - 1 that a kept chunk holds but cannot be cut to:
        traced again the first time they are asked for alone, and kept apart for a later
        trace that asks for exactly them (as a GPU's chunks were always kept)."""
        key = (*base, first, n)
        if key not in self._kept_again:
            got = [_read_only(pb) for pb in self._trace(pixel, n, first, stream, progress)]
            self._kept_again[key] = got
        yield from self._kept_again[key]

    def _trace(
        self, pixel: tuple[int, int], n: int, first_id: int, stream: int, progress: bool
    ) -> Iterator[PixelBatch]:
        s = self.sampling
        row, k = pixel
        src = self.source(pixel)
        weights = self.hole_weights(pixel)
        key, done = self._stream_key(pixel, stream), 0
        for b in launch(
            self.path,
            src,
            n,
            s.seed,
            stream=stream,
            fresnel=s.fresnel,
            first_id=first_id,
            chunk=s.chunk,
            progress=progress,
            hole_weights=weights,
            device=self.device,
            scratch=self._scratch,
        ):
            self.passes.add(key, first_id + done, b.n_samples)  # each chunk as launched
            done += b.n_samples
            yield PixelBatch(b, row, k, self.s2_max, src.x, src.y, self.n_obj)


def _cut(pb: PixelBatch, first: int, a: int, b: int) -> PixelBatch | None:
    """Rays a ... b - 1 of a kept chunk whose first ray is ``first`` (a and b counted from
    it) as a batch of their
    own: ``pb`` itself for the whole chunk; None where that cannot be cut exactly (a
    chunk a GPU keeps, or a cut that is not on a :data:`~.launch.BLOCK` edge, where the
    ledger of lost rays is not known)."""
    r = pb.rays
    if a == 0 and b == r.n_samples:
        return pb
    if r.device is not None or r.block_ledger is None or a % BLOCK:
        return None
    if b % BLOCK and b != r.n_samples:
        return None
    i0, i1 = np.searchsorted(r.ids, [first + a, first + b])
    led = r.block_ledger[a // BLOCK : -(-b // BLOCK)]
    sl = slice(int(i0), int(i1))
    rays = replace(
        r,
        ids=r.ids[sl],
        x=r.x[sl],
        y=r.y[sl],
        sx=r.sx[sl],
        sy=r.sy[sl],
        w=r.w[sl],
        hole_row=r.hole_row[sl],
        hole_k=r.hole_k[sl],
        ledger=led.sum(axis=0),
        n_launched=b - a,
        n_samples=b - a,
        block_ledger=led,
    )
    return _read_only(replace(pb, rays=rays))


def _read_only(pb: PixelBatch) -> PixelBatch:
    """``pb`` with every array made read-only (a kept batch is handed out again)."""
    for obj in (pb, pb.rays):
        for v in vars(obj).values():
            if isinstance(v, np.ndarray):
                v.flags.writeable = False
    return pb


def tracer_for(
    design: Design, sampling: Sampling, tracer: PixelTracer | None = None
) -> PixelTracer:
    """The tracer an analysis of ``design`` uses: ``tracer``'s pilots under ``sampling``.

    Parameters
    ----------
    design : Design
    sampling : Sampling of this analysis
    tracer : a tracer of the same design whose pilots to share, or None (a new tracer)

    Raises
    ------
    InputError
        If ``tracer`` traces another design.
    """
    if tracer is None:
        return PixelTracer(design, sampling)
    if tracer.design is not design and tracer.design.fingerprint() != design.fingerprint():
        raise InputError(
            f"tracer: traces design {tracer.design.name!r}, not {design.name!r} "
            "(its pilots would not fit)"
        )
    return tracer.with_sampling(sampling)
