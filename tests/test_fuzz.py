"""Property-based fuzzing of the edges (hypothesis): invalid designs, option values, image
files and height maps always end with exit code 2, a message naming the field, option or
file, no traceback and no output file. Bounded to a few hundred examples per class."""

from __future__ import annotations

import math
import os
import shutil

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from edges import assert_clean_refusal, run, to_toml
from helpers import preset_dict
from opticalstamp.design import DesignError, design_from_dict
from opticalstamp.io.files import write_png

#: examples per class; raise it for a longer census (OPTICALSTAMP_FUZZ_EXAMPLES=2000)
FUZZ = settings(
    max_examples=int(os.environ.get("OPTICALSTAMP_FUZZ_EXAMPLES", "120")),
    deadline=None,
    derandomize=True,
    suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow],
)

NON_NUMBERS = st.one_of(
    st.booleans(),
    st.text(max_size=8),
    st.lists(st.floats(allow_nan=False), max_size=2),
    st.dictionaries(st.sampled_from("ab"), st.integers(), max_size=1),
)
NON_FINITE = st.sampled_from([math.nan, math.inf, -math.inf])


def _outside(lo: float | None, hi: float | None, *, lo_open=False, hi_open=False):
    """Finite floats outside [lo, hi] (or on an open bound)."""
    parts = []
    if lo is not None:
        parts.append(
            st.floats(max_value=lo, exclude_max=not lo_open, allow_nan=False, allow_infinity=False)
        )
    if hi is not None:
        parts.append(
            st.floats(min_value=hi, exclude_min=not hi_open, allow_nan=False, allow_infinity=False)
        )
    return st.one_of(*parts)


# (path in the preset dict, strategy of invalid values)
POSITIVE = st.one_of(NON_NUMBERS, NON_FINITE, _outside(0.0, 100_000.0, lo_open=True))
HOLE = st.one_of(NON_NUMBERS, NON_FINITE, _outside(0.0, None, lo_open=True))
OFFSET = st.one_of(NON_NUMBERS, NON_FINITE, _outside(-1e4, 1e4))
MEDIUM = st.one_of(
    st.booleans(), NON_FINITE, _outside(1.0, 4.0), st.text(alphabet="xyz", min_size=1, max_size=5)
)
LINES = st.one_of(
    st.booleans(),
    st.floats(),
    st.text(max_size=3),
    st.integers(max_value=0),
    st.integers(min_value=65),
)
ROWS = st.one_of(st.booleans(), st.floats(), st.integers().filter(lambda v: v not in (1, 2)))
DESIGN_FIELDS = [
    (("slabs", 0, "thickness_um"), POSITIVE),
    (("slabs", 1, "thickness_um"), POSITIVE),
    (("slabs", 2, "mask_top", "size_um"), HOLE),
    (("slabs", 1, "mask_top", "offset_y_um"), OFFSET),
    (("slabs", 1, "medium"), MEDIUM),
    (("reference_gap", "thickness_um"), st.one_of(NON_NUMBERS, NON_FINITE, _outside(0.0, 1e5))),
    (("sensor", "pixel_pitch_um"), st.one_of(NON_NUMBERS, NON_FINITE, _outside(1.0, 1e5))),
    (("sensor", "lines"), LINES),
    (("sensor", "rows"), ROWS),
    (("wavelength_um",), st.one_of(NON_NUMBERS, NON_FINITE, _outside(0.35, 1.1))),
]


def _set(d: dict, path: tuple, value) -> dict:
    node = d
    for key in path[:-1]:
        node = node[key]
    node[path[-1]] = value
    return d


def _field_name(path: tuple) -> str:
    return ".".join(str(p) for p in path)


@FUZZ
@given(data=st.data())
def test_fuzz_invalid_designs(tmp_path, data):
    path, strategy = data.draw(st.sampled_from(DESIGN_FIELDS))
    value = data.draw(strategy)
    d = _set(preset_dict("paper2016"), path, value)
    with pytest.raises(DesignError):
        design_from_dict(d)
    folder = tmp_path / "fuzz"
    shutil.rmtree(folder, ignore_errors=True)
    folder.mkdir()
    f = folder / "bad.toml"
    f.write_text(to_toml(d))
    res = run(["spots", "-d", f, "--rays", 1000, "--plot", folder / "s.png"])
    assert_clean_refusal(res, (_field_name(path), "bad.toml"), folder, ["bad.toml"])


