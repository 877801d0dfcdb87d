"""Design search, tolerancing and their execution (process pool, Dask, journal)."""

from __future__ import annotations

import json
import os
import signal
import time

import numpy as np
import pytest
import xarray as xr
from typer.testing import CliRunner

from opticalstamp.analysis.ghosts import analyse_ghosts
from opticalstamp.analysis.rmtf import rmtf
from opticalstamp.cli.common import app
from opticalstamp.design import load_design, scale_to_dpi, with_stack
from opticalstamp.io.journal import JournalWarning, read_journal
from opticalstamp.studies.evaluate import evaluate_design, rmtf_with_background
from opticalstamp.studies.runner import run_tasks, task_key
from opticalstamp.studies.search import pareto_front, search
from opticalstamp.studies.tolerance import apply_errors, draw_errors, parse_spec, tolerance

runner = CliRunner()


@pytest.fixture(scope="module")
def paper():
    return load_design("paper2016")


def test_evaluation_agrees_with_the_full_models(paper):
    """The search's cheap evaluation against the exact tracer's RMTF with ghost light."""
    m = evaluate_design(paper, ghost_rays=1 << 19)
    full = rmtf(paper, dpi=(200.0,), z_mm=(1.0, 2.0, 3.0), n_rays=1 << 21)
    for z, v in zip((1.0, 2.0, 3.0), full.rmtf_max["200"], strict=True):
        assert m["rmtf_at"][f"{z:g}"] == pytest.approx(v, abs=0.02)
    g = analyse_ghosts(paper, n_rays=1 << 20)
    assert m["ghost_fraction"] == pytest.approx(g.ghost_fraction, abs=0.01)
    assert not m["near_ghost"] and m["nearest_ghost_mm"] > 5
    # a uniform background B lowers a fully resolved chart to G / (G + B)
    r = rmtf_with_background(paper, 100.0, [0.0], 1.0)
    assert r[0] == pytest.approx(m["etendue_own_um2sr"] / (m["etendue_own_um2sr"] + 1.0), abs=1e-3)


def test_pareto_front():
    pts = np.array([[1, 1], [2, 0.5], [0.5, 2], [0.9, 0.9], [2, 0.5]])
    assert set(pareto_front(pts).tolist()) == {0, 1, 2, 4}


def _square(x: float) -> dict:
    return {"y": x["v"] ** 2}


def _fails_on_three(p: dict) -> dict:
    if p["v"] == 3:
        raise RuntimeError("three is not allowed")
    return {"y": p["v"]}


def _dies_on_two(p: dict) -> dict:
    if p["v"] == 2:
        os._exit(3)  # a worker that dies
    return {"y": p["v"]}


def test_journal_resume_and_failures(tmp_path):
    j = tmp_path / "j.jsonl"
    tasks = [(task_key({"v": v}), {"v": v}) for v in range(5)]
    out = run_tasks(_fails_on_three, tasks, workers=1, journal=j, retries=1)
    assert [r["ok"] for r in out.values()] == [True, True, True, False, True]
    bad = out[tasks[3][0]]
    assert "three is not allowed" in bad["error"] and bad["payload"] == {"v": 3}
    assert bad["attempts"] == 2
    # a rerun does not redo finished (or marked) evaluations
    calls = []
    again = run_tasks(lambda p: calls.append(p) or {"y": 0}, tasks, workers=1, journal=j)
    assert calls == [] and again == out
    # a truncated last line (a kill during a write) is ignored and that task is redone
    j.write_text(j.read_text() + '{"key": "abc", "payl')
    with pytest.warns(JournalWarning, match="line 6"):
        assert len(read_journal(j)) == 5


def test_process_pool_survives_a_dying_worker(tmp_path):
    tasks = [(task_key({"v": v}), {"v": v}) for v in range(4)]
    out = run_tasks(_dies_on_two, tasks, workers=2, journal=tmp_path / "j.jsonl", retries=1)
    ok = {r["payload"]["v"]: r["ok"] for r in out.values()}
    assert ok == {0: True, 1: True, 2: False, 3: True}
    assert "died" in out[tasks[2][0]]["error"]


def _pid(p: dict) -> dict:
    return {"y": p["v"], "pid": os.getpid()}


