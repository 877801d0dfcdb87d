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

from ..design import Design
from ..raytrace.kernel import STATUS_NAMES, launch
from ..raytrace.sampling import DEFENSIVE_SHARE, Source, hole_targets, site_index
from ..raytrace.stack import pixel_center, reverse_path
from ..raytrace.tally import (
    OWN_PATH,
    Estimate,
    KeyedSums,
    PathRegistry,
    estimate,
    is_own_path,
    object_plane,
    ratio_estimate,
)

#: Ray-count schedule of the precision-driven run: checks after 2^20, 2^21, ... rays.
FIRST_CHECK = 1 << 20
#: Width of the bins of ghost light over distance from the pixel's axis (um).
DISTANCE_BIN_UM = 84.6


@dataclass(frozen=True)
class GhostPath:
    """One sequence of holes that leads light to the pixel."""

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
    meta: dict = field(default_factory=dict)

    def to_dict(self) -> dict:
        return asdict(self)


PILOT_RAYS = 1 << 18


def pixel_source(design: Design, row: int, k: int) -> Source:
    """The sensitive area of used pixel (row, k) as a Lambertian virtual source."""
    cx, cy = pixel_center(design, row, k)
    s = design.sensor
    return Source(cx, cy, s.sensitive_width_um, s.sensitive_height_um)


def acceptance(design: Design, n0: float, sx: np.ndarray, sy: np.ndarray) -> np.ndarray:
    """Pixel angular response (0 or 1) for invariant directions s in the medium n0."""
    cut = design.sensor.acceptance_half_angle_deg
    if cut >= 90.0:
        return np.ones(sx.shape)
    return (sx * sx + sy * sy <= (n0 * np.sin(np.radians(cut))) ** 2).astype(np.float64)


