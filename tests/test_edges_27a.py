"""Issue 27, bad input at the edges: study journals, options, restore's sidecar.

Journals: records with NaN, negative, missing or mistyped figures are skipped with a
warning naming the lines and evaluated again (never passed on to the results); a journal
that is a folder is refused; no run leaves its lock file behind. Options: ``--device ''``,
illumination profiles that are no regular file, too large or all zero, an illuminance
below starlight, ``--spec`` at a height the study does not compute. The sidecar of
``restore``: mistyped fields, a sidecar of another image, relative paths.
"""

from __future__ import annotations

import json
import math
import os
import shutil
import tempfile
import warnings
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from edges import assert_clean_refusal, run
from opticalstamp.device import device_name
from opticalstamp.io.files import MAX_PROFILE_BYTES, read_illumination_profile, write_png
from opticalstamp.io.journal import JournalWarning, append_record, journal_lock, read_journal
from opticalstamp.studies.evaluate import RMTF_Z_MM, check_figures
from opticalstamp.studies.runner import run_tasks, task_key
from opticalstamp.studies.tolerance import meets
from opticalstamp.validate import InputError

# -- journals ------------------------------------------------------------------------------


def _figures(v: int) -> dict:
    """A valid evaluation's figures (as the journal reads them back), distinct per v."""
    return {
        "estimator": "test",
        "restored_dof_mm": None,
        "etendue_own_um2sr": 1.0 + v,
        "etendue_ghost_um2sr": 0.25 * v,
        "ghost_fraction": 0.25 * v / (1.0 + 1.25 * v),
        "efficiency_ratio": 0.01 * (1 + v),
        "efficiency_ratio_total": 0.02 * (1 + v),
        "dof_mm": 0.5 * v,
        "dof_open_ended": False,
        "rmtf_at": {f"{z:g}": 0.8 / (1 + z + v) for z in RMTF_Z_MM},
        "nearest_ghost_mm": None if v % 2 else 1.5 + v,  # null: no ghost light lands
        "near_ghost": False,
        "diffraction_spill": 0.1,
        "stack_um": 1850.0 + v,
    }


N_TASKS = 5
PAYLOADS = [{"v": v, "options": {}} for v in range(N_TASKS)]
TASKS = [(task_key(p), p) for p in PAYLOADS]
KEYS = [k for k, _ in TASKS]


def _record(v: int, result: dict | None = None) -> dict:
    return {
        "key": KEYS[v],
        "payload": PAYLOADS[v],
        "ok": True,
        "result": _figures(v) if result is None else result,
        "attempts": 1,
    }


def _resume(journal: Path):
    """One resume in this process: (records, the tasks evaluated, warnings)."""
    calls = []

    def evaluate(p):
        calls.append(p["v"])
        return _figures(p["v"])

    with warnings.catch_warnings(record=True) as got:
        warnings.simplefilter("always")
        out = run_tasks(evaluate, TASKS, workers=1, journal=journal, check=check_figures)
    return out, calls, [w for w in got if issubclass(w.category, JournalWarning)]


#: figures and values that break their rules (None is fine for the nearest ghost and the
#: restored depth of field, so it is not among theirs)
BAD = st.sampled_from(
    [math.nan, math.inf, -math.inf, -1.0, -1e-300, None, "1.0", True, False, [], {}]
)
#: for the two figures where null is fine (a JSON writer turns NaN and infinities into it)
BAD_NOT_NULL = st.sampled_from([-1.0, -1e-9, "1.0", True, [], {}])
FIELDS = st.sampled_from(
    [
        "etendue_own_um2sr",
        "etendue_ghost_um2sr",
        "ghost_fraction",
        "efficiency_ratio",
        "efficiency_ratio_total",
        "dof_mm",
        "stack_um",
        "diffraction_spill",
    ]
)