def test_a_worker_pool_kept_across_calls(tmp_path):
    """A search's generations share one pool of processes (a pool per generation cost
    more than the generation): the same processes serve two calls, none of them this
    one; a worker that dies fails only its own task and the next call gets new
    processes; leaving the block ends them."""
    from opticalstamp.studies.runner import WorkerPool

    def tasks(vs):
        return [(task_key({"v": v}), {"v": v}) for v in vs]

    with WorkerPool(2) as pool:
        first = run_tasks(_pid, tasks(range(6)), pool=pool)
        second = run_tasks(_pid, tasks(range(6, 12)), pool=pool)
        pids = {r["result"]["pid"] for r in [*first.values(), *second.values()]}
        assert len(pids) <= 2 and os.getpid() not in pids
        assert [r["result"]["y"] for r in second.values()] == list(range(6, 12))
        ex = pool.executor()
        out = run_tasks(_dies_on_two, tasks(range(4)), pool=pool, retries=1)
        ok = {r["payload"]["v"]: r["ok"] for r in out.values()}
        assert ok == {0: True, 1: True, 2: False, 3: True}
        assert pool.executor() is not ex  # the broken pool was replaced
        again = run_tasks(_pid, tasks(range(20, 24)), pool=pool)
        assert all(r["ok"] for r in again.values())
        last = {r["result"]["pid"] for r in again.values()}
        assert not last & pids
        os.kill(next(iter(last)), signal.SIGKILL)  # a worker killed while the pool idles
        time.sleep(1.0)
        after = run_tasks(_pid, tasks(range(30, 34)), pool=pool)
        assert [r["ok"] for r in after.values()] == [True] * 4  # on new processes
        last = {r["result"]["pid"] for r in after.values()}
    for pid in last:  # ended (and reaped) on leaving the block
        with pytest.raises(ProcessLookupError):
            os.kill(pid, 0)


@pytest.fixture(scope="module")
def dask_cluster():
    distributed = pytest.importorskip("distributed")
    cluster = distributed.LocalCluster(
        n_workers=2, threads_per_worker=1, processes=True, host="127.0.0.1", dashboard_address=None
    )
    yield cluster.scheduler_address
    cluster.close()


def test_search_same_for_any_workers_and_on_dask(paper, dask_cluster, tmp_path):
    kw = dict(dpi=300.0, population=8, generations=2, seed=3, ghost_rays=1 << 15)
    one = search(paper, workers=1, **kw)
    two = search(paper, workers=2, **kw)
    dsk = search(paper, dask_address=dask_cluster, journal=tmp_path / "d.jsonl", **kw)
    key = [
        (r["holes_um"], r["thicknesses_um"], r["dof_mm"], r["efficiency_ratio"])
        for r in one.records
    ]
    assert key == [
        (r["holes_um"], r["thicknesses_um"], r["dof_mm"], r["efficiency_ratio"])
        for r in two.records
    ]
    assert key == [
        (r["holes_um"], r["thicknesses_um"], r["dof_mm"], r["efficiency_ratio"])
        for r in dsk.records
    ]
    assert one.reference["holes_um"] == [48.0, 40.0, 40.0]
    # the warm start puts the paper's design in the first generation
    assert any(
        r["holes_um"] == [48.0, 40.0, 40.0] and r["thicknesses_um"] == [1000.0, 400.0, 450.0]
        for r in one.records
    )
    # resuming from the Dask run's journal evaluates nothing new
    again = search(paper, dask_address="tcp://127.0.0.1:1", journal=tmp_path / "d.jsonl", **kw)
    assert [r["dof_mm"] for r in again.records] == [r["dof_mm"] for r in dsk.records]


def test_pins_and_bad_pins(paper):
    r = search(
        paper,
        population=8,
        generations=1,
        pinned={"hole1": 48, "slab1": 1000.0},
        ghost_rays=1 << 15,
        workers=1,
    )
    assert all(x["holes_um"][0] == 48 and x["thicknesses_um"][0] == 1000 for x in r.records)
    with pytest.raises(ValueError, match="unknown variables"):
        search(paper, population=8, generations=1, pinned={"hole9": 1}, workers=1)


def test_scale_to_dpi_scales_the_sensor(paper):
    d600 = scale_to_dpi(paper, 600.0)
    assert d600.sensor.row_pitch_um / 2 == pytest.approx(42.3, rel=2e-3)
    assert d600.masks[-1].hole_width_um == pytest.approx(24.0, abs=0.1)
    assert [sl.thickness_um for sl in d600.slabs] == [450.0, 400.0, 1000.0]