# (command, option, strategy of invalid values): every numeric option of every command
FLOATS_BAD = lambda lo, hi, **kw: st.one_of(NON_FINITE, _outside(lo, hi, **kw))  # noqa: E731
OPTION_CASES = [
    ("rmtf", "--window-um", FLOATS_BAD(0, 1e6, lo_open=True)),
    ("rmtf", "--shift-um", FLOATS_BAD(0, 1000, lo_open=True)),
    ("rmtf", "--threshold", FLOATS_BAD(0, 1, lo_open=True, hi_open=True)),
    ("rmtf", "--dof-dpi", FLOATS_BAD(1, 5000)),
    ("rmtf", "--z", FLOATS_BAD(0, 100)),
    ("rmtf", "--dpi", FLOATS_BAD(1, 5000)),
    ("ghosts", "--detector-um", FLOATS_BAD(0, 1e6, lo_open=True)),
    ("ghosts", "--rse-own", FLOATS_BAD(0, 1, lo_open=True, hi_open=True)),
    ("ghosts", "--rse-ghost", FLOATS_BAD(0, 1, lo_open=True, hi_open=True)),
    ("ghosts", "--z", FLOATS_BAD(0, 100)),
    ("spots", "--z", FLOATS_BAD(0, 100)),
    ("psf", "--z", FLOATS_BAD(0, 100)),
    ("psf", "--x-obj", FLOATS_BAD(-1e5, 1e5)),
    ("psf", "--y-obj", FLOATS_BAD(-1e5, 1e5)),
    ("diffraction", "--slit-um", FLOATS_BAD(0, 1e4, lo_open=True)),
    ("diffraction", "--z", FLOATS_BAD(0, 100)),
    ("diffraction", "--gap-um", FLOATS_BAD(0, 1e6)),
    ("diffraction", "--next-um", FLOATS_BAD(0, 1e6, lo_open=True)),
    ("diffraction", "--wavelength-um", FLOATS_BAD(0.2, 2.0)),
    ("search", "--dpi", FLOATS_BAD(50, 2400)),
    ("search", "--dof-dpi", FLOATS_BAD(50, 2400)),
    ("search", "--budget-mm", FLOATS_BAD(0.2, 20)),
    ("search", "--near-mm", FLOATS_BAD(0, 100)),
    ("search", "--max-ghost", FLOATS_BAD(0, 1)),
    ("tolerance", "--misregistration-um", FLOATS_BAD(0, 100)),
    ("tolerance", "--hole-um", FLOATS_BAD(0, 100)),
    ("tolerance", "--thickness-um", FLOATS_BAD(0, 1000)),
    ("tolerance", "--tilt-deg", FLOATS_BAD(0, 5)),
    ("tolerance", "--dpi", FLOATS_BAD(50, 2400)),
    ("tolerance", "--z", FLOATS_BAD(0, 10)),
    ("chart", "--dpi", FLOATS_BAD(100, 4800)),
    ("scan", "--z", FLOATS_BAD(0, 10)),
    ("scan", "--illuminance-lux", FLOATS_BAD(1e-3, 1e7)),
    ("scan", "--exposure-ms", FLOATS_BAD(0, 1e4, lo_open=True)),
    ("scan", "--speed-error", FLOATS_BAD(-0.5, 0.5, lo_open=True, hi_open=True)),
    ("scan", "--surround", FLOATS_BAD(0, 1)),
    ("scan", "--dpi", FLOATS_BAD(10, 20000)),
    ("measure-rmtf", "--dpi", FLOATS_BAD(10, 20000)),
    ("sfr", "--dpi", FLOATS_BAD(10, 20000)),
]
POSITIONAL = {
    "chart": ["bars", "-o", "c.png"],
    "scan": ["doc.png", "-o", "s.png"],
    "measure-rmtf": ["doc.png"],
    "sfr": ["doc.png"],
}


@FUZZ
@given(data=st.data())
def test_fuzz_invalid_option_values(tmp_path, monkeypatch, data):
    cmd, opt, strategy = data.draw(st.sampled_from(OPTION_CASES))
    value = data.draw(strategy)
    folder = tmp_path / "fuzz"
    shutil.rmtree(folder, ignore_errors=True)
    folder.mkdir()
    write_png(folder / "doc.png", np.full((64, 64), 0.5), 600.0)
    monkeypatch.chdir(folder)
    text = repr(value) if value == value else "nan"
    res = run([cmd, *POSITIONAL.get(cmd, []), opt, text])
    assert_clean_refusal(res, opt, folder, ["doc.png"])


