"""Stacks of any number of mask layers: ghosts, RMTF and spots with 5 and 6 masks.

The physics check: a mask added between two masks of the paper's prototype, in the same
medium, with a hole at least as large as both neighbours' holes, never clips an own-path
ray (a straight line between two points inside two convex holes stays inside their
convex hull). So the 5- and 6-mask stacks built that way have the prototype's own path,
ray for ray; only ghost light can be blocked by the extra masks. A mask doubled by a
slightly larger twin 0.1 um above it (the shortest slab a design takes) blocks nothing at
all: the ghost paths are the prototype's, each listed with the twin's hole equal to its
original's.
"""

from __future__ import annotations

import numpy as np
import pytest

from helpers import assert_agree, preset_dict
from opticalstamp.analysis.ghosts import analyse_ghosts
from opticalstamp.analysis.rmtf import rmtf
from opticalstamp.analysis.spots import spots
from opticalstamp.design import design_from_dict, load_design
from opticalstamp.raytrace.launch import RayBatch, launch
from opticalstamp.raytrace.pixel import pixel_source
from opticalstamp.raytrace.stack import reverse_path
from opticalstamp.raytrace.tally import OWN_PATH, PathRegistry, is_own_path


def _slab(medium, thickness_um: float, name: str, size_um: float) -> dict:
    mask = {"name": name, "shape": "square", "size_um": size_um}
    return {"medium": medium, "thickness_um": thickness_um, "mask_top": mask}


def split_prototype(n_masks: int):
    """paper2016 with extra masks inside its gaps (5: both plates split; 6: air gap too).

    The extra holes (44 um in the air gap, 42 um in plate L2, 50 um in plate L1) are larger
    than the holes above and below them and than the 42.3 um pixel.
    """
    data = preset_dict("paper2016")
    slabs = []
    if n_masks == 6:
        slabs += [_slab("air", 225.0, "extra air", 44.0), _slab("air", 225.0, "layer 3", 40.0)]
    else:
        slabs += [_slab("air", 450.0, "layer 3", 40.0)]
    slabs += [_slab(1.52, 200.0, "extra L2", 42.0), _slab(1.52, 200.0, "layer 2", 40.0)]
    slabs += [_slab(1.52, 500.0, "extra L1", 50.0), _slab(1.52, 500.0, "layer 1", 48.0)]
    data["slabs"] = slabs
    data["name"] = f"split-{n_masks}"
    design = design_from_dict(data)
    assert len(design.masks) == n_masks
    return design


PROTO = load_design("paper2016")


@pytest.mark.parametrize("n_masks", [5, 6])
def test_own_path_is_the_prototypes_ray_by_ray(n_masks):
    # plain Lambertian sampling draws the same rays (seed, ray index) whatever the stack
    design = split_prototype(n_masks)
    own = {}
    for d in (PROTO, design):
        path = reverse_path(d)
        src = pixel_source(d, 0, 0)
        ids, w = [], []
        for b in launch(path, src, 1 << 21, 3, importance=False):
            o = is_own_path(b, 0, 0)
            ids.append(b.ids[o])
            w.append(b.w[o])
        own[d.name] = (np.concatenate(ids), np.concatenate(w))
    (ids3, w3), (ids_n, w_n) = own["paper2016"], own[design.name]
    assert ids3.size > 100
    np.testing.assert_array_equal(ids3, ids_n)
    np.testing.assert_array_equal(w3, w_n)


def twin_prototype(n_masks: int):
    """paper2016 with each of its top ``n_masks - 3`` masks doubled 0.1 um above itself.

    The twin holes are 0.2 um larger; over 0.1 um of glass (n = 1.52) no ray that left the
    pixel's air gap drifts by more than 0.1 um tan(asin(1 / 1.52)) = 0.087 um, so a ray
    passes a twin exactly when it passes the mask below it: the stack
    has the prototype's own path and ghost paths, ray for ray, with those holes listed
    twice. The first mask and the slabs below it are the prototype's, so importance
    sampling draws the same rays.
    """
    eps = 0.1  # MIN_LENGTH_UM: the shortest slab a design takes
    stack = [("air", 450.0, "layer 3", 40.0), (1.52, 400.0, "layer 2", 40.0)]
    stack += [(1.52, 1000.0, "layer 1", 48.0)]
    doubled = [name for *_, name, _ in stack][6 - n_masks :]
    slabs = []
    for medium, t, name, size in stack:
        if slabs and slabs[-1]["mask_top"]["name"].startswith("twin"):
            t -= eps  # the twin's slab is cut from this plate
        slabs.append(_slab(medium, t, name, size))
        if name in doubled:
            slabs.append(_slab(1.52, eps, f"twin {name}", size + 0.2))
    data = preset_dict("paper2016")
    data["slabs"] = slabs
    data["name"] = f"twins-{n_masks}"
    design = design_from_dict(data)
    assert len(design.masks) == n_masks
    return design