def test_errors_are_applied_and_reproducible(paper):
    e = draw_errors(
        paper, 7, 1, {"misregistration_um": 3, "hole_um": 1, "thickness_um": 10, "tilt_deg": 0.0}
    )
    assert e == draw_errors(
        paper, 7, 1, {"misregistration_um": 3, "hole_um": 1, "thickness_um": 10, "tilt_deg": 0.0}
    )
    d = apply_errors(paper, {"dx1": 2.5, "hole2": -1.0, "slab2": 20.0})
    assert d.masks[-1].offset_x_um == 2.5  # layer 1 = object side
    assert d.masks[1].hole_width_um == 39.0 and d.slabs[1].thickness_um == 420.0
    tilted = apply_errors(paper, {"tilt": 0.01})
    assert tilted.slabs[0].thickness_um == pytest.approx(
        450 + 620 * 169.2 * np.tan(np.radians(0.01)), rel=1e-3
    )
    with pytest.raises(ValueError, match="spec"):
        parse_spec("dof>2")


def test_misregistration_lowers_rmtf_on_average(paper):
    """Paper §5: misalignment of the plates lowers the contrast (never raises it on
    average): shifting layer 3 by 3 um lowers RMTF(200 dpi) at every Z."""
    nominal = evaluate_design(paper, ghost_rays=1 << 15)
    shifted = evaluate_design(
        with_stack(paper, offsets_um=[(0, 0), (0, 0), (3.0, 0)]), ghost_rays=1 << 15
    )
    for z, v in nominal["rmtf_at"].items():
        assert shifted["rmtf_at"][z] < v


def test_tolerance_study(paper, tmp_path):
    r = tolerance(
        paper,
        samples=12,
        spec="dof>=2.0,ghost<=0.3",
        workers=1,
        ghost_rays=1 << 15,
        journal=tmp_path / "t.jsonl",
    )
    d = r.to_dict()
    assert set(d["rmtf200"]) == {"0.5", "1", "2", "3", "3.5"}
    assert d["dof_mm"]["p5"] <= d["dof_mm"]["p50"] <= d["dof_mm"]["p95"]
    assert 0 <= d["yield"] <= 1 and d["n_failed"] == 0
    names = [row["error"] for row in d["sensitivity"]]
    assert "dx1" in names and "slab3" in names and "tilt" in names
    zero = tolerance(
        paper,
        samples=3,
        sigmas={"misregistration_um": 0, "hole_um": 0, "thickness_um": 0, "tilt_deg": 0},
        workers=1,
        ghost_rays=1 << 15,
    )
    assert all(s["dof_mm"] == zero.nominal["dof_mm"] for s in zero.samples)


def test_cli_search_and_tolerance_write_netcdf(tmp_path):
    """The CLI's search and tolerance study write their NetCDF with provenance. By ray
    optics (--optics ray: the surrogate, the front verified by the exact tracer), a
    fifth of the wave estimator's time: what is checked here (the front's fields, the
    files, their attributes and sizes) is the same by either optics; the CLI by wave
    optics (auto on the prototype) is run by test_artwork_files.py, test_back_from_search.py
    (search) and test_tolerance_optics.py::test_cli_optics (tolerance)."""
    out = tmp_path / "s.nc"
    res = runner.invoke(
        app,
        [
            "search",
            "--dpi",
            "300",
            "--population",
            "8",
            "--generations",
            "1",
            "--workers",
            "1",
            "--optics",
            "ray",
            "-o",
            str(out),
            "--json",
        ],
    )
    assert res.exit_code == 0, res.output
    d = json.loads(res.stdout)
    assert d["pareto"] and {
        "holes_um",
        "thicknesses_um",
        "efficiency_ratio",
        "dof_mm",
        "ghost_fraction",
    } <= set(d["pareto"][0])
    ds = xr.open_dataset(out, engine="scipy")
    assert ds.attrs["design"] == "paper2016" and ds.attrs["seed"] == 0
    assert "opticalstamp_version" in ds.attrs and ds.sizes["evaluation"] == 8
    ds.close()
    out = tmp_path / "t.nc"
    res = runner.invoke(
        app,
        [
            "tolerance",
            "--samples",
            "6",
            "--workers",
            "1",
            "--json",
            "--spec",
            "dof>=2",
            "--optics",
            "ray",
            "-o",
            str(out),
        ],
    )
    assert res.exit_code == 0, res.output
    d = json.loads(res.stdout)
    assert {"rmtf200", "dof_mm", "sensitivity", "yield"} <= set(d)
    ds = xr.open_dataset(out, engine="scipy")
    assert ds.sizes["sample"] == 6 and json.loads(ds.attrs["sigmas"])["misregistration_um"] == 3
    ds.close()