def allocate_holes(
    design: Design,
    path,
    src: Source,
    row: int,
    k: int,
    seed: int,
    fresnel: bool,
    rse_own: float = 1e-3,
    rse_ghost: float = 1e-2,
) -> np.ndarray:
    """Weights over the first mask's holes for importance sampling (from a pilot run).

    A pilot of 2^18 rays (its own random stream, geometric table q) measures, for each
    first-mask hole j, the sums S_j of the squared own-path and ghost weights. Within each
    tally, holes get samples in proportion to sqrt(S_j) (the variance-minimising
    allocation); the split a between the two tallies minimises the rays needed to reach
    both relative standard errors, predicted by reweighting the pilot:
    E'[w'^2] = sum_j (q_j / q'_j) S_j / N.
    """
    m0 = int(path.slabs[path.first_mask_slab, 2])
    n_sites = path.lattice.n_rows * (path.lattice.k_hi - path.lattice.k_lo + 1)
    s1 = np.zeros((2, n_sites))
    s2 = np.zeros((2, n_sites))
    n0 = path.slabs[0, 1]
    for b in launch(path, src, PILOT_RAYS, seed, stream=1, fresnel=fresnel):
        w = b.w * acceptance(design, n0, b.sx, b.sy)
        site = site_index(path, b.hole_row[:, m0], b.hole_k[:, m0])
        g = (~is_own_path(b, row, k)).astype(np.int64)
        np.add.at(s1, (g, site), w)
        np.add.at(s2, (g, site), w * w)
    q = hole_targets(path, src).q_per_area * path.hole_area(m0)
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
    rse_own: float = 1e-3,
    rse_ghost: float = 1e-2,
    max_rays: int = 1 << 27,
    seed: int = 0,
    fresnel: bool = False,
    detector_half_um: float = 500.0,
    chunk: int = 1 << 21,
    progress: bool = False,
) -> GhostResult:
    """Etendue of the own and ghost paths of one pixel, and where ghost light comes from.

    Parameters
    ----------
    design : Design
    pixel : (row, k), the used pixel (row 0 = A, 1 = B; k = 0 is mid-array)
    z_mm : object distances (mm above the reference plane) at which to locate ghost light
    n_rays : fixed number of rays; if None, run until the relative standard errors
        ``rse_own`` and ``rse_ghost`` are reached (checked at 2^20, 2^21, ... rays, a
        schedule independent of ``chunk``) or ``max_rays``
    detector_half_um : half width of the square virtual detector (paper Fig. 4) centred
        on the pixel's axis; ghost etendue landing inside it is reported per Z
    """
    path = reverse_path(design)
    row, k = pixel
    src = pixel_source(design, row, k)
    cx, cy = src.x, src.y
    weights = allocate_holes(design, path, src, row, k, seed, fresnel, rse_own, rse_ghost)
    n_obj = design.index(design.object_medium)
    n0 = path.slabs[0, 1]
    registry = PathRegistry(path.n_masks, row, k)
    own = OWN_PATH
    sums = KeyedSums()
    zs = [float(z) for z in z_mm]
    nbins = 400
    hist = np.zeros((len(zs), nbins + 1))
    inside = np.zeros(len(zs))
    inside2 = np.zeros(len(zs))
    nearest = np.full((len(zs), 0), np.inf)  # per Z and path slot
    ledger = np.zeros((path.slabs.shape[0], 4), np.int64)
    done = 0
    for end in _schedule(n_rays, max_rays):
        for b in launch(
            path,
            src,
            end - done,
            seed,
            fresnel=fresnel,
            first_id=done,
            chunk=chunk,
            progress=progress,
            hole_weights=weights,
        ):
            ledger += b.ledger
            codes = registry.ids(b)
            theta = np.degrees(np.arcsin(np.sqrt(b.sx**2 + b.sy**2) / n0))
            w = b.w * acceptance(design, n0, b.sx, b.sy)
            slot = sums.add(codes, w, theta)
            g = (codes != own) & (w > 0)
            for iz, z in enumerate(zs):
                xo, yo = object_plane(b, z * 1000.0, n_obj)
                dist = np.hypot(xo[g] - cx, yo[g] - cy)
                ib = np.minimum((dist / DISTANCE_BIN_UM).astype(np.int64), nbins)
                np.add.at(hist[iz], ib, w[g])
                box = (np.abs(xo[g] - cx) <= detector_half_um) & (
                    np.abs(yo[g] - cy) <= detector_half_um
                )
                wb = w[g][box]
                np.add.at(inside, np.full(wb.size, iz), wb)
                np.add.at(inside2, np.full(wb.size, iz), wb * wb)
                if nearest.shape[1] < len(sums.keys):
                    grow = len(sums.keys) - nearest.shape[1]
                    nearest = np.hstack([nearest, np.full((len(zs), grow), np.inf)])
                np.minimum.at(nearest[iz], slot[g], dist)
        done = end
        n = done
        e_own = _path_estimate(sums, own, n)
        e_gh = _ghost_estimate(sums, own, n)
        if n_rays is None and e_own.rse <= rse_own and (e_gh.value > 0 and e_gh.rse <= rse_ghost):
            break
    n = done
    e_own = _path_estimate(sums, own, n)
    e_gh = _ghost_estimate(sums, own, n)
    frac = ratio_estimate(e_own, e_gh, n)
    names = list(path.mask_names)
    paths = []
    for code, sl in sums.keys.items():
        if code == own:
            continue
        e = estimate(sums.s1[sl], sums.s2[sl], n)
        holes = [
            {"mask": names[m], "row": "other" if o else "own", "dk": int(dk)}
            for m, (o, dk) in enumerate(registry.decode(code))
        ][::-1]
        paths.append(
            GhostPath(
                holes=holes,
                etendue_um2sr=e.value,
                etendue_se=e.se,
                share=e.value / e_gh.value if e_gh.value else 0.0,
                n_rays=int(sums.count[sl]),
                emission_angle_deg=(float(sums.lo[sl]), float(sums.hi[sl])),
                nearest_landing_um={_zkey(z): _finite(nearest[iz, sl]) for iz, z in enumerate(zs)},
            )
        )
    paths.sort(key=lambda p: -p.etendue_um2sr)
    landing = {}
    for iz, z in enumerate(zs):
        e_in = estimate(inside[iz], inside2[iz], n)
        h = hist[iz] / n
        nz = np.flatnonzero(h)
        landing[_zkey(z)] = {
            "bin_um": DISTANCE_BIN_UM,
            "etendue_by_distance_um2sr": h.tolist(),
            "nearest_um": _finite(nearest[iz].min(initial=np.inf)),
            "median_um": _weighted_quantile(h, 0.5),
            "within_detector_um2sr": e_in.value,
            "within_detector_se": e_in.se,
            "detector_half_um": detector_half_um,
            "last_nonzero_bin": int(nz[-1]) if nz.size else None,
        }
    led = {
        name: {st: int(ledger[i, j]) for j, st in enumerate(STATUS_NAMES) if ledger[i, j]}
        for i, name in enumerate(_plane_names(design, path))
    }
    return GhostResult(
        design=design.name,
        fingerprint=design.fingerprint(),
        pixel={"row": "AB"[row], "k": k, "x_um": cx, "y_um": cy},
        seed=seed,
        n_rays=n,
        fresnel=fresnel,
        etendue_own_um2sr=e_own.value,
        etendue_own_se=e_own.se,
        etendue_ghost_um2sr=e_gh.value,
        etendue_ghost_se=e_gh.se,
        ghost_fraction=frac.value,
        ghost_fraction_se=frac.se,
        paths=paths,
        landing=landing,
        ledger=led,
    )


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


def _weighted_quantile(h: np.ndarray, q: float) -> float | None:
    tot = h.sum()
    if tot <= 0:
        return None
    c = np.cumsum(h) / tot
    i = int(np.searchsorted(c, q))
    return (i + 0.5) * DISTANCE_BIN_UM


def _plane_names(design: Design, path) -> list[str]:
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
