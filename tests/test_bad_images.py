"""Bad image and height-map files: every command ends with ``error: ...`` naming the file
and exit code 2, never a traceback or a silently wrong result; the slanted-edge SFR of the
tool's own chart (and of its scan) is sane in the default mode."""

from __future__ import annotations

import json
import struct
import zlib

import numpy as np
import pytest
import tifffile
from PIL import Image
from typer.testing import CliRunner

from opticalstamp.cli.common import app
from opticalstamp.imaging.heightmap import HeightMapError, shape_map
from opticalstamp.io.files import ImageError, read_image

runner = CliRunner()


def _run(*args):
    return runner.invoke(app, [str(a) for a in args])


def _refused(res, name: str, *words: str) -> None:
    """Exit code 2, the file (or option) named, the rule's words, no traceback."""
    assert res.exception is None or isinstance(res.exception, SystemExit), res.exception
    assert res.exit_code == 2, res.output
    assert "Traceback" not in res.output and "error: " in res.output
    assert name in res.output, res.output
    for w in words:
        assert w in res.output, res.output


def _raw_tiff(
    data=None, *, shape=None, bits=8, fmt=1, spp=1, xres=(600, 1), yres=(600, 1)
) -> bytes:
    """A little-endian one-strip TIFF written by hand, so that any tag value is possible."""
    if data is not None:
        data = np.ascontiguousarray(data)
        h, w = data.shape[:2]
        payload = data.tobytes()
    else:
        (h, w), payload = shape, b""
    nbytes = min(len(payload) or w * h * spp * bits // 8, 2**32 - 1)
    tags = [  # (tag, type, count, value bytes); types 3 SHORT, 4 LONG, 5 RATIONAL
        (256, 4, 1, struct.pack("<I", w)),
        (257, 4, 1, struct.pack("<I", h)),
        (258, 3, spp, struct.pack(f"<{spp}H", *[bits] * spp)),
        (259, 3, 1, struct.pack("<H", 1)),
        (262, 3, 1, struct.pack("<H", 1)),
        (273, 4, 1, b"\0\0\0\0"),  # strip offset: patched below
        (277, 3, 1, struct.pack("<H", spp)),
        (278, 4, 1, struct.pack("<I", h)),
        (279, 4, 1, struct.pack("<I", nbytes)),
        (282, 5, 1, struct.pack("<II", *xres)),
        (283, 5, 1, struct.pack("<II", *yres)),
        (296, 3, 1, struct.pack("<H", 2)),
        (339, 3, spp, struct.pack(f"<{spp}H", *[fmt] * spp)),
    ]
    if spp == 2:
        tags.append((338, 3, 1, struct.pack("<H", 2)))  # ExtraSamples: unassociated alpha
    tags.sort()
    ext_at = 8 + 2 + 12 * len(tags) + 4
    entries, ext = b"", b""
    for tag, typ, count, val in tags:
        if len(val) <= 4:
            entries += struct.pack("<HHI", tag, typ, count) + val.ljust(4, b"\0")
        else:
            entries += struct.pack("<HHII", tag, typ, count, ext_at + len(ext))
            ext += val
    out = bytearray(b"II*\0" + struct.pack("<IH", 8, len(tags)) + entries + b"\0" * 4 + ext)
    i = [t[0] for t in tags].index(273)
    struct.pack_into("<I", out, 8 + 2 + 12 * i + 8, len(out))
    return bytes(out) + payload


def _png_header_only(w: int, h: int) -> bytes:
    """A PNG that declares w x h grey pixels and holds one row of them."""

    def chunk(kind: bytes, data: bytes) -> bytes:
        return (
            struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data))
        )

    ihdr = struct.pack(">IIBBBBB", w, h, 8, 0, 0, 0, 0)
    idat = zlib.compress(b"\0" * (w + 1))
    return b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", ihdr) + chunk(b"IDAT", idat) + chunk(b"IEND", b"")


def _ramp(n: int = 64) -> np.ndarray:
    return np.linspace(0, 255, n * n).reshape(n, n).astype(np.uint8)


