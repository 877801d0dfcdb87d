"""Ghost (crosstalk) analysis of one pixel: paper Figs. 2 and 4.

A pixel is traced in reverse as a Lambertian virtual source (paper Fig. 4). A ray that
leaves the stack through the pixel's own hole in every mask follows the *own path*; any
other sequence of holes is a *ghost path*: object light that reaches this pixel through
another pixel's holes. The etendue (um^2 sr) of each path is the power the pixel receives
from a uniform Lambertian object of unit radiance through that path.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, field

import numpy as np

from ..defaults import DETECTOR_HALF_UM, RSE_GHOST, RSE_OWN
from ..design import Design
from ..raytrace.kernel import STATUS_NAMES
from ..raytrace.pixel import PixelTracer, Sampling, tracer_for
from ..raytrace.sampling import weight_bound
from ..raytrace.stack import output_pitch
from ..raytrace.tally import OWN_PATH, Estimate, KeyedSums, estimate, ratio_estimate
from .tallies import GhostTally, run

#: Ray-count schedule of the precision-driven run: checks after 2^20, 2^21, ... rays.
FIRST_CHECK = 1 << 20
#: Confidence of the upper bound on the ghost light where no ghost ray was seen.
BOUND_CONFIDENCE = 0.95


@dataclass(frozen=True)
class GhostPath:
    """One sequence of holes that leads light to the pixel (sequences that only rays
    outside the pixel's acceptance follow carry none and are not listed)."""

    holes: list[dict]  # per mask from the object side down: name, row ("own"/"other"), dk
    etendue_um2sr: float
    etendue_se: float
    share: float  # of all ghost etendue
    n_rays: int
    emission_angle_deg: tuple[float, float]  # at the pixel, in its medium
    nearest_landing_um: dict[str, float]  # per Z (mm, as str): nearest distance from the axis


@dataclass(frozen=True)
class GhostResult:
    """Ghost analysis of one pixel (JSON-ready through :meth:`to_dict`)."""

    design: str
    fingerprint: str
    pixel: dict
    seed: int
    n_rays: int
    fresnel: bool
    etendue_own_um2sr: float
    etendue_own_se: float
    etendue_ghost_um2sr: float
    etendue_ghost_se: float
    ghost_fraction: float
    ghost_fraction_se: float
    paths: list[GhostPath]
    landing: dict[str, dict]  # per Z (mm): ghost light over distance from the axis
    ledger: dict[str, dict[str, int]]
    #: where no ray carried ghost light: a 95 % upper bound on ghost / own-path etendue
    #: (:func:`ghost_ratio_bound`); None where ghost light was found
    ghost_ratio_bound: float | None = None
    #: where no ray carried own-path light: a 95 % upper bound on the own-path etendue
    #: (um^2 sr, :func:`etendue_bound`; 0 where no ray the pixel accepts can reach any
    #: hole), which bounds the ghost etendue too where none was found either; None where
    #: own-path light was found
    own_etendue_bound: float | None = None
    meta: dict = field(default_factory=dict)

    def to_dict(self) -> dict:
        return asdict(self)

    def to_dataset(self):
        """The result as an xarray Dataset (the dicts of :meth:`to_dict` as labelled arrays).

        Coordinates: ``z_mm`` (the object distances of ``landing``), ``distance_um`` (centre
        of each landing bin, with ``distance_lo_um`` / ``distance_hi_um`` its edges),
        ``path`` (a label per ghost path, largest etendue first: each mask's hole, object
        side first, as ``mask:row dk``), ``mask``, ``plane`` and ``status`` (the ledger).

        Variables: ``landing_um2sr`` (z_mm, distance_um), ghost etendue per distance bin
        from the pixel's axis; ``landing_overflow_um2sr`` (z_mm), the last bin of
        ``landing[z]["etendue_by_distance_um2sr"]``, which holds every distance beyond the
        regular bins (>= ``distance_overflow_um``); ``nearest_um``, ``median_um`` (with
        ``median_beyond`` where the median lies in the overflow bin and is its lower edge),
        ``within_detector_um2sr``, ``within_detector_se`` (z_mm); per path
        ``path_etendue_um2sr``, ``path_etendue_se``, ``path_share`` (of all ghost
        etendue), ``path_n_rays``, ``emission_angle_lo_deg``, ``emission_angle_hi_deg``,
        ``path_nearest_landing_um`` (path, z_mm) and ``hole_dk`` (path, mask; ``hole_row``
        its own/other label); the scalars ``etendue_own_um2sr``, ``etendue_ghost_um2sr``,
        ``ghost_fraction`` and their ``*_se``; ``ledger`` (plane, status), ray counts.
        Missing values (None in the dicts) are NaN; every variable has ``units``. Where
        no ghost light was found, the attribute ``ghost_ratio_bound`` holds the bound.
        """
        import xarray as xr

        f64 = np.float64
        zkeys = list(self.landing)
        land = [self.landing[k] for k in zkeys]
        bins = {float(v["bin_um"]) for v in land}
        if len(bins) > 1:
            raise ValueError(f"landing bins differ between distances: {sorted(bins)}")
        bin_um = bins.pop() if bins else float("nan")
        hist = np.array([v["etendue_by_distance_um2sr"] for v in land], dtype=f64)
        hist = hist if land else np.zeros((0, 0))
        n_bins = max(hist.shape[1] - 1, 0)  # the last bin is the overflow
        lo = np.arange(n_bins) * bin_um
        masks = [h["mask"] for h in self.paths[0].holes] if self.paths else []
        labels = [_path_label(p.holes) for p in self.paths]
        statuses = list(STATUS_NAMES)
        statuses += sorted({s for row in self.ledger.values() for s in row} - set(statuses))

        def per_z(key: str) -> np.ndarray:
            return np.array([_nan(v[key]) for v in land], dtype=f64)

        def per_path(get) -> np.ndarray:
            return np.array([get(p) for p in self.paths], dtype=f64)

        um, um2sr, one = {"units": "um"}, {"units": "um^2 sr"}, {"units": "1"}
        data = {
            "landing_um2sr": (("z_mm", "distance_um"), hist[:, :n_bins], um2sr),
            "landing_overflow_um2sr": (
                "z_mm",
                hist[:, n_bins] if hist.shape[1] else np.zeros(len(zkeys)),
                um2sr | {"long_name": "ghost etendue landing at >= distance_overflow_um"},
            ),
            "nearest_um": ("z_mm", per_z("nearest_um"), um),
            "median_um": (
                "z_mm",
                per_z("median_um"),
                um | {"long_name": "median landing distance (a lower bound where median_beyond)"},
            ),
            "median_beyond": (
                "z_mm",
                np.array([bool(v.get("median_beyond", False)) for v in land], dtype=bool),
                {"units": "1", "long_name": "median in the overflow bin: median_um its lower edge"},
            ),
            "within_detector_um2sr": ("z_mm", per_z("within_detector_um2sr"), um2sr),
            "within_detector_se": ("z_mm", per_z("within_detector_se"), um2sr),
            "path_etendue_um2sr": ("path", per_path(lambda p: p.etendue_um2sr), um2sr),
            "path_etendue_se": ("path", per_path(lambda p: p.etendue_se), um2sr),
            "path_share": ("path", per_path(lambda p: p.share), one),
            "path_n_rays": (
                "path",
                np.array([p.n_rays for p in self.paths], dtype=np.int64),
                {"units": "rays"},
            ),
            "emission_angle_lo_deg": (
                "path",
                per_path(lambda p: p.emission_angle_deg[0]),
                {"units": "deg"},
            ),
            "emission_angle_hi_deg": (
                "path",
                per_path(lambda p: p.emission_angle_deg[1]),
                {"units": "deg"},
            ),
            "path_nearest_landing_um": (
                ("path", "z_mm"),
                np.array(
                    [[_nan(p.nearest_landing_um.get(k)) for k in zkeys] for p in self.paths],
                    dtype=f64,
                ).reshape(len(self.paths), len(zkeys)),
                um,
            ),
            "hole_dk": (
                ("path", "mask"),
                np.array([[h["dk"] for h in p.holes] for p in self.paths], dtype=np.int64).reshape(
                    len(self.paths), len(masks)
                ),
                {"units": "pixels", "long_name": "hole index relative to the pixel's own"},
            ),
            "etendue_own_um2sr": ((), f64(self.etendue_own_um2sr), um2sr),
            "etendue_own_se": ((), f64(self.etendue_own_se), um2sr),
            "etendue_ghost_um2sr": ((), f64(self.etendue_ghost_um2sr), um2sr),
            "etendue_ghost_se": ((), f64(self.etendue_ghost_se), um2sr),
            "ghost_fraction": ((), f64(self.ghost_fraction), one),
            "ghost_fraction_se": ((), f64(self.ghost_fraction_se), one),
            "ledger": (
                ("plane", "status"),
                np.array(
                    [[row.get(s, 0) for s in statuses] for row in self.ledger.values()],
                    dtype=np.int64,
                ).reshape(len(self.ledger), len(statuses)),
                {"units": "rays"},
            ),
        }
        coords = {
            "z_mm": ("z_mm", [float(k) for k in zkeys], {"units": "mm"}),
            "distance_um": ("distance_um", lo + bin_um / 2, um),
            "distance_lo_um": ("distance_um", lo, um),
            "distance_hi_um": ("distance_um", lo + bin_um, um),
            "path": ("path", labels),
            "mask": ("mask", masks),
            "hole_row": (
                ("path", "mask"),
                np.array([[h["row"] for h in p.holes] for p in self.paths], dtype=object).reshape(
                    len(self.paths), len(masks)
                ),
            ),
            "plane": ("plane", list(self.ledger)),
            "status": ("status", statuses),
        }
        detector = {v["detector_half_um"] for v in land}
        attrs = {
            "design": self.design,
            "fingerprint": self.fingerprint,
            "seed": self.seed,
            "n_rays": self.n_rays,
            "fresnel": int(self.fresnel),
            "pixel_row": self.pixel["row"],
            "pixel_k": self.pixel["k"],
            "pixel_x_um": self.pixel["x_um"],
            "pixel_y_um": self.pixel["y_um"],
            "bin_um": bin_um,
            "distance_overflow_um": n_bins * bin_um,
        }
        if len(detector) == 1:
            attrs["detector_half_um"] = float(detector.pop())
        if "estimator" in self.meta:
            attrs["estimator"] = self.meta["estimator"]
        if self.ghost_ratio_bound is not None:
            attrs["ghost_ratio_bound"] = self.ghost_ratio_bound
        if self.own_etendue_bound is not None:
            attrs["own_etendue_bound_um2sr"] = self.own_etendue_bound
        return xr.Dataset(data, coords=coords, attrs=attrs)


def _path_label(holes: list[dict]) -> str:
    """'layer 1:own-19; layer 2:other+0; ...' (each mask's hole, object side first)."""
    return "; ".join(f"{h['mask']}:{h['row']}{h['dk']:+d}" for h in holes)


def _nan(v) -> float:
    return float("nan") if v is None else float(v)


def _schedule(n_rays: int | None, max_rays: int) -> list[int]:
    if n_rays is not None:
        return [n_rays]
    ends, n = [], FIRST_CHECK
    while n < max_rays:
        ends.append(n)
        n *= 2
    ends.append(max_rays)
    return ends


def analyse_ghosts(
    design: Design,
    *,
    pixel: tuple[int, int] = (0, 0),
    z_mm: tuple[float, ...] = (0.0,),
    n_rays: int | None = None,
    rse_own: float = RSE_OWN,
    rse_ghost: float = RSE_GHOST,
    max_rays: int = 1 << 27,
    seed: int = 0,
    fresnel: bool = False,
    detector_half_um: float = DETECTOR_HALF_UM,
    chunk: int = 1 << 21,
    progress: bool = False,
    sampling: Sampling | None = None,
    tracer: PixelTracer | None = None,
) -> GhostResult:
    """Etendue of the own and ghost paths of one pixel, and where ghost light comes from.

    Parameters
    ----------
    design : Design
    pixel : (row, k), the used pixel (row 0 = A, 1 = B; k = 0 is mid-array)
    z_mm : object distances (mm above the reference plane) at which to locate ghost light
    n_rays : fixed number of rays; if None, run until the relative standard errors
        ``rse_own`` and ``rse_ghost`` are reached (checked at 2^20, 2^21, ... rays, a
        schedule independent of ``chunk``) or ``max_rays``; where no ray has carried
        ghost light yet, until ``rse_own`` is reached and the 95 % upper bound on
        ghost / own-path etendue (:func:`ghost_ratio_bound`) is at most ``rse_own``:
        ghost light too faint to change the own path's figure beyond its own precision
    detector_half_um : half width of the square virtual detector (paper Fig. 4) centred
        on the pixel's axis; ghost etendue landing inside it is reported per Z
    sampling : Sampling, replaces ``n_rays``, ``rse_own``, ``rse_ghost``, ``max_rays``,
        ``seed``, ``fresnel`` and ``chunk`` (its ray count, where None, is ``n_rays``)
    tracer : PixelTracer of this design whose pilot runs to reuse (other analyses of the
        same pixel share them); the sampling is still this call's

    Returns
    -------
    GhostResult
        With ``ghost_ratio_bound`` set where no ray carried ghost light (the ghost
        etendue and fraction are then 0 and only the bound says how small they are), and
        ``own_etendue_bound`` where none carried own-path light (no light reaches the
        pixel through its own holes, as far as ``n_rays`` can tell; the run stops at
        once where no accepted ray can reach any hole: the etendue is then exactly 0).
    """
    if sampling is None:
        sampling = Sampling(n_rays, seed, fresnel, chunk, rse_own, rse_ghost, max_rays)
    sampling = sampling.or_rays(n_rays)
    tr = tracer_for(design, sampling, tracer)
    row, k = pixel
    src = tr.source(pixel)
    cx, cy = src.x, src.y
    lat = tr.path.lattice
    nbins = 400
    bin_um = output_pitch(design)  # landing distances in output pixels (84.6 um: paper)
    t = GhostTally(
        tr.path.n_masks, pixel, lat.k_lo, lat.k_hi, tr.n0, z_mm, bin_um, nbins,
        detector_half_um, tr.path.slabs.shape[0],
    )  # fmt: skip
    own = OWN_PATH
    sums = t.sums
    zs = [float(z) for z in z_mm]
    w_max = weight_bound(tr.path, src, tr.hole_weights(pixel), tr.s2_max)
    done = 0
    # no ray the pixel accepts reaches any hole: no light at all, nothing to trace for
    schedule = [FIRST_CHECK] if w_max == 0 and sampling.n_rays is None else None
    for end in schedule or _schedule(sampling.n_rays, sampling.max_rays):
        run(tr, pixel, [t], end - done, first_id=done, progress=progress)
        done = end
        n = done
        e_own = _path_estimate(sums, own, n)
        e_gh = _ghost_estimate(sums, own, n)
        if e_gh.value > 0:
            ghost_ok = e_gh.rse <= sampling.rse_ghost
        else:  # no ghost light yet: its rse is undefined; stop on the bound instead
            ghost_ok = ghost_ratio_bound(w_max, n, e_own.value) <= sampling.rse_own
        if sampling.n_rays is None and e_own.rse <= sampling.rse_own and ghost_ok:
            break
    n = done
    e_own = _path_estimate(sums, own, n)
    e_gh = _ghost_estimate(sums, own, n)
    bound = own_bound = None
    if e_gh.value == 0 and e_own.value > 0:
        bound = ghost_ratio_bound(w_max, n, e_own.value)
    if e_own.value == 0:
        own_bound = etendue_bound(w_max, n)
    frac = ratio_estimate(e_own, e_gh, n)
    names = list(tr.path.mask_names)
    paths = []
    for code, sl in sums.keys.items():
        if code == own or sums.s1[sl] <= 0:  # no light: only rays the pixel does not accept
            continue
        e = estimate(sums.s1[sl], sums.s2[sl], n)
        holes = [
            {"mask": names[m], "row": "other" if o else "own", "dk": int(dk)}
            for m, (o, dk) in enumerate(t.registry.decode(code))
        ][::-1]
        paths.append(
            GhostPath(
                holes=holes,
                etendue_um2sr=e.value,
                etendue_se=e.se,
                share=e.value / e_gh.value if e_gh.value else 0.0,
                n_rays=int(sums.count[sl]),
                emission_angle_deg=(float(sums.lo[sl]), float(sums.hi[sl])),
                nearest_landing_um={
                    _zkey(z): _finite(t.nearest[iz, sl]) for iz, z in enumerate(zs)
                },
            )
        )
    paths.sort(key=lambda p: -p.etendue_um2sr)
    landing = {}
    for iz, z in enumerate(zs):
        e_in = estimate(t.inside[iz], t.inside2[iz], n)
        h = t.hist[iz] / n
        nz = np.flatnonzero(h)
        median, beyond = _weighted_quantile(h, 0.5, bin_um)
        landing[_zkey(z)] = {
            "bin_um": bin_um,
            "etendue_by_distance_um2sr": h.tolist(),
            "nearest_um": _finite(t.nearest[iz].min(initial=np.inf)),
            "median_um": median,
            "median_beyond": beyond,
            "within_detector_um2sr": e_in.value,
            "within_detector_se": e_in.se,
            "detector_half_um": detector_half_um,
            "last_nonzero_bin": int(nz[-1]) if nz.size else None,
        }
    led = {
        name: {st: int(t.ledger[i, j]) for j, st in enumerate(STATUS_NAMES) if t.ledger[i, j]}
        for i, name in enumerate(_plane_names(tr.path))
    }
    return GhostResult(
        design=design.name,
        fingerprint=design.fingerprint(),
        pixel={"row": "AB"[row], "k": k, "x_um": cx, "y_um": cy},
        seed=sampling.seed,
        n_rays=n,
        fresnel=sampling.fresnel,
        etendue_own_um2sr=e_own.value,
        etendue_own_se=e_own.se,
        etendue_ghost_um2sr=e_gh.value,
        etendue_ghost_se=e_gh.se,
        ghost_fraction=frac.value,
        ghost_fraction_se=frac.se,
        paths=paths,
        landing=landing,
        ledger=led,
        ghost_ratio_bound=bound,
        own_etendue_bound=own_bound,
    )


def ghost_ratio_bound(
    w_max: float, n_rays: int, etendue_own: float, confidence: float = BOUND_CONFIDENCE
) -> float:
    """Upper bound on ghost / own-path etendue where none of ``n_rays`` carried ghost light.

    Each ray is a ghost ray carrying light (weight > 0) with some probability p; where
    none of n is, p < 1 - (1 - confidence)^(1/n) (about 3 / n at 95 %: the rule of
    three). A ray's weight is at most ``w_max``
    (:func:`~opticalstamp.raytrace.sampling.weight_bound`), so the ghost etendue
    E[w; ghost] is below ``w_max`` p. The bound is that over the own-path estimate
    (whose own relative error, <= ``rse_own`` at the stop, is small against the bound's).
    The ray count at which :func:`analyse_ghosts` stops is set by the own path's
    precision and by this bound, which only shrinks with n, not by the ghost rays: the
    bound is that of a fixed count.

    Parameters
    ----------
    w_max : largest weight of a ray (um^2 sr)
    n_rays : rays traced, none of which carried ghost light
    etendue_own : own-path etendue (um^2 sr)
    confidence : of the bound

    Returns
    -------
    float
        The bound (inf where there is no own-path light or no ray).
    """
    if n_rays <= 0 or etendue_own <= 0:
        return float("inf")
    return etendue_bound(w_max, n_rays, confidence) / etendue_own


def etendue_bound(w_max: float, n_rays: int, confidence: float = BOUND_CONFIDENCE) -> float:
    """Upper bound (um^2 sr) on the etendue of light that none of ``n_rays`` carried.

    The rule of three of :func:`ghost_ratio_bound` without the ratio: a ray carries such
    light with probability p < 1 - (1 - confidence)^(1/n), and at most ``w_max``
    (:func:`~opticalstamp.raytrace.sampling.weight_bound`) of it, so the etendue is below
    ``w_max`` p; exactly 0 where ``w_max`` is 0 (no ray can carry any), inf where no ray
    was traced.
    """
    if w_max == 0:
        return 0.0
    if n_rays <= 0:
        return float("inf")
    return float(w_max * -np.expm1(np.log1p(-confidence) / n_rays))


def _finite(v: float) -> float | None:
    return float(v) if np.isfinite(v) else None


def _zkey(z: float) -> str:
    return f"{z:g}"


def _path_estimate(sums: KeyedSums, code: int, n: int) -> Estimate:
    sl = sums.get(code)
    return Estimate(0.0, 0.0) if sl is None else estimate(sums.s1[sl], sums.s2[sl], n)


def _ghost_estimate(sums: KeyedSums, own: int, n: int) -> Estimate:
    keep = np.ones(sums.s1.size, bool)
    sl = sums.get(own)
    if sl is not None:
        keep[sl] = False
    return estimate(float(sums.s1[keep].sum()), float(sums.s2[keep].sum()), n)


def _weighted_quantile(h: np.ndarray, q: float, bin_um: float) -> tuple[float | None, bool]:
    """The q-quantile of the landing distance (a bin centre) and whether it is only a
    lower bound: where it falls in the last bin, the overflow, which holds every distance
    beyond the regular bins, the quantile is that bin's lower edge, at least."""
    tot = h.sum()
    if tot <= 0:
        return None, False
    c = np.cumsum(h) / tot
    i = int(np.searchsorted(c, q))
    if i >= h.size - 1:  # in the overflow bin
        return (h.size - 1) * bin_um, True
    return (i + 0.5) * bin_um, False


def _plane_names(path) -> list[str]:
    out = []
    for i in range(path.slabs.shape[0]):
        m = int(path.slabs[i, 2])
        z = path.z_exit[i]
        out.append(
            path.mask_names[m]
            if m >= 0
            else ("reference plane" if i == path.slabs.shape[0] - 1 else f"z={z:g}um")
        )
    return out
