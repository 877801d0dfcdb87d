"""Spots (responsivity maps, paper Fig. 5) and PSFs on the sensor (paper Fig. 10).

The *spot* of a pixel at object distance Z is its responsivity map R(x, y) (sr): a
Lambertian object of radiance L(x, y) gives the pixel the power integral L R dA. It is
found by reverse tracing (the pixel as virtual source) and histogramming where rays meet
the object plane; the stack is traced once and the rays extrapolated to every Z.

The *PSF* is forward: where light from a Lambertian object point lands on the sensor.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, field, replace

import numpy as np

from ..defaults import MAP_MAX_BINS, RAYS_MAP
from ..design import Design
from ..raytrace.launch import launch
from ..raytrace.pixel import PixelTracer, Sampling, acceptance, tracer_for
from ..raytrace.sampling import Source
from ..raytrace.stack import forward_path, lattice_of, output_pitch
from .colour import channel_designs
from .responsivity import Optics, band_spots, resolve_optics
from .spectrum import channels as light_channels
from .tallies import SpotTally, run


@dataclass(frozen=True)
class Spot:
    """Responsivity map of one pixel at one object distance."""

    z_mm: float
    x_edges_um: np.ndarray  # relative to the pixel's axis
    y_edges_um: np.ndarray
    map_sr: np.ndarray  # [y, x] responsivity, etendue per object area (sr)
    extent_x_um: float  # edge to edge, own path
    extent_y_um: float
    fwhm_x_um: float
    fwhm_y_um: float
    center_cell_fraction: float  # of all light (own + ghost) reaching the object plane


@dataclass(frozen=True)
class SpotResult:
    design: str
    fingerprint: str
    seed: int
    n_rays: int
    pixel: dict
    spots: list[Spot]
    meta: dict = field(default_factory=dict)

    def to_dict(self) -> dict:
        keys = ("extent_x_um", "extent_y_um", "fwhm_x_um", "fwhm_y_um", "center_cell_fraction")
        out = {
            "design": self.design,
            "fingerprint": self.fingerprint,
            "seed": self.seed,
            "n_rays": self.n_rays,
            "pixel": self.pixel,
            "z_mm": [s.z_mm for s in self.spots],
        }
        for key in keys:
            out[key] = [float(getattr(s, key)) for s in self.spots]
        return out | {"meta": self.meta}

    def to_dataset(self):
        """The spots as an xarray Dataset on the coordinate ``z_mm``.

        Variables ``extent_x_um``, ``extent_y_um``, ``fwhm_x_um``, ``fwhm_y_um``,
        ``center_cell_fraction`` (z_mm), as in :meth:`to_dict`, and ``map_sr`` (z_mm, y,
        x), the responsivity maps. Each distance has its own map grid (its own size and
        offset from the pixel's axis), so the maps are centred in a common (y, x) array and
        padded with NaN; the coordinates ``x_um`` (z_mm, x) and ``y_um`` (z_mm, y) are each
        map bin's centre from the pixel's axis (NaN in the padding). One distance's map
        with its own coordinates::

            m = ds.map_sr.sel(z_mm=1.0).dropna("x", how="all").dropna("y", how="all")
        """
        import xarray as xr

        nz = len(self.spots)
        ny = max((s.map_sr.shape[0] for s in self.spots), default=0)
        nx = max((s.map_sr.shape[1] for s in self.spots), default=0)
        maps = np.full((nz, ny, nx), np.nan)
        xc = np.full((nz, nx), np.nan)
        yc = np.full((nz, ny), np.nan)
        for i, s in enumerate(self.spots):
            my, mx = s.map_sr.shape
            oy, ox = (ny - my) // 2, (nx - mx) // 2
            maps[i, oy : oy + my, ox : ox + mx] = s.map_sr
            xc[i, ox : ox + mx] = 0.5 * (s.x_edges_um[1:] + s.x_edges_um[:-1])
            yc[i, oy : oy + my] = 0.5 * (s.y_edges_um[1:] + s.y_edges_um[:-1])

        def col(key: str) -> np.ndarray:
            return np.array([getattr(s, key) for s in self.spots], dtype=np.float64)

        um = {"units": "um"}
        attrs = {
            "design": self.design,
            "fingerprint": self.fingerprint,
            "seed": self.seed,
            "n_rays": self.n_rays,
            "pixel_row": self.pixel["row"],
            "pixel_k": self.pixel["k"],
            "pixel_x_um": self.pixel["x_um"],
            "pixel_y_um": self.pixel["y_um"],
        }
        for k, v in self.meta.items():
            attrs[k] = int(v) if isinstance(v, bool) else v
        return xr.Dataset(
            {
                "extent_x_um": ("z_mm", col("extent_x_um"), um),
                "extent_y_um": ("z_mm", col("extent_y_um"), um),
                "fwhm_x_um": ("z_mm", col("fwhm_x_um"), um),
                "fwhm_y_um": ("z_mm", col("fwhm_y_um"), um),
                "center_cell_fraction": ("z_mm", col("center_cell_fraction"), {"units": "1"}),
                "map_sr": (
                    ("z_mm", "y", "x"),
                    maps,
                    {"units": "sr", "long_name": "responsivity (etendue per object area)"},
                ),
            },
            coords={
                "z_mm": ("z_mm", col("z_mm"), {"units": "mm"}),
                "x_um": (("z_mm", "x"), xc, um),
                "y_um": (("z_mm", "y"), yc, um),
            },
            attrs=attrs,
        )


def fwhm(profile: np.ndarray, centers: np.ndarray) -> float:
    """Full width at half maximum (outermost half-max crossings, linear interpolation)."""
    if profile.max() <= 0:
        return float("nan")
    half = profile.max() / 2
    above = np.flatnonzero(profile >= half)
    i0, i1 = above[0], above[-1]

    def cross(i_in: int, i_out: int) -> float:
        if i_out < 0 or i_out >= profile.size:
            return centers[i_in]
        a, b = profile[i_out], profile[i_in]
        return centers[i_out] + (half - a) / (b - a) * (centers[i_in] - centers[i_out])

    return float(cross(i1, i1 + 1) - cross(i0, i0 - 1))


def spots(
    design: Design,
    *,
    z_mm=(0.0, 1.0, 2.0, 3.0, 4.0),
    pixel: tuple[int, int] = (0, 0),
    n_rays: int = RAYS_MAP,
    seed: int = 0,
    fresnel: bool = False,
    bin_um: float = 2.0,
    ghosts: bool = True,
    chunk: int = 1 << 21,
    progress: bool = False,
    sampling: Sampling | None = None,
    tracer: PixelTracer | None = None,
    optics: str | Optics = "ray",
) -> SpotResult:
    """Responsivity maps of one pixel at each object distance (paper Fig. 5).

    Parameters
    ----------
    z_mm : object distances above the reference plane (mm)
    bin_um : map pixel size (um); a spot wider than ``MAP_MAX_BINS`` of them (a stack too
        thin to confine the light) is mapped on that many coarser bins
    ghosts : include ghost paths in the maps and the centre-cell fraction
    sampling : Sampling, replaces ``n_rays``, ``seed``, ``fresnel`` and ``chunk`` (its ray
        count, where None, is ``n_rays``)
    tracer : PixelTracer of this design whose pilot runs to reuse (other analyses of the
        same pixel share them); the sampling is still this call's
    optics : "ray", "wave" or "auto" (:func:`~opticalstamp.analysis.responsivity.
        resolve_optics`): with wave optics the maps are the wave engine's in its band
        (the design's light) plus the traced light beyond it, on the wave engine's
        bins; the edge-to-edge extents stay those of the geometric own path. A colour
        scanner (``electronics.illumination`` "rgb") under wave optics: each channel's
        spots (its LED's light in the band, the light beyond traced through the design at
        the channel's mean wavelength, :func:`~.colour.channel_designs`); the headline
        the channel whose light spreads most (:data:`SPOT_RULE`), every channel's figures
        in ``meta["channels"]``
    """
    if sampling is None:
        sampling = Sampling(n_rays, seed, fresnel, chunk)
    sampling = sampling.or_rays(n_rays)
    opt = resolve_optics(design, optics, fresnel=sampling.fresnel, channels=True)
    specs = light_channels(design)
    kw = dict(pixel=pixel, sampling=sampling, bin_um=bin_um, ghosts=ghosts, progress=progress)
    zs = [float(z) for z in z_mm]
    if opt.engine != "wave" or len(specs) == 1:
        return _spots(design, design, None, zs, opt, tracer=tracer, **kw)
    traced = channel_designs(design)
    per = {
        name: _spots(
            design,
            traced[name],
            spec,
            zs,
            opt,
            tracer=tracer if traced[name] is design else None,
            **kw,
        )  # fmt: skip
        for name, spec in specs.items()
    }
    return widest_channel(per, specs)


#: the headline of a colour scanner's spots, in words
SPOT_RULE = (
    "a colour scanner's spots are its widest channel's (the least light on the centre "
    "output cell over the heights): each channel is its own exposure, and a colour image "
    "is as sharp as its most blurred channel"
)


def widest_channel(per: dict[str, SpotResult], specs: dict) -> SpotResult:
    """The spots of the channel whose light spreads most (the least on the centre output
    cell, summed over the heights; the first in red, green, blue order on a tie), with
    every channel's figures in ``meta["channels"]`` and the rule in ``meta["headline"]``."""
    share = {n: sum(s.center_cell_fraction for s in r.spots) for n, r in per.items()}
    name = min(share, key=share.get)
    head = per[name]
    channels = {n: {k: v for k, v in r.to_dict().items() if k != "meta"} for n, r in per.items()}
    for n, sp in specs.items():
        channels[n]["spectrum"] = {
            "name": sp.name, "wavelengths_um": list(sp.wavelengths_um),
            "weights": [float(w) for w in sp.weights],
        }  # fmt: skip
    meta = head.meta | {"channels": channels, "headline": {"channel": name, "rule": SPOT_RULE}}
    return replace(head, meta=meta)


def _spots(
    design: Design,
    traced: Design,
    spectrum,
    zs: list[float],
    opt: Optics,
    *,
    pixel: tuple[int, int],
    sampling: Sampling,
    bin_um: float,
    ghosts: bool,
    progress: bool,
    tracer: PixelTracer | None,
) -> SpotResult:
    """:func:`spots` under one light: ``spectrum`` (None: the design's) in the wave
    engine's band, the rest traced through ``traced`` (``design`` at that light's mean
    wavelength where its media disperse, else ``design``)."""
    n_rays = sampling.n_rays
    tr = tracer_for(traced, sampling, tracer)
    row, k = pixel
    src = tr.source(pixel)
    # map half-widths from the own-path support of a pilot (its own random stream)
    cell_um = output_pitch(design)  # the output pixel grid of paper Fig. 5 (84.6 um)
    pilot = SpotTally(zs, None, None, cell_um)
    run(tr, pixel, [pilot], 1 << 18, stream=2)
    reach = np.maximum(np.abs(pilot.lo), np.abs(pilot.hi))  # inf where no own ray landed
    half = np.where(np.isfinite(reach), reach, 0.0).max(axis=1)
    half = np.ceil((1.25 * half + 3 * bin_um) / cell_um * 2 + 1) * cell_um / 2
    # a spot wider than MAP_MAX_BINS bins (a stack too thin to confine the light) is
    # mapped on coarser bins, never on a grid that does not fit in memory
    bins = np.maximum(bin_um, 2 * half / MAP_MAX_BINS)
    inband = band_spots(design, opt, zs, half, bins, pixel, progress, spectrum=spectrum)
    edges = inband.edges
    t = SpotTally(zs, edges, bins, cell_um, ghosts, inband.band)
    run(tr, pixel, [t], progress=progress)
    light = inband.light * n_rays  # in the tallies' units (etendue x rays)
    inside = t.inside + light * inband.center_cell
    total = t.total + light[0]
    maps, lo, hi = t.maps, t.lo, t.hi  # each read once (from the device, where a GPU ran)
    out = []
    for iz, z in enumerate(zs):
        e = edges[iz]
        m = maps[iz] / (n_rays * bins[iz] * bins[iz]) + inband.maps[iz]
        c = 0.5 * (e[1:] + e[:-1])
        out.append(
            Spot(
                z,
                e,
                e.copy(),
                m,
                float(hi[iz, 0] - lo[iz, 0]),
                float(hi[iz, 1] - lo[iz, 1]),
                fwhm(m.sum(axis=0), c),
                fwhm(m.sum(axis=1), c),
                float(inside[iz] / total) if total else 0.0,
            )
        )
    return SpotResult(
        design.name,
        design.fingerprint(),
        sampling.seed,
        n_rays,
        {"row": "AB"[row], "k": k, "x_um": src.x, "y_um": src.y},
        out,
        {
            "ghosts": ghosts,
            "fresnel": sampling.fresnel,
            "bin_um": bin_um,
            "cell_um": cell_um,
            "optics": opt.to_dict(),
        },
    )


# -- PSF --------------------------------------------------------------------------------
@dataclass(frozen=True)
class PSF:
    """Where the light of a Lambertian object point lands on the sensor (paper Fig. 10)."""

    design: str
    fingerprint: str
    seed: int
    n_rays: int
    x_obj_um: float
    y_obj_um: float
    z_mm: float
    own_pixel: float  # fractions of the power reaching the sensor plane
    neighbour_own_path: float
    neighbour_ghost: float
    insensitive: float
    reaching_sensor: float  # fraction of the emitted power
    own_pixel_id: dict
    grid_power: np.ndarray  # [line, column] power fraction per 600-dpi pixel
    grid_x0_um: float  # x of the left edge of column 0
    grid_pitch_um: float
    fine_map: np.ndarray  # [y, x] landing power density (fraction per um^2)
    fine_edges_x_um: np.ndarray
    fine_edges_y_um: np.ndarray
    used_pixels: list[tuple[float, float]]  # centres of used pixels in the window
    sensitive_um: tuple[float, float]
    meta: dict = field(default_factory=dict)

    def to_dict(self) -> dict:
        d = asdict(self)
        for key in ("grid_power", "fine_map", "fine_edges_x_um", "fine_edges_y_um"):
            d.pop(key)
        d["grid_power"] = self.grid_power.tolist()
        return d

    def to_dataset(self):
        """The PSF as an xarray Dataset.

        Variables ``grid_power`` (line, column), the power fraction per sensor pixel, with
        the coordinates ``line_y_um`` / ``column_x_um`` (pixel centres on the sensor);
        ``fine_map`` (y_um, x_um), landing power density on bin centres; the scalar
        fractions ``own_pixel``, ``neighbour_own_path``, ``neighbour_ghost``,
        ``insensitive`` (of the power reaching the sensor plane) and ``reaching_sensor``
        (of the emitted power). The object point, own pixel and design in the attributes.
        """
        import xarray as xr

        lines, cols = self.grid_power.shape
        one = {"units": "1"}
        ex, ey = self.fine_edges_x_um, self.fine_edges_y_um
        scalars = {
            k: ((), np.float64(getattr(self, k)), one)
            for k in (
                "own_pixel",
                "neighbour_own_path",
                "neighbour_ghost",
                "insensitive",
                "reaching_sensor",
            )
        }
        return xr.Dataset(
            {
                "grid_power": (("line", "column"), self.grid_power, one),
                "fine_map": (("y_um", "x_um"), self.fine_map, {"units": "1/um^2"}),
                **scalars,
            },
            coords={
                "line_y_um": ("line", np.arange(lines) * self.grid_pitch_um, {"units": "um"}),
                "column_x_um": (
                    "column",
                    self.grid_x0_um + (np.arange(cols) + 0.5) * self.grid_pitch_um,
                    {"units": "um"},
                ),
                "y_um": ("y_um", 0.5 * (ey[1:] + ey[:-1]), {"units": "um"}),
                "x_um": ("x_um", 0.5 * (ex[1:] + ex[:-1]), {"units": "um"}),
            },
            attrs={
                "design": self.design,
                "fingerprint": self.fingerprint,
                "seed": self.seed,
                "n_rays": self.n_rays,
                "x_obj_um": self.x_obj_um,
                "y_obj_um": self.y_obj_um,
                "z_mm": self.z_mm,
                "own_pixel_row": self.own_pixel_id["row"],
                "own_pixel_k": self.own_pixel_id["k"],
                "grid_pitch_um": self.grid_pitch_um,
                "fresnel": int(bool(self.meta.get("fresnel", False))),
            },
        )


def nearest_pixel(design: Design, x: float, y: float) -> tuple[int, int]:
    """Used pixel (row, k) whose axis is nearest to (x, y) (ties: row A, lower k)."""
    lat = lattice_of(design)
    best = None
    for r in range(lat.n_rows):
        kk = int(np.clip(np.floor((x - lat.row_x[r]) / lat.pitch + 0.5), lat.k_lo, lat.k_hi))
        for k in (kk - 1, kk, kk + 1):
            if not lat.k_lo <= k <= lat.k_hi:
                continue
            px, py = lat.centers(r, k)
            d = (x - px) ** 2 + (y - py) ** 2
            if best is None or d < best[0] - 1e-9:
                best = (d, r, k)
    return best[1], best[2]


def pixel_hit(design: Design, x: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(row, k) of the used pixel whose sensitive area contains (x, y); row -1 if none."""
    lat = lattice_of(design)
    s = design.sensor
    row = np.full(x.shape, -1, np.int64)
    kout = np.zeros(x.shape, np.int64)
    for r in range(lat.n_rows):
        k = np.floor((x - lat.row_x[r]) / lat.pitch + 0.5)
        inside = (
            (np.abs(x - lat.row_x[r] - k * lat.pitch) <= s.sensitive_width_um / 2)
            & (np.abs(y - lat.row_y[r]) <= s.sensitive_height_um / 2)
            & (k >= lat.k_lo)
            & (k <= lat.k_hi)
        )
        row[inside] = r
        kout[inside] = k[inside].astype(np.int64)
    return row, kout


def psf(
    design: Design,
    *,
    x_obj_um: float = 0.0,
    y_obj_um: float = 0.0,
    z_mm: float = 1.0,
    n_rays: int = RAYS_MAP,
    seed: int = 0,
    fresnel: bool = False,
    window_um: float = 400.0,
    bin_um: float = 2.0,
    chunk: int = 1 << 21,
    progress: bool = False,
    device: str | None = None,
) -> PSF:
    """Forward-trace a Lambertian object point at (x, y, Z) to the sensor (paper Fig. 10).

    The power reaching the sensor plane is split into: the *own pixel* (the used pixel
    whose axis is nearest the point) through its own holes; *neighbour pixels by own-path
    blur* (another used pixel through that pixel's own holes); *ghosts* (a used pixel
    reached through holes that are not its own); and the *insensitive* area.

    The landing map (``fine_map``, ``bin_um`` bins) covers ``window_um`` either side of
    the point in x and in y, wherever the sensor's lines are: ghost light lands beyond
    them (about 100 um off the axis for the prototype). The share of the power reaching
    the sensor plane that lands outside it is ``meta["outside_map"]``. ``device``: where
    the rays are traced (:func:`~opticalstamp.device.run_device`; the same rays either
    way).
    """
    path = forward_path(design, z_mm * 1000.0)
    src = Source(x_obj_um, y_obj_um)
    own_r, own_k = nearest_pixel(design, x_obj_um, y_obj_um)
    lat = lattice_of(design)
    s = design.sensor
    n_s = path.slabs[-1, 1]
    pitch = s.pixel_pitch_um
    cols = int(np.ceil(window_um / pitch))
    col0 = int(np.floor(x_obj_um / pitch + 0.5)) - cols
    grid = np.zeros((s.lines, 2 * cols + 1))
    ex = np.arange(-window_um, window_um + bin_um / 2, bin_um) + x_obj_um
    ey = np.arange(-window_um, window_um + bin_um / 2, bin_um) + y_obj_um
    fine = np.zeros((ey.size - 1, ex.size - 1))
    parts = np.zeros(4)
    reach = np.zeros(1)
    rays = launch(
        path, src, n_rays, seed, fresnel=fresnel, chunk=chunk, progress=progress, device=device
    )
    for b in rays:
        w = b.w * acceptance(design, n_s, b.sx, b.sy)
        np.add.at(reach, np.zeros(w.size, np.int64), w)
        row, k = pixel_hit(design, b.x, b.y)
        on = row >= 0
        chain = np.all((b.hole_row == row[:, None]) & (b.hole_k == k[:, None]), axis=1) & on
        own = chain & (row == own_r) & (k == own_k)
        cat = np.where(~on, 3, np.where(own, 0, np.where(chain, 1, 2)))
        np.add.at(parts, cat, w)
        col = np.floor(b.x / pitch + 0.5).astype(np.int64) - col0
        line = np.floor(b.y / pitch + 0.5).astype(np.int64)
        ok = (col >= 0) & (col < grid.shape[1]) & (line >= 0) & (line < s.lines)
        np.add.at(grid, (line[ok], col[ok]), w[ok])
        ix = np.floor((b.x - ex[0]) / bin_um).astype(np.int64)
        iy = np.floor((b.y - ey[0]) / bin_um).astype(np.int64)
        ok = (ix >= 0) & (ix < ex.size - 1) & (iy >= 0) & (iy < ey.size - 1)
        np.add.at(fine, (iy[ok], ix[ok]), w[ok])
    tot = parts.sum()
    frac = parts / tot if tot > 0 else parts
    used = []
    for r in range(lat.n_rows):
        for kk in range(
            int(np.floor((ex[0] - lat.row_x[r]) / lat.pitch)),
            int(np.ceil((ex[-1] - lat.row_x[r]) / lat.pitch)) + 1,
        ):
            if lat.k_lo <= kk <= lat.k_hi:
                px, py = lat.centers(r, kk)
                used.append((float(px), float(py)))
    ox, oy = lat.centers(own_r, own_k)
    outside = max(float(1 - fine.sum() / reach[0]), 0.0) if reach[0] > 0 else 0.0
    return PSF(
        design.name,
        design.fingerprint(),
        seed,
        n_rays,
        x_obj_um,
        y_obj_um,
        z_mm,
        float(frac[0]),
        float(frac[1]),
        float(frac[2]),
        float(frac[3]),
        float(reach[0]) / n_rays,
        {"row": "AB"[own_r], "k": own_k, "x_um": float(ox), "y_um": float(oy)},
        grid / n_rays,
        (col0 - 0.5) * pitch,
        pitch,
        fine / (n_rays * bin_um**2),
        ex,
        ey,
        used,
        (s.sensitive_width_um, s.sensitive_height_um),
        {"fresnel": fresnel, "outside_map": outside},
    )