# -- 1. reader failures: every one an ImageError naming the file, checked from the header
def test_unreadable_files_end_cleanly_in_every_command(tmp_path):
    files = {
        "zero_den.tif": _raw_tiff(_ramp(), xres=(600, 0)),
        "garbage.tif": b"II*\0" + bytes(range(256)) * 4,
        "garbage.png": b"\x89PNG\r\n\x1a\n" + bytes(range(256)),
        "truncated.tif": _raw_tiff(_ramp())[:-2000],
        "empty.png": b"",
    }
    for name, data in files.items():
        (tmp_path / name).write_bytes(data)
    (tmp_path / "t.txt").write_text("text\n")
    commands = {
        "measure-rmtf": [],
        "sfr": [],
        "scan": ["-o", tmp_path / "out.png", "--z", "1"],
        "ocr-eval": ["--text", tmp_path / "t.txt", "--z", "1"],
    }
    for name in files:
        for command, extra in commands.items():
            _refused(_run(command, tmp_path / name, *extra), name)
    res = _run("sfr", tmp_path / "zero_den.tif")
    _refused(res, "zero_den.tif", "not a number", "--dpi")
    _refused(_run("sfr", tmp_path / "garbage.tif"), "garbage.tif", "no readable image")


def test_huge_declared_images_are_refused_from_the_header(tmp_path, monkeypatch):
    huge = tmp_path / "huge.tif"
    huge.write_bytes(_raw_tiff(shape=(100_000, 100_000)))  # 10 GB declared, 200 bytes held
    for command in ("measure-rmtf", "sfr"):
        _refused(_run(command, huge), "huge.tif", "needs about", "GiB")
    _refused(_run("scan", huge, "-o", tmp_path / "o.png", "--z", "1"), "huge.tif", "needs about")
    # a decompression bomb by Pillow's rule (196 Mpx > 2 x MAX_IMAGE_PIXELS, 179 Mpx): the
    # memory estimate decides instead, and Pillow's own limit is left as it was (the
    # smallest square bomb: with memory to spare the image is decoded, 8 s at 400 Mpx)
    assert 14_000**2 > 2 * Image.MAX_IMAGE_PIXELS
    bomb = tmp_path / "bomb.png"
    bomb.write_bytes(_png_header_only(14_000, 14_000))
    before = Image.MAX_IMAGE_PIXELS
    _refused(_run("measure-rmtf", bomb), "bomb.png")
    monkeypatch.setattr("opticalstamp.io.files.available_memory_bytes", lambda: 1 << 30)
    _refused(_run("sfr", bomb), "bomb.png", "needs about")
    assert Image.MAX_IMAGE_PIXELS == before


def test_tiny_images_get_a_minimum_size_per_command(tmp_path):
    (tmp_path / "t.txt").write_text("text\n")
    for w, h in ((1, 1), (100_000, 1), (1, 100_000)):
        p = tmp_path / f"tiny_{w}x{h}.png"
        Image.new("L", (w, h), 255).save(p, dpi=(600, 600))
        for command, extra, need in (
            ("measure-rmtf", [], "8 x 8"),
            ("sfr", [], "16 x 16"),
            ("ocr-eval", ["--text", tmp_path / "t.txt", "--z", "1"], "32 x 32"),
        ):
            _refused(_run(command, p, *extra), p.name, "too small", need)


def test_grey_plus_alpha_tiff_reads_its_grey_channel(tmp_path):
    grey = _ramp()
    p = tmp_path / "grey_alpha.tif"
    p.write_bytes(_raw_tiff(np.stack([grey, np.full_like(grey, 255)], axis=-1), spp=2))
    img, dpi = read_image(p)
    np.testing.assert_allclose(img, grey / 255.0)
    assert dpi == 600