@st.composite
def corrupted(draw) -> dict:
    """A result of _figures with one figure broken: a bad value, a missing figure, a bad
    RMTF, a missing height, a flag that is a number."""
    res = _figures(draw(st.integers(0, N_TASKS - 1)))
    kind = draw(st.sampled_from(["value", "missing", "rmtf", "height", "flag", "nearest"]))
    if kind == "value":
        res[draw(FIELDS)] = draw(BAD)
    elif kind == "missing":  # every figure but the estimator's free text is needed
        del res[draw(st.sampled_from(sorted(set(res) - {"estimator"})))]
    elif kind == "rmtf":
        z = draw(st.sampled_from(sorted(res["rmtf_at"])))
        res["rmtf_at"][z] = draw(st.one_of(BAD, st.sampled_from([1.5, -0.5])))
    elif kind == "height":
        del res["rmtf_at"][draw(st.sampled_from(sorted(res["rmtf_at"])))]
    elif kind == "flag":
        res[draw(st.sampled_from(["near_ghost", "dof_open_ended"]))] = draw(
            st.sampled_from([0, 1, None, "false"])
        )
    else:
        res[draw(st.sampled_from(["nearest_ghost_mm", "restored_dof_mm"]))] = draw(BAD_NOT_NULL)
    return res


def test_the_figures_of_a_valid_evaluation_keep_their_rules():
    for v in range(N_TASKS):
        assert check_figures(PAYLOADS[v], _figures(v)) is None
    restored = {"options": {"restored": True}}
    assert "restored_dof_mm" in check_figures(restored, _figures(0))
    assert check_figures(restored, _figures(0) | {"restored_dof_mm": 1.2}) is None
    exact = {"exact": True, "options": {}}  # the exact tracer: no spill, no restoration
    fig = {k: v for k, v in _figures(0).items() if k not in ("diffraction_spill",)}
    assert check_figures(exact, fig) is None
    assert "diffraction_spill" in check_figures(PAYLOADS[0], fig)
    heights = {"options": {"rmtf_z_mm": [0.5, 1.0]}}
    assert check_figures(heights, _figures(0)) == "rmtf_at: no RMTF at Z = 0.5 mm"


@settings(
    max_examples=30,
    deadline=None,
    derandomize=True,
    suppress_health_check=[HealthCheck.too_slow],
)
@given(
    cut=st.floats(0.0, 1.0),
    tail=st.one_of(
        st.tuples(st.just("junk"), st.binary(max_size=60)),
        st.tuples(st.just("record"), corrupted()),
        st.tuples(st.just("raw"), corrupted()),  # NaN and Infinity as JSON tokens
    ),
    shadow=st.booleans(),
)
def test_a_resumed_journal_keeps_every_valid_record_and_no_nonsense(cut, tail, shadow):
    """Any byte prefix of a valid journal, then junk or a record with corrupted figures:
    the resume raises nothing, returns only figures that keep their rules, keeps every
    complete valid record of the prefix (never evaluated again, even when the corrupted
    record has its key), and leaves a journal that a second resume reads back the same."""
    with tempfile.TemporaryDirectory(dir=os.environ.get("TMPDIR")) as folder:
        j = Path(folder) / "out.nc.journal.jsonl"
        for v in range(N_TASKS - 1):  # the last task is never journalled
            append_record(j, _record(v))
        full = j.read_bytes()
        prefix = full[: int(cut * len(full))]
        j.write_bytes(prefix)
        kind, value = tail
        ends = np.cumsum([len(line) + 1 for line in full.split(b"\n")[: N_TASKS - 1]])
        # a record is complete with its newline; without it only where what follows starts
        # on a line of its own (the writer's appends do; raw junk glued to it does not)
        complete = {
            v
            for v in range(N_TASKS - 1)
            if len(prefix) >= ends[v] or (kind != "junk" and len(prefix) == ends[v] - 1)
        }
        if kind == "junk":
            with open(j, "ab") as fh:
                fh.write(value)
        else:
            v = next(iter(complete)) if shadow and complete else N_TASKS - 1
            rec = _record(v, value)
            if kind == "record":
                append_record(j, rec)  # the writer: NaN and infinities as null
            else:
                with open(j, "ab") as fh:
                    fh.write(b"\n" + json.dumps(rec).encode() + b"\n")
        out, calls, _ = _resume(j)
        assert sorted(out) == sorted(KEYS)
        for key, p in TASKS:
            assert out[key]["ok"] and check_figures(p, out[key]["result"]) is None
            assert out[key]["result"] == _figures(p["v"])
        assert not set(calls) & complete  # no complete valid record lost
        assert not (Path(folder) / "out.nc.journal.jsonl.lock").exists()
        again, calls2, _ = _resume(j)
        assert calls2 == [] and again == out
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", JournalWarning)
            assert read_journal(j, lambda r: check_figures(r["payload"], r["result"])) == out


