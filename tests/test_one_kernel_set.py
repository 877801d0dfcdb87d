"""Scan to restore on one kernel set (issue 22): ``scan --restore`` builds the scan's
kernels once and restores with them; ``restore_scan(kernels=)`` gives what it gives when
it builds its own; the heights are checked in one place; the two kinds of design answer
one interface."""

from __future__ import annotations

import numpy as np
import pytest
from tests.edges import run

from opticalstamp.design import load_design
from opticalstamp.imaging import heightmap, kinds, restore
from opticalstamp.imaging.charts import bar_chart
from opticalstamp.imaging.scan import (
    ScanSettings,
    pixel_groups,
    prepare_kernels,
    scan_pitch,
    simulate_scan,
)


@pytest.fixture(scope="module")
def paper():
    return load_design("paper2016")


@pytest.fixture(scope="module")
def bars(paper):
    """A bar chart scanned at 2 mm, with the kernels it was scanned with."""
    doc = bar_chart(1200, chart_dpi=(200,), block_mm=2.0, height_mm=2.0)
    st = ScanSettings(sensor=paper.electronics)
    cache = prepare_kernels(paper, z_mm=(2.0,), height_maps=(np.full((3, 3), 2.0),), settings=st)
    scan = simulate_scan(doc, 1200, paper, z_mm=2.0, settings=st, kernels=cache)
    return scan, st, cache


def test_restoring_with_the_scans_kernels_is_restoring_with_new_ones(paper, bars):
    scan, st, cache = bars
    for method in ("wiener", "rl"):
        kw = {"method": method, "settings": st, "iterations": 5}
        a = restore.restore_scan(scan.image, paper, z_mm=2.0, kernels=cache, **kw)
        b = restore.restore_scan(scan.image, paper, z_mm=2.0, **kw)
        assert np.array_equal(a.image, b.image) and a.meta == b.meta
    hm = np.full((3, 3), 2.0)
    a = restore.restore_scan(scan.image, paper, height_map=hm, settings=st, kernels=cache)
    b = restore.restore_scan(scan.image, paper, height_map=hm, settings=st)
    assert np.array_equal(a.image, b.image)


def test_kernels_that_do_not_fit_are_refused(paper, bars):
    scan, st, cache = bars
    with pytest.raises(ValueError, match="kernels: built for seed 0, not 1"):
        restore.restore_scan(scan.image, paper, z_mm=2.0, settings=st, seed=1, kernels=cache)
    with pytest.raises(ValueError, match=r"kernels: none built for the levels \[3.0\]"):
        restore.restore_scan(scan.image, paper, z_mm=3.0, settings=st, kernels=cache)


def test_scan_restore_builds_the_kernels_once(tmp_path, monkeypatch):
    """The CLI's ``scan --restore``: one build of the kernels (it was two), and the
    restoration it writes is the one a restoration building its own kernels gives."""
    builds, restored = [], []
    build, restore_scan = kinds.stamp_kernel_sets, restore.restore_scan

    def counting(*a, **kw):
        builds.append(a[1])  # the sets of distances
        return build(*a, **kw)

    def keeping(image, design, **kw):
        r = restore_scan(image, design, **kw)
        restored.append((image, design, kw, r))
        return r

    monkeypatch.setattr(kinds, "stamp_kernel_sets", counting)
    monkeypatch.setattr(restore, "restore_scan", keeping)
    page = tmp_path / "bars.png"
    assert run(["chart", "bars", "-o", page]).exit_code == 0
    for no_ghosts in ([], ["--no-ghosts"]):
        builds.clear()
        restored.clear()
        out = tmp_path / f"s{len(no_ghosts)}.tif"
        res = run(["scan", page, "-o", out, "--z", "2.5", "--restore", "wiener", *no_ghosts])
        assert res.exit_code == 0, res.output
        assert builds == [[(2.5,)]]  # one build, for the one height
        ((image, design, kw, r),) = restored
        assert kw["kernels"] is not None and kw["z_mm"] == 2.5
        again = restore_scan(image, design, **(kw | {"kernels": None}))
        assert np.array_equal(r.image, again.image)


def test_heights_are_checked_in_one_place(paper):
    doc = np.ones((64, 64))
    for bad in (-0.5, 10.5, float("nan")):
        with pytest.raises(ValueError, match=r"z_mm: must lie in \[0, 10\] mm"):
            heightmap.check_heights(bad, None)
        with pytest.raises(ValueError, match="z_mm: must lie in"):
            simulate_scan(doc, 600, paper, z_mm=bad)
        with pytest.raises(ValueError, match="z_mm: must lie in"):
            prepare_kernels(paper, z_mm=(bad,))
        with pytest.raises(ValueError, match="z_mm: must lie in"):
            restore.restore_scan(doc, paper, z_mm=bad)
    hm = np.full((3, 3), 11.0)
    for call in (
        lambda: simulate_scan(doc, 600, paper, height_map=hm),
        lambda: prepare_kernels(paper, height_maps=(hm,)),
        lambda: restore.restore_scan(doc, paper, height_map=hm),
    ):
        with pytest.raises(heightmap.HeightMapError, match="outside the modelled range"):
            call()


def test_both_kinds_answer_one_interface(paper):
    rod = load_design("sla-1row-12deg")
    assert kinds.scanner_of(paper) is kinds.STAMP
    assert kinds.scanner_of(rod) is kinds.ROD_LENS_ARRAY
    assert (
        kinds.STAMP.not_restorable is None and "rod lattice" in kinds.ROD_LENS_ARRAY.not_restorable
    )
    # the stamp: its two rows, row B delayed by its offset over the merged pitch
    p = scan_pitch(paper)
    assert p == pytest.approx(84.6)  # the prototype's merged 300-dpi line
    a, b = pixel_groups(paper, 40)
    assert (a.kernel, b.kernel, a.delay, b.delay) == (0, 1, 0, 1)  # row B: 84.6 um later
    assert np.allclose(np.diff(a.x_um), 2 * p) and np.allclose(b.x_um - a.x_um[: b.x_um.size], p)
    assert a.x_um.size + b.x_um.size == 40  # every output column, once
    # the rod-lens array: one row, its columns sorted into phase classes
    groups = pixel_groups(rod, 64)
    assert sum(g.x_um.size for g in groups) == 64 and {g.delay for g in groups} == {0}
    assert scan_pitch(rod) == rod.output_pitch_um
    assert kinds.ROD_LENS_ARRAY.kernel_source(rod, "auto", False) == "trace"
    with pytest.raises(ValueError, match="rod-lens array's kernels are traced"):
        kinds.ROD_LENS_ARRAY.kernel_source(rod, "paraxial", False)
    with pytest.raises(ValueError, match="stamps; a rod-lens array's pixels"):
        restore.output_kernel(rod, 1.0)
