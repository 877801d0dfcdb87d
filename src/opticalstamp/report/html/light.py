"""The page's light sections: "Light efficiency" with the sensitive-area study, and
"Signal and noise"."""

from __future__ import annotations

import html
import math

from .common import percent, table, unmeasured


def efficiency_html(e: dict, signal: dict | None = None, paper: bool = False) -> str:
    """Light efficiency (paper Fig. 13) against the reference lens, the sensitive-area
    study and the "Signal and noise" block (``signal``: report.json's "signal");
    ``paper``: with the paper's own figures."""
    title = "Light efficiency (paper Fig. 13)"
    missing = unmeasured(title, e)
    if missing is not None:
        return missing
    o = e.get("meta", {}).get("optics", {})
    wave = o.get("engine") == "wave"
    eff_rows = [
        [
            "own path with its diffraction, the light in the wave band: the signal (headline)"
            if wave
            else "own path: the signal (the headline figure)",
            e["etendue_own_um2sr"],
            e["ratio_own"],
            1 / e["ratio_own"] if e["ratio_own"] else None,  # no light: no inverse
            e["working_f_number_own"],
        ],
        [
            "all light: wave band + traced far ghosts (crosstalk)"
            if wave
            else "own + ghost light (ghost light is crosstalk)",
            e["etendue_um2sr"],
            e["ratio"],
            1 / e["ratio"] if e["ratio"] else None,
            e["working_f_number"],
        ],
    ]
    if wave:  # the ray figures the wave ones replace
        g_ref = e["reference_etendue_um2sr"]
        eff_rows += [
            [
                f"ray optics: {name}",
                g,
                g / g_ref,
                g_ref / g if g else None,
                e["reference_f_number"] / (g / g_ref) ** 0.5 if g else None,
            ]
            for name, g in (
                ("own path (geometric)", o["ray_etendue_own_um2sr"]),
                ("own + ghost light", o["ray_etendue_um2sr"]),
            )
        ]
    eff_rows += [["paper (Fig. 13)", None, 1 / 36, 36.0, 60.0]] if paper else []
    area_rows = [
        [
            a["sensitive_um"][0],
            a["area_scale"],
            a["gain_own_vs_design"],
            a["gain_vs_design"],
            a["ghost_fraction"],
        ]
        for a in e["sensitive_area"]
    ]
    return f"""<h2>{title}</h2>
<p>Reference: 1:1 lens, f = 10 mm, 2 mm pupil, 20 mm conjugates, a pixel of the
design's output pitch ({e["meta"]["reference_lens"]["pixel_um"]:.1f} µm; the paper's 84.6 µm):
{e["reference_etendue_um2sr"]:.4g} µm²·sr (working F {e["reference_f_number"]:g}).</p>
{table(eff_rows, ["light", "etendue (µm²·sr)", "ratio", "1/ratio", "working F"])}
{channels_html(o, e["reference_etendue_um2sr"])}{area_html(area_rows)}
<img src="efficiency.png">
{signal_html(signal, e)}
"""


def channels_html(o: dict, g_ref: float) -> str:
    """A colour scanner's light per channel (the efficiency's ``meta["optics"]``), the
    headline (the weakest signal) marked, and the rule; empty for one light."""
    chans = o.get("channels")
    if not chans:
        return ""
    from ...analysis.colour import LIGHT_RULE

    head = o["headline"]["channel"]
    rows = [
        [
            name + (" — the headline" if name == head else ""),
            c["wave_in_band_um2sr"],
            c["wave_in_band_um2sr"] / g_ref,
            g_ref / c["wave_in_band_um2sr"] if c["wave_in_band_um2sr"] else None,
            c["etendue_um2sr"],
            c["traced_at_um"],
        ]
        for name, c in chans.items()
    ]
    return f"""<h3>Colour: the light per LED (illumination rgb)</h3>
<p>The signal above is the <b>{html.escape(head)}</b> channel's: {html.escape(LIGHT_RULE)}.</p>
{
        table(
            rows,
            [
                "channel",
                "signal: wave in band (µm²·sr)",
                "ratio",
                "1/ratio",
                "all light (µm²·sr)",
                "far light traced at (µm)",
            ],
        )
    }
"""


