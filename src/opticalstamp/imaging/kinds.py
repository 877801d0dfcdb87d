"""The two kinds of design a scan takes, behind one interface.

A scan asks a design for its output pitch, its pixels grouped by the kernel they share,
what its kernel source means and its kernels at sets of distances, and whether its scans
can be restored. An aperture-array stamp (:class:`Stamp`) and a rod-lens array
(:class:`RodLensArray`) answer each in their own way; :func:`scanner_of` is the one place
where a design's kind is asked, so the scan, its kernels and the restoration hold no
branch on it.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..analysis.paraxial import PARAXIAL_MAX_SLOPE, paraxial_max_slope
from ..design import AnyDesign, RodLensDesign
from ..raytrace.stack import lattice_of, output_pitch
from .kernels import ScanKernel, stamp_kernel_sets
from .rodkernels import phase_of, rod_kernel_sets


@dataclass(frozen=True)
class PixelGroup:
    """Pixels that share one kernel: their x centres, the sensor y of their row, the line
    delay of their row, and the index of their kernels in ``scan_kernels``' output."""

    x_um: np.ndarray
    y_um: float
    delay: int
    kernel: int


class Stamp:
    """An aperture-array stamp: rows of used pixels, each row one kernel."""

    #: why its scans cannot be restored (None: they can)
    not_restorable: str | None = None

    def pitch(self, design) -> float:
        """Output pixel pitch (um): the merged line's."""
        return output_pitch(design)

    def groups(self, design, n_cols: int) -> list[PixelGroup]:
        """Its rows of used pixels (row B delayed by row offset / pitch lines)."""
        pitch = self.pitch(design)
        lat = lattice_of(design)
        n_rows = design.sensor.rows
        delay = int(round(lat.row_y[1] / pitch)) if n_rows == 2 else 0
        out = []
        for r in range(n_rows):
            n_k = n_cols // n_rows + 1
            x_pix = lat.row_x[r] % lat.pitch + np.arange(n_k) * lat.pitch + pitch / 2
            out.append(PixelGroup(x_pix[x_pix < n_cols * pitch], lat.row_y[r], delay * r, r))
        return out

    def kernel_source(self, design, source: str, fresnel: bool) -> str:
        """ "paraxial", "trace" or "wave" (see
        :func:`~opticalstamp.imaging.kernels.scan_kernels`)."""
        rect = all(m.shape != "circle" for m in design.masks)
        if source == "auto":  # the closed form where it holds: rectangles, paraxial own path
            steep = paraxial_max_slope(design) > PARAXIAL_MAX_SLOPE if rect else True
            source = "paraxial" if rect and not fresnel and not steep else "trace"
        if source not in ("paraxial", "trace", "wave"):
            raise ValueError(
                f"kernel source must be auto, paraxial, trace or wave (got {source!r})"
            )
        if source == "wave":
            from ..analysis.responsivity import wave_unavailable

            # asked for: circles' maps too; a colour scanner's by its grey light
            why = wave_unavailable(design, maps=False, channels=True)
            if why is not None:
                raise ValueError(f"wave kernels: {why}")
        if source == "paraxial" and not rect:
            raise ValueError("paraxial kernels need rectangular holes (this design has circles)")
        return source

    def kernel_sets(
        self, design, z_sets, source, ghosts, fresnel, n_rays, seed, progress, tracer
    ) -> list[list[list[ScanKernel]]]:
        """Kernels [set][row][level], from one trace per row."""
        return stamp_kernel_sets(
            design, z_sets, source, ghosts, fresnel, n_rays, seed, progress, tracer
        )


class RodLensArray:
    """A rod-lens array: one sensor row whose pixels sit at varying phases of the rods."""

    not_restorable: str | None = (
        "a rod-lens array's pixels sit at varying phases of its rod lattice"
    )

    def pitch(self, design) -> float:
        """Output pixel pitch (um): the sensor's."""
        return design.output_pitch_um

    def groups(self, design, n_cols: int) -> list[PixelGroup]:
        """Its pixels' phase classes on the rod lattice (classes without a pixel left out)."""
        x = (np.arange(n_cols) + 0.5) * self.pitch(design)
        cls = phase_of(design, x)
        return [PixelGroup(x[cls == g], 0.0, 0, int(g)) for g in np.unique(cls)]

    def kernel_source(self, design, source: str, fresnel: bool) -> str:
        """Always "trace": a rod-lens array has no closed form."""
        if source not in ("auto", "trace"):
            raise ValueError(f"a rod-lens array's kernels are traced (got source {source!r})")
        return "trace"

    def kernel_sets(
        self, design, z_sets, source, ghosts, fresnel, n_rays, seed, progress, tracer
    ) -> list[list[list[ScanKernel]]]:
        """Kernels [set][phase class][level], from one trace (no ghost path; its GRIN
        tracer takes no pixel tracer)."""
        return rod_kernel_sets(
            design, z_sets, fresnel=fresnel, n_rays=n_rays, seed=seed, progress=progress
        )


STAMP = Stamp()
ROD_LENS_ARRAY = RodLensArray()


def scanner_of(design: AnyDesign) -> Stamp | RodLensArray:
    """The kind of ``design``, as a scan sees it."""
    return ROD_LENS_ARRAY if isinstance(design, RodLensDesign) else STAMP
