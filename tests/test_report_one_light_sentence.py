"""The verdict box's sentence on the engines of the analyses of one light (the spots, the
scans and the restoration) says what each section recorded that it ran by, not a fixed
"ray optics": they follow the report's optics (wave optics for the prototype under
--optics auto), a colour scanner's are ray optics and say why."""

from __future__ import annotations

import pytest

from opticalstamp.report.html.page import one_light_sentence
from opticalstamp.report.summary import one_light_engines

NAMES = ("spots", "scans", "restoration")


def _data(engine: str) -> dict:
    """report.json's sections of one light, each recording ``engine`` as it does."""
    return {
        "spots": {"meta": {"optics": {"engine": engine}}},
        "scans": {"optics": engine},
        "restoration": {"optics": engine},
    }


@pytest.mark.parametrize("engine", ["ray", "wave"])
def test_the_engines_are_those_the_sections_recorded(engine):
    assert one_light_engines(_data(engine)) == dict.fromkeys(NAMES, engine)
    mixed = _data("ray") | {"scans": {"optics": "wave"}}
    assert one_light_engines(mixed) == {"spots": "ray", "scans": "wave", "restoration": "ray"}
    # a section not measured says nothing about its engine
    gone = _data(engine) | {"restoration": {"not_measurable": "why"}}
    assert one_light_engines(gone) == {"spots": engine, "scans": engine}


def test_the_sentence_names_each_analysis_by_its_engine():
    wave = one_light_sentence(dict.fromkeys(NAMES, "wave"))
    assert wave.startswith("Ghosts and PSFs are ray optics;")
    assert "the spots, scans and restoration are by wave optics" in wave
    ray = one_light_sentence(dict.fromkeys(NAMES, "ray"))
    assert ray == "Ghosts, spots, scans, restoration and PSFs are ray optics."
    assert "wave" not in ray
    mixed = one_light_sentence({"spots": "wave", "scans": "ray", "restoration": "ray"})
    assert mixed.startswith("Ghosts, scans, restoration and PSFs are ray optics;")
    assert "the spots are by wave optics" in mixed
    # a report.json from before the engines were recorded: all ray optics then
    assert one_light_sentence(None) == ray
    rgb = one_light_sentence(
        dict.fromkeys(NAMES, "ray"), {"engine": "ray", "reason": "ray optics: rgb <lit>"}
    )
    assert rgb.endswith("and so are the spots, scans and restoration here (rgb &lt;lit&gt;).")
    lit = {"engine": "ray", "reason": "ray optics: rgb"}
    colour = one_light_sentence(dict.fromkeys(NAMES, "wave"), lit)
    assert colour == (
        "Ghosts and PSFs are ray optics; the spots are by wave optics, channel by channel "
        "(the widest shown); the scans and restoration are by wave optics, grey scans under "
        "the three LEDs lit together at the luminance weights."
    )
