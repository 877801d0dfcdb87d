"""Each pixel traced once, checked on a report the suite runs anyway: a spy on every
launch from a pixel source in the process, and the check of a report's pass count
(``build_report(passes=)``) against it and against the report's work description.

Used by the full report of tests/test_report.py and the quick report of
tests/test_report_speed_paths.py (each had been run a second time, in
tests/test_trace_once.py, only to be counted)."""

from __future__ import annotations

import numpy as np

from opticalstamp.defaults import RAYS_LSF
from opticalstamp.imaging.kernels import _rays as traced_kernel_rays
from opticalstamp.raytrace import pixel as pixel_module
from opticalstamp.raytrace.pixel import PILOT_RAYS, PixelTracer
from opticalstamp.report import build


def spy_and_count(monkeypatch):
    """Install, on ``monkeypatch``: a spy on every launch from a pixel source in this
    process, however it is reached; a record of the work description the report asks
    for; a pass count handed to every ``build_report``. Returns (launches, works,
    passes), filled as the report runs."""
    from opticalstamp.raytrace.passes import TracePasses

    seen, works, passes = [], [], TracePasses()
    launch, work, report = pixel_module.launch, build.report_work, build.build_report

    def spied(path, src, n, seed, **kw):
        seen.append((path, src, kw.get("stream", 0), kw.get("first_id", 0), n))
        return launch(path, src, n, seed, **kw)

    def recorded(*args, **kwargs):
        works.append(work(*args, **kwargs))
        return works[-1]

    monkeypatch.setattr(pixel_module, "launch", spied)
    monkeypatch.setattr(build, "report_work", recorded)
    monkeypatch.setattr(build, "build_report", lambda *a, **k: report(*a, passes=passes, **k))
    return seen, works, passes


def assert_each_pixel_traced_once(design, seen, work, passes, kernels: str = "wave") -> None:
    """Every stream of every used pixel of ``design`` traced once: the analyses' rays
    (stream 0), the hole pilot (1) and the spots' own sizing pilot (2, pixel A only),
    under one sampling; a stream holds as many rays as its most demanding analysis asks
    for (not their sum); and the count is complete: every launch of the design's pixels
    in this process went through the report's tracer, none overlapping another of its
    stream. ``kernels``: the scan kernels' source (wave kernels trace only the light
    beyond the wave band, on fewer rays)."""
    mine = [k for k in passes.keys() if k.design == design.fingerprint()]
    rows = {(r, 0) for r in range(design.sensor.rows)}
    assert {k: passes.passes(k) for k in mine} == {k: 1 for k in mine}
    assert {(k.pixel, k.stream) for k in mine} == {(p, s) for p in rows for s in (0, 1)} | {
        ((0, 0), 2)
    }
    assert {(k.seed, k.fresnel) for k in mine} == {(0, False)}
    got = {(k.pixel, k.stream): passes.rays(k) for k in mine}
    # pixel A's stream: the ghost analysis, spots, LSFs, scan kernels, ray-vs-wave and the
    # wave light (RAYS_LSF); pixel B's: the LSFs, kernels and ray-vs-wave
    asked_a = (work.ghost_rays, work.map_rays, work.concept_rays, work.lsf_rays)
    kernel_rays = traced_kernel_rays(kernels, work.kernel_rays)
    assert got[(0, 0), 0] == max(*asked_a, kernel_rays, work.wave_rays, RAYS_LSF)
    assert got[(1, 0), 0] == max(work.lsf_rays, kernel_rays, work.wave_rays)
    assert got[(0, 0), 1] == got[(1, 0), 1] == got[(0, 0), 2] == PILOT_RAYS
    # the spy sees the other designs' launches too (the single-row concept on the same
    # stack, the larger sensitive area): only this design's pixels are counted
    proto = PixelTracer(design).path

    def is_design(path, src) -> bool:
        return (
            np.array_equal(path.slabs, proto.slabs)
            and np.array_equal(path.masks, proto.masks)
            and np.array_equal(path.lattice.as_array(), proto.lattice.as_array())
            and src.width == design.sensor.sensitive_width_um
            and src.height == design.sensor.sensitive_height_um
        )

    spans: dict = {}
    for path, src, stream, first, n in seen:
        if is_design(path, src):
            spans.setdefault((round(src.x, 6), round(src.y, 6), stream), []).append((first, n))
    assert sum(n for v in spans.values() for _, n in v) == sum(passes.rays(k) for k in mine), (
        spans,
        {(k.pixel, k.stream): passes.spans(k) for k in mine},
    )
    for v in spans.values():
        v.sort()
        assert all(a + n <= b for (a, n), (b, _) in zip(v, v[1:], strict=False)), v