def test_a_journal_with_corrupted_figures_names_the_lines(tmp_path):
    j = tmp_path / "j.jsonl"
    append_record(j, _record(0))
    append_record(j, _record(1, _figures(1) | {"etendue_own_um2sr": -1.0}))
    append_record(j, _record(2, _figures(2) | {"rmtf_at": {"1": -0.5, "2": 0.1, "3": 0.1}}))
    out, calls, got = _resume(j)
    assert sorted(calls) == [1, 2, 3, 4]
    msg = str(got[0].message)
    assert str(j) in msg and "2 record(s)" in msg and "line 2, 3" in msg
    assert "etendue_own_um2sr: must be >= 0 (got -1.0)" in msg
    assert out[KEYS[1]]["result"]["etendue_own_um2sr"] == 2.0


def test_a_fresh_result_that_breaks_the_rules_is_journalled_as_failed(tmp_path):
    """What a resume would skip is not written as a result: it is a failure, read back
    the same by every resume (never evaluated again and again)."""
    j = tmp_path / "j.jsonl"

    def nan_dof(p):
        return _figures(p["v"]) | {"dof_mm": math.nan}

    out = run_tasks(nan_dof, TASKS[:2], workers=1, journal=j, check=check_figures)
    assert not any(r["ok"] for r in out.values())
    assert all(r["error"].startswith("ResultError: dof_mm") for r in out.values())
    with warnings.catch_warnings():
        warnings.simplefilter("error", JournalWarning)
        again = run_tasks(nan_dof, TASKS[:2], workers=1, journal=j, check=check_figures)
    assert again == out


def test_a_journal_that_is_a_folder_is_refused_and_leaves_no_lock(tmp_path):
    j = tmp_path / "out.nc.journal.jsonl"
    j.mkdir()
    for call in (
        lambda: run_tasks(lambda p: {}, TASKS, workers=1, journal=j),
        lambda: read_journal(j),
    ):
        with pytest.raises(InputError, match="a folder"):
            call()
    assert sorted(p.name for p in tmp_path.iterdir()) == [j.name]
    res = run(["search", "--population", "4", "--generations", "1", "--workers", "1",
               "--no-verify", "-o", tmp_path / "out.nc"])  # fmt: skip
    assert_clean_refusal(res, str(j), tmp_path, [j.name])


def test_the_lock_file_goes_with_the_run_whatever_ends_it(tmp_path):
    j = tmp_path / "j.jsonl"
    lock = tmp_path / "j.jsonl.lock"
    with pytest.raises(ZeroDivisionError), journal_lock(j):
        assert lock.exists()
        1 / 0  # noqa: B018 - the run fails
    assert not lock.exists()
    lock.write_text("PID 1 on a machine long gone\n")  # a killed run's file, not its lock
    run_tasks(lambda p: _figures(p["v"]), TASKS, workers=1, journal=j)
    assert not lock.exists()


def _corrupt_journal(journal: Path, change: dict) -> None:
    lines = []
    for line in journal.read_text().splitlines():
        rec = json.loads(line)
        if rec["ok"]:
            rec["result"] |= change
        lines.append(json.dumps(rec))
    journal.write_text("\n".join(lines) + "\n")