# -- 2. non-square pixels: refused naming both values, unless --dpi overrides --------------
def test_anisotropic_resolution_is_refused_unless_dpi_is_given(tmp_path):
    png, tif = tmp_path / "aniso.png", tmp_path / "aniso.tif"
    Image.fromarray(_ramp()).save(png, dpi=(600, 150))
    tif.write_bytes(_raw_tiff(_ramp(), xres=(600, 1), yres=(150, 1)))
    for p in (png, tif):
        for command in ("measure-rmtf", "sfr"):
            _refused(_run(command, p), p.name, "600", "150", "square", "--dpi")
        _refused(_run("scan", p, "-o", tmp_path / "o.png", "--z", "1"), p.name, "150")
        with pytest.raises(ImageError, match="not square"):
            read_image(p)
        img, dpi = read_image(p, dpi=600.0)  # --dpi overrides the file's resolution
        assert dpi == 600.0 and img.shape == (64, 64)
    # within 0.1 %: square (PNG stores pixels per metre)
    Image.fromarray(_ramp()).save(png, dpi=(600, 600.3))
    assert read_image(png)[1] == pytest.approx(600, abs=0.01)


# -- 3. NaN and infinity: refused in images and height maps ---------------------------------
def test_float_images_with_nan_or_inf_are_refused(tmp_path):
    for bad in (np.nan, np.inf, -np.inf):
        f = np.full((64, 64), 0.5, np.float32)
        f[3, 3] = bad
        p = tmp_path / f"float_{bad}.tif"
        tifffile.imwrite(p, f, resolution=(1200, 1200), resolutionunit="INCH")
        for command in ("measure-rmtf", "sfr"):
            _refused(_run(command, p), p.name, "NaN or infinite")
        res = _run("scan", p, "-o", tmp_path / "o.png", "--z", "1")
        _refused(res, p.name, "NaN or infinite")
        assert not (tmp_path / "o.png").exists()


def test_bad_height_map_files_are_refused(tmp_path):
    assert _run("chart", "edge", "-o", tmp_path / "e.png", "--dpi", "600").exit_code == 0
    good = np.full((32, 32), 1.0)
    cases = {
        "nan.npy": np.where(np.eye(32, dtype=bool), np.nan, good),
        "inf.npy": np.where(np.eye(32, dtype=bool), np.inf, good),
        "structured.npy": np.zeros((32, 32), dtype=[("a", "f8"), ("b", "i4")]),
        "complex.npy": good.astype(complex),
        "datetime.npy": np.zeros((32, 32), "datetime64[s]"),
        "string.npy": np.full((32, 32), "1.0"),
        "object.npy": np.full((32, 32), 1.0, dtype=object),
        "bool.npy": np.ones((32, 32), bool),
        "empty.npy": np.zeros((0, 0)),
        "vector.npy": np.ones(32),
    }
    for name, arr in cases.items():
        np.save(tmp_path / name, arr, allow_pickle=True)
    np.savez(tmp_path / "archive.npz", good)
    (tmp_path / "archive.npy").write_bytes((tmp_path / "archive.npz").read_bytes())
    (tmp_path / "garbage.npy").write_bytes(b"\x93NUMPY" + bytes(range(200)))
    nan_tif = np.full((32, 32), 1.0, np.float32)
    nan_tif[5, 5] = np.nan
    tifffile.imwrite(tmp_path / "nan.tif", nan_tif)
    names = [*cases, "archive.npy", "garbage.npy", "nan.tif"]
    for name in names:
        res = _run(
            "scan", tmp_path / "e.png", "-o", tmp_path / "o.png", "--height-map", tmp_path / name
        )
        _refused(res, name)
    for name, rule in (
        ("nan.tif", "NaN or infinite"),
        ("complex.npy", "real numbers"),
        ("archive.npy", ".npz"),
        ("empty.npy", "2-D"),
    ):
        res = _run(
            "scan", tmp_path / "e.png", "-o", tmp_path / "o.png", "--height-map", tmp_path / name
        )
        _refused(res, name, rule)


@pytest.mark.parametrize(
    "spec, rule",
    [
        ("crumple:1:inf", "SCALE"),
        ("crumple:1:nan", "SCALE"),
        ("crumple:1:1e9", "SCALE"),
        ("crumple:inf:10", "modelled range"),
        ("gutter:1e300:1e300", "modelled range"),
        ("gutter:3:1e300", "RADIUS"),
        ("gutter:3:-1", "RADIUS"),
        ("tilt:0:nan", "modelled range"),
        ("tilt:0:1e9", "modelled range"),
        ("tilt:-inf:0", "modelled range"),
        ("flat:inf", "modelled range"),
    ],
)
def test_bad_height_map_shapes_are_refused(spec, rule):
    with pytest.raises(HeightMapError, match=rule) as err:
        shape_map(spec, 50, 40)
    assert spec in str(err.value)