@pytest.fixture(scope="module")
def proto_ghosts():
    return analyse_ghosts(PROTO, n_rays=1 << 20, seed=4)


@pytest.mark.parametrize("n_masks", [5, 6])
def test_interior_masks_block_ghosts_only(n_masks, proto_ghosts):
    design = split_prototype(n_masks)
    g = analyse_ghosts(design, n_rays=1 << 20, seed=4)
    p = proto_ghosts
    assert_agree(g.etendue_own_um2sr, g.etendue_own_se, p.etendue_own_um2sr, p.etendue_own_se)
    # a mask inside each plate stops the grazing chains (paper §2: more layers, fewer ghosts)
    assert g.etendue_ghost_um2sr < 0.01 * p.etendue_ghost_um2sr


@pytest.mark.parametrize("n_masks", [5, 6])
def test_twin_masks_give_the_prototypes_paths(n_masks, proto_ghosts):
    design = twin_prototype(n_masks)
    g = analyse_ghosts(design, n_rays=1 << 20, seed=4)
    p = proto_ghosts
    assert_agree(g.etendue_own_um2sr, g.etendue_own_se, p.etendue_own_um2sr, p.etendue_own_se)
    assert_agree(
        g.etendue_ghost_um2sr, g.etendue_ghost_se, p.etendue_ghost_um2sr, p.etendue_ghost_se
    )
    # the same rays: equal to rounding, and the same ghost paths with every twin's hole
    # equal to the hole of the mask it doubles
    assert g.etendue_own_um2sr == pytest.approx(p.etendue_own_um2sr, rel=1e-12)
    assert g.ghost_fraction == pytest.approx(p.ghost_fraction, rel=1e-12)
    names = [m.name for m in design.masks][::-1]
    assert len(g.paths) == len(p.paths) > 10
    for q, r in zip(g.paths, p.paths, strict=True):
        assert [h["mask"] for h in q.holes] == names
        by_mask = {h["mask"]: (h["row"], h["dk"]) for h in q.holes}
        for h in q.holes:
            if h["mask"].startswith("twin "):
                assert (h["row"], h["dk"]) == by_mask[h["mask"].removeprefix("twin ")]
        assert [h for h in q.holes if not h["mask"].startswith("twin")] == r.holes
        assert q.etendue_um2sr == pytest.approx(r.etendue_um2sr, rel=1e-12)
        assert q.n_rays == r.n_rays
    assert sum(q.etendue_um2sr for q in g.paths) == pytest.approx(g.etendue_ghost_um2sr)


@pytest.mark.parametrize("n_masks", [5, 6])
def test_rmtf_of_split_stacks(n_masks):
    design = split_prototype(n_masks)
    z = (0.0, 1.0, 2.0)
    # paraxial closed form of the own path: the extra masks are never binding
    a = rmtf(PROTO, z_mm=z, method="paraxial")
    b = rmtf(design, z_mm=z, method="paraxial")
    for key, vals in a.rmtf_max.items():
        np.testing.assert_allclose(b.rmtf_max[key], vals, rtol=1e-9, atol=1e-12)
    # exact tracer, own path only: the same curves within standard errors
    t3 = rmtf(PROTO, z_mm=z, ghosts=False, n_rays=1 << 20, seed=2)
    tn = rmtf(design, z_mm=z, ghosts=False, n_rays=1 << 20, seed=2)
    for key in t3.rmtf_max:
        for v3, s3, vn, sn in zip(
            t3.rmtf_max[key],
            t3.rmtf_max_se[key],
            tn.rmtf_max[key],
            tn.rmtf_max_se[key],
            strict=True,
        ):
            assert abs(vn - v3) <= 5.0 * np.hypot(sn, s3) + 1e-9, (key, vn, sn, v3, s3)
    # with ghosts it runs and gives a depth of field
    g = rmtf(design, z_mm=z, n_rays=1 << 19)
    assert np.isfinite(g.dof_mm["200"])