def test_search_resumes_a_journal_of_nonsense_by_evaluating_again(tmp_path):
    """NaN stacks made the optimiser refuse ('NaN is not allowed') and left the lock
    behind; negative RMTF reached the front. Now: a warning, the figures evaluated again.
    By ray optics (the surrogate, a tenth of the wave estimator's time): the journal's
    records and the rules they are checked against are the same by either optics."""
    out = tmp_path / "s.nc"
    args = ["search", "--population", "4", "--generations", "1", "--workers", "1",
            "--no-verify", "--optics", "ray", "-o", out, "--json"]  # fmt: skip
    first = run(args)
    assert first.exit_code == 0, first.output
    journal = tmp_path / "s.nc.journal.jsonl"
    for change in (
        {"stack_um": math.nan, "ghost_fraction": math.nan},
        {"rmtf_at": {"1": -0.5, "2": -0.5, "3": -0.5}, "etendue_own_um2sr": -1.0},
    ):
        _corrupt_journal(journal, change)
        with pytest.warns(JournalWarning, match="break the study's rules"):
            res = run(args)
        assert res.exit_code == 0, res.output
        data = json.loads(res.stdout)
        assert data["pareto"] == json.loads(first.stdout)["pareto"]
        assert all(v >= 0 for p in data["pareto"] for v in p["rmtf_at"].values())
        assert not (tmp_path / "s.nc.journal.jsonl.lock").exists()


def test_tolerance_evaluates_a_negative_nominal_again(tmp_path):
    from opticalstamp.design import load_design
    from opticalstamp.studies.tolerance import tolerance

    d = load_design("paper2016")
    j = tmp_path / "t.nc.journal.jsonl"
    kw = {"samples": 2, "ghost_rays": 1 << 12, "workers": 1, "journal": j, "verify": False}
    first = tolerance(d, **kw)
    _corrupt_journal(j, {"etendue_own_um2sr": -1.0, "efficiency_ratio": None})
    with pytest.warns(JournalWarning):
        again = tolerance(d, **kw)
    assert again.nominal["etendue_own_um2sr"] == first.nominal["etendue_own_um2sr"] > 0
    assert again.nominal["efficiency_ratio"] == first.nominal["efficiency_ratio"]
    assert not (tmp_path / "t.nc.journal.jsonl.lock").exists()


def test_a_spec_on_the_ghost_radius_reads_a_journalled_no_ghost():
    """JSON has no infinity: a journal writes 'no ghost light lands' as null."""
    assert meets({"nearest_ghost_mm": None}, [("ghost_radius", ">=", 5.0)])
    assert not meets({"nearest_ghost_mm": 2.0}, [("ghost_radius", ">=", 5.0)])


# -- options -------------------------------------------------------------------------------


def test_an_empty_device_is_refused(monkeypatch):
    res = run(["--device", "", "presets", "show", "paper2016"])
    assert_clean_refusal(res, "--device")
    with pytest.raises(InputError, match="device"):
        device_name("")
    assert device_name() == "auto"
    monkeypatch.setenv("OPTICALSTAMP_DEVICE", "")  # an empty variable is an unset one, as in
    assert run(["presets"]).exit_code == 0  # a shell
    monkeypatch.setenv("OPTICALSTAMP_DEVICE", "tpu")  # the command line's default: named
    assert_clean_refusal(run(["presets"]), "OPTICALSTAMP_DEVICE")


def test_a_spec_at_a_height_the_study_does_not_compute_is_refused(tmp_path):
    res = run(["tolerance", "--samples", "2", "--workers", "1", "--z", "1,2",
               "--spec", "rmtf@99>=0.3", "-o", tmp_path / "t.nc"])  # fmt: skip
    assert_clean_refusal(res, "--spec", tmp_path, [])
    assert "1, 2 mm" in res.output


@pytest.fixture(scope="module")
def page(tmp_path_factory) -> Path:
    """A small 600-dpi page of bars."""
    folder = tmp_path_factory.mktemp("page")
    img = np.ones((96, 96))
    img[:, ::8] = 0.0
    img[:, 1::8] = 0.0
    write_png(folder / "page.png", img, 600.0)
    return folder / "page.png"


def _profile(tmp_path, text: str) -> Path:
    p = tmp_path / "light.csv"
    p.write_text(text)
    return p