@pytest.mark.parametrize(
    ("args", "text"),
    [
        (["search", "--dask", "localhost:8786"], "--dask"),
        (["search", "--pin", "hole1"], "--pin"),
        (["search", "--population", "2"], "--population"),
        (["search", "-o", "x.csv"], "-o"),
        (["tolerance", "--misregistration-um", "-1"], "must be in [0, 100]"),
        (["tolerance", "--spec", "yield>3"], "--spec"),
        (["tolerance", "--samples", "0"], "--samples"),
    ],
)
def test_cli_bad_options(args, text):
    res = runner.invoke(app, args)
    assert res.exit_code == 2, res.output
    assert text in res.output and "Traceback" not in res.output


def test_structural_variants_and_merged_front(paper):
    from opticalstamp.analysis.paraxial import paraxial_etendue
    from opticalstamp.design import structural_variants
    from opticalstamp.studies.search import merged_front

    v = structural_variants(paper, layers=(2, 3), stagger=("yes", "no"))
    assert len(v) == 4
    two = v["paper2016, 2 layers, staggered"]
    assert [m.name for m in two.masks] == ["layer 3", "layer 1"]
    one_row = v["paper2016, 3 layers, one row"]
    assert one_row.sensor.rows == 1 and one_row.sensor.row_pitch_um == pytest.approx(84.6)
    # the middle layer costs only 1 % of the own-path light: it is there for the ghosts
    assert paraxial_etendue(paper) / paraxial_etendue(two) == pytest.approx(0.99, abs=0.005)
    with pytest.raises(ValueError, match="layers"):
        structural_variants(paper, layers=(5,))
    res = {
        k: search(d, population=8, generations=1, workers=1, ghost_rays=1 << 15)
        for k, d in list(v.items())[:2]
    }
    front = merged_front(res)
    assert all("variant" in r for r in front)


def test_cli_search_variants(tmp_path):
    """--layers 2,3: one search per variant, a file each. By ray optics (the variants'
    loop and files do not depend on the optics; the wave estimator took five times as
    long)."""
    res = runner.invoke(
        app,
        [
            "search",
            "--layers",
            "2,3",
            "--population",
            "8",
            "--generations",
            "1",
            "--workers",
            "1",
            "--optics",
            "ray",
            "--json",
            "-o",
            str(tmp_path / "v.nc"),
        ],
    )
    assert res.exit_code == 0, res.output
    d = json.loads(res.stdout)
    assert len(d["variants"]) == 2 and (tmp_path / "v.v1.nc").exists()
    bad = runner.invoke(app, ["search", "--stagger", "maybe"])
    assert bad.exit_code == 2 and "--stagger" in bad.output


def test_exact_search_and_tolerance(paper, dask_cluster):
    """--estimator trace: every candidate's figures are the exact tracer's
    (evaluate_exact of the same design, bit for bit), the same on one worker and on Dask;
    a tolerance study traces its samples exactly too (only the holes erring: three
    sensitivity rows traced, not thirteen, 15 -> 4 s measured; the estimator does not
    depend on the sigmas)."""
    from opticalstamp.design import with_stack
    from opticalstamp.studies.tolerance import tolerance
    from opticalstamp.studies.verify import EXACT, evaluate_exact

    kw = dict(population=4, generations=1, seed=2, estimator="trace")
    one = search(paper, workers=1, **kw)
    dsk = search(paper, dask_address=dask_cluster, **kw)
    assert one.meta["estimator"] == EXACT
    assert [r["dof_mm"] for r in one.records] == [r["dof_mm"] for r in dsk.records]
    r = next(r for r in one.records if r["ok"])
    d = with_stack(paper, holes_um=r["holes_um"], thicknesses_um=r["thicknesses_um"])
    ex = evaluate_exact(d, dpi=200.0, near_mm=one.meta["near_mm"], seed=2)
    for k in ("dof_mm", "efficiency_ratio", "ghost_fraction", "diffraction_spill"):
        assert r[k] == ex[k], k
    holes = {"misregistration_um": 0.0, "hole_um": 1.0, "thickness_um": 0.0, "tilt_deg": 0.0}
    t = tolerance(paper, samples=2, seed=1, workers=1, estimator="trace", sigmas=holes)
    assert t.meta["estimator"] == EXACT and "nominal_exact" not in t.meta
    assert t.nominal["estimator"] == EXACT