@pytest.mark.parametrize("n_masks", [5, 6])
def test_spots_of_split_stacks(n_masks):
    design = split_prototype(n_masks)
    z = (0.0, 2.0)
    a = spots(PROTO, z_mm=z, n_rays=1 << 20, seed=1, ghosts=False)
    b = spots(design, z_mm=z, n_rays=1 << 20, seed=1, ghosts=False)
    for sa, sb in zip(a.spots, b.spots, strict=True):
        # own-path spots: same support and the same etendue, within sampling noise
        assert sb.extent_x_um == pytest.approx(sa.extent_x_um, abs=2.0)
        assert sb.extent_y_um == pytest.approx(sa.extent_y_um, abs=2.0)
        assert sb.fwhm_x_um == pytest.approx(sa.fwhm_x_um, abs=4.0)
        assert sb.map_sr.sum() == pytest.approx(sa.map_sr.sum(), rel=0.01)
        assert sb.center_cell_fraction == pytest.approx(sa.center_cell_fraction, abs=0.01)
    assert spots(design, z_mm=z, n_rays=1 << 18).spots[0].map_sr.sum() > 0


# -- the path registry ---------------------------------------------------------------------
def _batch(hole_row, hole_k) -> RayBatch:
    hole_row = np.asarray(hole_row, np.int8)
    hole_k = np.asarray(hole_k, np.int32)
    n = hole_row.shape[0]
    z = np.zeros(n)
    return RayBatch(
        np.arange(n), z, z, z, z, z + 1, hole_row, hole_k, np.zeros((1, 4), np.int64), n, n
    )


def test_registry_round_trip_large_offsets_many_masks():
    rng = np.random.default_rng(0)
    n, nm, row, k = 5000, 7, 1, 123_456
    hk = k + rng.choice([-1_000_000, -5000, -2048, -1, 0, 2047, 2048, 3000, 2**30], (n, nm))
    hr = rng.integers(0, 2, (n, nm))
    hk[:10] = k  # some own-path rays
    hr[:10] = row
    b = _batch(hr, hk)
    reg = PathRegistry(nm, row, k)
    ids = reg.ids(b)
    assert ids.dtype == np.int64
    np.testing.assert_array_equal(ids == OWN_PATH, is_own_path(b, row, k))
    for i in range(n):
        seq = reg.decode(int(ids[i]))
        assert seq == [(int(hr[i, m] != row), int(hk[i, m] - k)) for m in range(nm)]
    # equal sequences share an id, distinct ones do not
    per = np.concatenate([hr != row, hk - k], axis=1)
    n_distinct = np.unique(per, axis=0).shape[0]
    assert np.unique(ids).size == n_distinct
    # ids are stable across batches: a second batch re-uses them and adds new ones
    ids2 = reg.ids(_batch(hr[::-1], hk[::-1]))
    np.testing.assert_array_equal(ids2, ids[::-1])
    assert len(reg) == n_distinct + (0 if np.any(ids == OWN_PATH) else 1)


def test_registry_orders_new_paths_like_the_old_codes():
    # within a batch, new sequences are numbered in lexicographic order of (dk, other row)
    # from the top mask down (the order of the former bit-packed codes)
    hr = [[0, 0, 0], [0, 1, 0], [0, 0, 0], [1, 0, 0], [0, 0, 0]]
    hk = [[5, 0, 0], [0, 0, -3], [0, 0, 0], [0, 0, -3], [0, 0, 7]]
    reg = PathRegistry(3, 0, 0)
    ids = reg.ids(_batch(hr, hk))
    assert ids.tolist() == [3, 2, OWN_PATH, 1, 4]
    assert reg.decode(1) == [(1, 0), (0, 0), (0, -3)]
    assert reg.ids(_batch(np.zeros((0, 3)), np.zeros((0, 3)))).size == 0
    with pytest.raises(ValueError, match="masks"):
        reg.ids(_batch([[0, 0]], [[0, 0]]))