@pytest.mark.parametrize(
    ("make", "rule"),
    [
        (lambda t: Path("/dev/zero"), "not a regular file"),
        (lambda t: t, "not a regular file"),  # the folder itself
        (lambda t: t / "none.csv", "no such file"),
        (lambda t: _profile(t, "0,0\n300,0\n"), "positive somewhere"),
        (lambda t: _profile(t, "# nothing\n"), "no rows"),
        (lambda t: _profile(t, "0,1\n"), "two rows"),
        (lambda t: _profile(t, "0,1\n0,1\n"), "increase"),
        (lambda t: _profile(t, "0,1\n1,-1\n"), ">= 0"),
        (lambda t: _profile(t, "0,1\n1,nan\n"), "finite"),
        (lambda t: _profile(t, "0,1,1\n1,1,1\n"), "two columns"),
        (lambda t: _profile(t, "x_mm,relative\n"), "cannot read"),
    ],
)
def test_bad_illumination_profiles_are_refused_before_reading(tmp_path, page, make, rule):
    out = tmp_path / "o"
    out.mkdir()
    res = run(["scan", page, "-o", out / "s.png", "--z", "1", "--illumination", make(tmp_path)])
    assert_clean_refusal(res, "--illumination", out, [])
    assert rule in res.output


def test_an_oversized_profile_is_refused_unread(tmp_path):
    big = tmp_path / "big.csv"
    with open(big, "wb") as fh:
        fh.truncate(MAX_PROFILE_BYTES + 1)  # sparse: nothing to read
    with pytest.raises(InputError, match="larger than"):
        read_illumination_profile(big)


def test_a_good_profile_scans(tmp_path, page):
    prof = _profile(tmp_path, "# x_mm,relative\n0,0\n2,1\n300,1\n")
    res = run(["scan", page, "-o", tmp_path / "s.png", "--z", "1", "--illumination", prof])
    assert res.exit_code == 0, res.output


def test_an_illuminance_below_starlight_is_refused(tmp_path, page):
    res = run(["scan", page, "-o", tmp_path / "s.png", "--z", "1", "--illuminance-lux", "1e-300"])
    assert_clean_refusal(res, "--illuminance-lux", tmp_path, [])
    d = tmp_path / "d.toml"
    base = run(["presets", "show", "paper2016"]).stdout
    d.write_text(base + "\n[electronics]\nilluminance_lux = 1e-300\n")
    res = run(["scan", page, "-o", tmp_path / "s.png", "--z", "1", "-d", d])
    assert_clean_refusal(res, "electronics.illuminance_lux", tmp_path, ["d.toml"])
    res = run(["scan", page, "-o", tmp_path / "s.png", "--z", "1", "--illuminance-lux", "0.001",
               "--json"])  # fmt: skip
    assert res.exit_code == 0, res.output
    assert all(v is not None for v in json.loads(res.stdout)["signal"].values())


# -- restore's sidecar -----------------------------------------------------------------


@pytest.fixture(scope="module")
def scanned(tmp_path_factory, page) -> Path:
    """A scan (PNG, TIFF, JSON sidecar) of the page at 1 mm, with its design file beside it."""
    folder = tmp_path_factory.mktemp("scan")
    shutil.copy(page, folder / "page.png")
    design = run(["presets", "show", "paper2016"]).stdout.replace(
        'name = "paper2016"', 'name = "mine"'
    )
    (folder / "mine.toml").write_text(design)
    cwd = Path.cwd()
    os.chdir(folder)
    try:
        res = run(["scan", "page.png", "-o", "out/s.png", "--z", "1", "-d", "mine.toml"])
    finally:
        os.chdir(cwd)
    assert res.exit_code == 0, res.output
    return folder / "out" / "s.png"


def _copy_scan(scanned: Path, to: Path, change: dict | None = None, raw: str | None = None):
    """The scan and its sidecar copied to ``to``, the sidecar's fields changed."""
    to.mkdir(exist_ok=True)
    shutil.copy(scanned, to / "s.png")
    side = json.loads(scanned.with_suffix(".json").read_text())
    side["design_source"] = "paper2016"  # the design file is not copied
    side.pop("design_fingerprint")
    side |= change or {}
    text = json.dumps(side) if raw is None else raw
    (to / "s.json").write_text(text)
    return to / "s.png"