def test_bad_height_map_shape_on_the_command_line(tmp_path):
    assert _run("chart", "edge", "-o", tmp_path / "e.png", "--dpi", "600").exit_code == 0
    res = _run("scan", tmp_path / "e.png", "-o", tmp_path / "o.png", "--height-map", "tilt:0:1e9")
    _refused(res, "tilt:0:1e9", "modelled range")


# -- 4. the slanted-edge SFR of the tool's own chart and scan, default --direction auto ----
def _sane_sfr(res) -> dict:
    assert res.exit_code == 0, res.output
    d = json.loads(res.stdout)
    s = np.asarray(d["sfr"])
    assert np.all(np.isfinite(s)) and s.min() >= 0 and s.max() <= 1.2
    assert s[0] == pytest.approx(1.0) and s[1] == pytest.approx(1.0, abs=0.05)
    assert (
        np.isfinite(d["mtf50_cy_per_mm"]) and 0 < d["mtf50_cy_per_mm"] < d["nyquist_cy_per_mm"] * 2
    )
    assert d["direction"] == "x" and abs(abs(d["edge_angle_deg"]) - 5) < 0.5
    return d


def test_sfr_of_the_edge_chart_and_its_scan(tmp_path):
    e = tmp_path / "e.png"
    assert _run("chart", "edge", "-o", e).exit_code == 0
    chart = _sane_sfr(_run("sfr", e, "--json"))
    assert chart["sfr_at_dpi"]["200"] > 0.95  # a 1200-dpi chart is sharp at 200 dpi
    res = _run("scan", e, "-o", tmp_path / "s.png", "--z", "1")
    assert res.exit_code == 0, res.output
    scan = _sane_sfr(_run("sfr", tmp_path / "s.tif", "--json"))
    both = _run("sfr", tmp_path / "s.tif", "--direction", "both", "--json")
    x = json.loads(both.stdout)["x"]
    assert scan["mtf50_cy_per_mm"] == pytest.approx(x["mtf50_cy_per_mm"], rel=1e-6)
    assert scan["mtf50_cy_per_mm"] < chart["mtf50_cy_per_mm"]


def test_sfr_refuses_regions_with_more_than_one_edge(tmp_path):
    e = tmp_path / "e.png"
    assert _run("chart", "edge", "-o", e).exit_code == 0
    for args, words in (
        (["--direction", "x"], ("more than one edge",)),
        (["--direction", "y"], ("more than one edge",)),
        (["--roi", "0,0,200,472"], ("side to side",)),  # a whole side and two corners
    ):
        _refused(_run("sfr", e, *args), "e.png", *words)
    # a slanted dark bar: two opposite edges in a row (grey at its edges: an image of two
    # grey levels is refused before its edges are counted)
    yy, xx = np.mgrid[0:120, 0:120]
    stripe = 0.9 - 0.8 * np.clip(12.5 - np.abs(xx - 60 - 0.09 * (yy - 60)), 0, 1)
    p = tmp_path / "bar.png"
    Image.fromarray((stripe * 255).astype(np.uint8)).save(p, dpi=(600, 600))
    _refused(_run("sfr", p), "bar.png", "more than one edge")


def test_sfr_normalisation_guard_refuses_two_edges(monkeypatch):
    """Were the edge count fooled, the fit across two opposite edges (LSF integral about 0:
    an SFR of 1e14 before) must still end in a ValueError, not in numbers."""
    from opticalstamp.imaging import measure
    from opticalstamp.imaging.charts import edge_chart

    img = edge_chart(1200.0)
    ones = (np.ones(img.shape[0], int), np.ones(img.shape[1], int))
    monkeypatch.setattr(measure, "_transitions", lambda _: ones)
    with pytest.raises(ValueError, match="no single step|lowest frequency"):
        measure.sfr(img, 1200.0, direction="x")