def signal_html(s: dict | None, eff: dict | None = None) -> str:
    """The "Signal and noise" block: a used pixel's electrons and temporal SNR at white and
    18 % grey with the design's electronics, and the exposure and line rate for the target
    SNR. ``s``: report.json's "signal" (None: no block); ``eff``: its "efficiency" (for
    the ghost light a white page adds)."""
    if not s:
        return ""
    missing = unmeasured("Signal and noise", s, level=3)
    if missing is not None:
        return missing

    def num(v: float) -> str:  # whole numbers from 100 up, three digits below
        return f"{v:,.0f}" if abs(v) >= 100 else f"{v:.3g}"

    el = s["electronics"]
    grey = s["electrons_grey18"] / s["electrons_white"] if s["electrons_white"] > 0 else 0.18
    well = el["full_well_e"]
    dark = el["dark_current_e_per_s"] * el["exposure_ms"] * 1e-3
    rows = [
        [name, num(e), f"{100 * e / well:.3g} %", "clipped" if e + dark > well else f"{snr:.3g}"]
        for name, e, snr in (
            ("white", s["electrons_white"], s["snr_white"]),
            (f"{100 * grey:.0f} % grey", s["electrons_grey18"], s["snr_grey18"]),
        )
    ]
    ghost = ""
    if eff and s["etendue_own_um2sr"] > 0:
        more = eff["etendue_um2sr"] / s["etendue_own_um2sr"]
        ghost = (
            f". The table counts the own path (the signal); a white page adds its ghost "
            f"light, {percent(100 * (more - 1))} % more: {num(s['electrons_white'] * more)} e- at "
            "white in all, the figure <code>opticalstamp scan</code> prints"
        )
    target = (
        f"SNR {s['target_snr_white']:g} at white needs an exposure of "
        f"<b>{s['exposure_for_target_ms']:.3g} ms</b> per line: at most "
        f"<b>{num(s['max_line_rate_for_target_hz'])} lines/s</b>"
        + ("" if el["exposure_duty"] == 1 else f" (exposing {el['exposure_duty']:g} of a line)")
    )
    if s["saturates_at_target"]:
        target += (
            ", more than the full well holds: out of reach (a full well gives an SNR of at "
            f"most about {math.sqrt(well):.0f})"
        )
    fill = 100 * s["full_well_fraction_white"]
    warn = (
        f"<p><b>warning:</b> white saturates the pixels ({fill:.0f} % of the full well with "
        f"the dark signal): an exposure below {s['exposure_to_full_well_ms']:.3g} ms or less "
        "light keeps it in range.</p>"
        if s["saturated_white"]
        else ""
    )
    return f"""<h3>Signal and noise</h3>
<p>A used pixel with the design's electronics ({el["illuminance_lux"]:,.0f} lux on the
page, {el["exposure_ms"]:.3g} ms per line, QE {el["quantum_efficiency"]:.2g},
{well:,.0f} e- full well, {el["read_noise_e"]:.3g} e- read noise,
{el["adc_bits"]}-bit ADC; a design file's <code>[electronics]</code>) and its own-path
etendue of {s["etendue_own_um2sr"]:.4g} µm²·sr{ghost}. Temporal SNR: photon and dark
shot noise, read noise, quantisation (the shading correction removes PRNU).</p>
{table(rows, ["reflectance", "electrons (own path)", "of the full well", "SNR"])}
<p>{target}.</p>
{warn}"""


def area_html(area_rows: list) -> str:
    """The sensitive-area study, where it could be run (a larger area that fits the pitch)."""
    if len(area_rows) < 2:
        return (
            "<p>Sensitive-area study: not run (a sensitive area twice as wide would not fit "
            "between this design's used pixels).</p>"
        )
    return (
        "<p>Effect of the sensitive-area size: a custom sensor whose used pixels are larger "
        "than this sensor's pitch allows, as large as the used-pixel lattice leaves room "
        "for (the paper, §5, expects 4x the light from 4x the area):</p>"
        + table(
            area_rows, ["side (µm)", "area ratio", "own-path gain", "total gain", "ghost fraction"]
        )
    )