@pytest.mark.parametrize(
    ("change", "field"),
    [
        ({"z_mm": "1"}, "z_mm"),
        ({"z_mm": [1]}, "z_mm"),
        ({"z_mm": True}, "z_mm"),  # a bool is not a number
        ({"z_mm": 99.0}, "z_mm"),
        ({"seed": "abc"}, "seed"),
        ({"seed": [1]}, "seed"),
        ({"seed": 1.5}, "seed"),
        ({"seed": True}, "seed"),
        ({"seed": -1}, "seed"),
        ({"color": "no"}, "color"),
        ({"height_map": 1}, "height_map"),
        ({"design_source": 7}, "design_source"),
        ({"settings": "x"}, "settings"),
        ({"files": "x"}, "files"),
        ({"files": {"s.png": 3}}, "files"),
    ],
)
def test_a_mistyped_sidecar_is_refused_naming_the_field(tmp_path, scanned, change, field):
    s = _copy_scan(scanned, tmp_path / "in", change)
    out = tmp_path / "o"
    out.mkdir()
    res = run(["restore", s, "-o", out / "r.png"])
    assert_clean_refusal(res, field, out, [])
    assert "s.json" in res.output


@pytest.mark.parametrize("raw", ["[1, 2]", '{"z_mm": NaN}', "{", "\udcff"])
def test_a_sidecar_that_is_no_json_object_is_refused(tmp_path, scanned, raw):
    s = _copy_scan(scanned, tmp_path / "in")
    (tmp_path / "in" / "s.json").write_bytes(raw.encode("utf-8", "surrogateescape"))
    res = run(["restore", s, "-o", tmp_path / "r.png"])
    assert_clean_refusal(res, "s.json", tmp_path, ["in"])


def test_a_sidecar_of_another_image_is_named_in_a_warning(tmp_path, scanned):
    from PIL import Image

    s = _copy_scan(scanned, tmp_path / "in")
    with Image.open(s) as im:
        other = 1.0 - np.asarray(im, dtype=np.float64) / 255.0
    write_png(s, other, 300.0)  # another image under the scan's name
    res = run(["restore", s, "-o", tmp_path / "r.png"])
    assert res.exit_code == 0, res.output
    assert "warning:" in res.output and "belongs to another image" in res.output
    assert str(s.with_suffix(".json")) in res.output and str(s) in res.output
    res = run(["restore", _copy_scan(scanned, tmp_path / "ok"), "-o", tmp_path / "r2.png"])
    assert res.exit_code == 0 and "warning" not in res.output


def test_a_design_beside_the_scan_is_found_from_another_folder(tmp_path, scanned, monkeypatch):
    side = json.loads(scanned.with_suffix(".json").read_text())
    assert side["design_source"] == "../mine.toml"  # relative to the sidecar's folder
    assert side["input"] == "../page.png"
    monkeypatch.chdir(tmp_path)
    res = run(["restore", scanned, "-o", "r.png", "--json"])
    assert res.exit_code == 0, res.output
    assert json.loads(res.stdout)["design"] == "mine"
    restored = json.loads((tmp_path / "r.json").read_text())
    assert (tmp_path / restored["design_source"]).resolve() == (
        scanned.parent.parent / "mine.toml"
    ).resolve()
    # a sidecar that names the design as it lies beside it (an older scan, moved)
    moved = tmp_path / "moved"
    moved.mkdir()
    for name in ("s.png", "s.tif"):
        shutil.copy(scanned.with_name(name), moved / name)
    shutil.copy(scanned.parent.parent / "mine.toml", moved / "mine.toml")
    (moved / "s.json").write_text(json.dumps(side | {"design_source": "mine.toml"}))
    res = run(["restore", moved / "s.png", "-o", "r2.png", "--json"])
    assert res.exit_code == 0, res.output
    assert json.loads(res.stdout)["design"] == "mine"