# -- image files: random bytes behind real magic numbers ----------------------------------
MAGICS = [b"\x89PNG\r\n\x1a\n", b"II*\x00", b"MM\x00*", b"\xff\xd8\xff\xe0", b""]


@FUZZ
@given(
    magic=st.sampled_from(MAGICS),
    body=st.binary(max_size=300),
    cmd=st.sampled_from(["measure-rmtf", "sfr", "scan", "ocr-eval"]),
    suffix=st.sampled_from([".png", ".tif", ".jpg"]),
)
def test_fuzz_garbage_images(tmp_path, magic, body, cmd, suffix):
    folder = tmp_path / "fuzz"
    shutil.rmtree(folder, ignore_errors=True)
    folder.mkdir()
    img = folder / f"img{suffix}"
    img.write_bytes(magic + body)
    (folder / "t.txt").write_text("abc")
    args = {
        "measure-rmtf": ["measure-rmtf", img, "--dpi", 600],
        "sfr": ["sfr", img, "--dpi", 600],
        "scan": ["scan", img, "-o", folder / "s.png", "--z", 1, "--dpi", 600],
        "ocr-eval": ["ocr-eval", img, "--text", folder / "t.txt", "--dpi", 600],
    }[cmd]
    assert_clean_refusal(run(args), img.name, folder, [img.name, "t.txt"])


# -- height maps ----------------------------------------------------------------------------
HEIGHT_ARRAYS = st.one_of(
    st.builds(lambda v: np.full((8, 8), v), NON_FINITE),
    st.builds(lambda v: np.full((8, 8), v), _outside(0.0, 10.0)),
    st.just(np.zeros((8, 8), dtype=np.complex128)),
    st.just(np.array(["a", "b"])),
    st.just(np.zeros(4, dtype=[("a", "f8")])),
    st.just(np.array(["2020-01-01"], dtype="datetime64[D]")),
    st.just(np.zeros((0, 0))),
    st.just(np.zeros(5)),
)


@FUZZ
@given(arr=HEIGHT_ARRAYS)
def test_fuzz_bad_height_maps(tmp_path, arr):
    folder = tmp_path / "fuzz"
    shutil.rmtree(folder, ignore_errors=True)
    folder.mkdir()
    write_png(folder / "doc.png", np.full((64, 64), 0.5), 600.0)
    hm = folder / "h.npy"
    np.save(hm, arr, allow_pickle=False)
    res = run(["scan", folder / "doc.png", "-o", folder / "s.png", "--height-map", hm])
    assert_clean_refusal(res, ("h.npy", "height map"), folder, ["doc.png", "h.npy"])


@FUZZ
@given(
    shape=st.sampled_from(["tilt", "gutter", "crumple"]),
    a=st.one_of(NON_FINITE, st.floats(min_value=1e6, allow_infinity=False)),
    b=st.floats(allow_nan=True, allow_infinity=True),
)
def test_fuzz_bad_height_specs(tmp_path, shape, a, b):
    folder = tmp_path / "fuzz"
    shutil.rmtree(folder, ignore_errors=True)
    folder.mkdir()
    write_png(folder / "doc.png", np.full((64, 64), 0.5), 600.0)
    spec = f"{shape}:{a!r}:{b!r}"
    res = run(["scan", folder / "doc.png", "-o", folder / "s.png", "--height-map", spec])
    assert_clean_refusal(res, (spec, shape, "height map"), folder, ["doc.png"])


def test_npz_given_as_npy(tmp_path):
    write_png(tmp_path / "doc.png", np.full((64, 64), 0.5), 600.0)
    np.savez(tmp_path / "h.npz", a=np.zeros((4, 4)))
    (tmp_path / "h.npz").rename(tmp_path / "h.npy")
    res = run(
        ["scan", tmp_path / "doc.png", "-o", tmp_path / "s.png", "--height-map", tmp_path / "h.npy"]
    )
    assert_clean_refusal(res, "h.npy", tmp_path, ["doc.png", "h.npy"])
