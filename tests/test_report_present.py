"""Report presentation: SI prefixes and numbers without e-notation, one style per realisation
across figures, kernel and spectrum colour scales, the opening verdict, rebuilding a report."""

from __future__ import annotations

import doctest
import math

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from fsdvs_hw.errors import InputError
from fsdvs_hw.kernels import Kernel, reference_kernel
from fsdvs_hw.realise.registry import REALISATIONS
from fsdvs_hw.records import Cost, ScoredPoint
from fsdvs_hw.report import figures, present
from fsdvs_hw.report.html import _quantities
from fsdvs_hw.report.present import number, point_title, si, style
from fsdvs_hw.report.redraw import write_report_from_scores
from fsdvs_hw.report.tables import score_rows
from fsdvs_hw.report.verdict import advice, verdict_table

THIN = "\u2009"


def test_si_prefixes_by_hand():
    # BIPM SI brochure §3: the prefix brings the number into [1, 1000); µm² = (µm)²
    assert si(0.0001, "m") == "100 µm"
    assert si(6.04e-6, "s") == "6.04 µs"
    assert si(9.381e-8, "S") == "93.8 nS"
    assert si(2e-9, "m^2") == "2000 µm²"
    assert si(3e-12, "m^2") == "3 µm²"
    assert si(1e-13, "F") == "100 fF"
    assert si(0.0009997, "m") == "1 mm"  # rounding carries into the next prefix
    assert si(-1.285e-5, "m") == "-12.9 µm"
    assert si(64.0, "count") == "64" and si(0.4223, "1") == "0.422" and si(4, "bit") == "4 bit"
    assert si(math.nan, "m") == "–"
    assert doctest.testmod(present).failed == 0


def test_number_by_hand():
    assert number(0.0423) == "0.0423" and number(4220.3) == "4220" and number(0.93612) == "0.936"
    assert number(29696) == f"29{THIN}696" and number(123456.7) == f"123{THIN}457"
    assert number(-0.000437) == "-4.37 × 10⁻⁴" and number(1.5e-16) == "1.5 × 10⁻¹⁶"
    assert number(9.9996e-5) == "1 × 10⁻⁴"  # the mantissa's rounding carries into the exponent
    assert number(math.nan) == "–" and number(None) == "–"


_floats = st.floats(allow_nan=False, allow_infinity=False, min_value=-1e30, max_value=1e30)


@given(_floats)
def test_number_never_e_notation_and_round_trips(v):
    text = number(v)
    assert "e" not in text.lower() or text in ("–",)
    if text.count("×") == 0:
        back = float(text.replace(THIN, ""))
        assert back == pytest.approx(v, rel=5e-3, abs=5e-4)
    else:
        mant, exp = text.split(" × 10")
        back = float(mant) * 10 ** int(exp.translate(str.maketrans("⁻⁰¹²³⁴⁵⁶⁷⁸⁹", "-0123456789")))
        assert back == pytest.approx(v, rel=5e-3)


@given(st.floats(min_value=1e-17, max_value=1e14), st.sampled_from(["m", "s", "S", "F", "m^2", "Hz"]))
def test_si_number_lies_in_one_to_a_thousand(v, unit):
    text = si(v, unit)
    assert "e" not in text.split(" ")[0] and "×" not in text or v < 1e-15 or v > 1e12
    head = text.split(" ")[0]
    if "×" not in text:
        lim = 1e6 if unit == "m^2" else 1000
        assert 1 <= float(head.replace(THIN, "")) <= lim or v < 1e-15 or v >= 1e12


def test_one_style_per_realisation_distinct_colours_and_markers():
    styles = {n: style(n) for n in REALISATIONS}
    for n, s in styles.items():
        if REALISATIONS[n].colour:
            assert s.colour == REALISATIONS[n].colour  # the registry's colour, everywhere
    assert len({s.colour for s in styles.values()}) == len(styles)
    assert len({s.marker for s in styles.values()}) == len(styles)
    assert styles["asic"].title == "ASIC taps" and styles["mesh"].title == "resistive mesh"
    assert point_title("asic", '{"asic.bits": 4}') == "ASIC taps (bits 4)"
    assert style("not_registered") == style("not_registered")  # stable


def test_kernel_colour_limit_shows_the_surround():
    taps = np.full((7, 7), -0.02)
    taps[3, 3] = 0.91
    taps[2, 3] = 0.10
    vmax, clipped = figures.kernel_colour_limit(taps)
    assert clipped and vmax == pytest.approx(0.10)  # not the centre's 0.91: the surround stays visible
    flat = np.full((5, 5), 0.3)
    assert figures.kernel_colour_limit(flat) == (pytest.approx(0.3), False)
    assert figures.kernel_colour_limit(np.zeros((3, 3))) == (1.0, False)


def _panels():
    target = reference_kernel("dog", 7, pitch_m=4.86e-6)
    delta = reference_kernel("delta", 7, pitch_m=4.86e-6)
    scaled = Kernel(target.taps * 3.0, pitch_m=target.pitch_m, name="x3")
    return [
        figures.Panel("learned", "learned", target),
        figures.Panel("delta", "delta", delta),
        figures.Panel("asic", "asic", scaled),
    ]


def test_kernel_panels_zero_centred_each_with_a_colour_bar_and_spectra_on_one_scale():
    import matplotlib.pyplot as plt

    panels = _panels()
    fig = figures.fig_kernels(panels)
    images = [ax.images[0] for ax in fig.axes if ax.images]
    assert len(images) == 3
    lims = [im.get_clim() for im in images]
    assert all(lo == pytest.approx(-hi) for lo, hi in lims)  # centred at zero
    assert len({round(hi, 9) for _, hi in lims}) == 3  # each panel on its own scale
    assert len(fig.axes) == 6  # every panel has its colour bar
    plt.close(fig)
    fig = figures.fig_spectra(panels)
    images = [ax.images[0] for ax in fig.axes if ax.images]
    assert len({im.get_clim() for im in images}) == 1  # one shared scale ...
    assert len(fig.axes) == 3 + 1  # ... and one colour bar
    peak = max(float(np.max(im.get_array())) for im in images)
    assert images[0].get_clim() == (0.0, pytest.approx(peak))
    plt.close(fig)


def _row_point(key, realisation, corr, cost, loss):
    h = 0.004
    ci = {
        "estimate": loss,
        "low": loss - h,
        "high": loss + h,
        "half_width": h,
        "confidence": 0.95,
        "n_clips": 64,
        "n_seeds_reference": 3,
        "text": f"no measurable loss (± {h:.3f})"
        if loss - h <= 0 <= loss + h
        else f"{loss:.3f} [{loss - h:.3f}, {loss + h:.3f}]",
    }
    res = {
        "kind": realisation,
        "kernel": reference_kernel("delta", 3, pitch_m=5e-6).to_dict(),
        "kernel_error": 0.1,
        "csf": {"mannos_sakrison_1974": {"correlation": corr}, "fitted_scale": {"correlation": corr}},
        "cost": cost,
        "wall_s": {"fit": 0.1},
        "tasks": {"status": "ok"},
    }
    params = {"asic.bits": key} if realisation == "asic" else {}
    return {
        "key": str(key),
        "realisation": realisation,
        "params": params,
        "status": "ok",
        "result": res,
        "wall_s": 0.2,
        "paired_loss": {"status": "ok", "reference": "L", "simulator": {"weighted": ci}},
    }


def test_verdict_recommends_the_cheapest_undominated_point_without_measurable_loss():
    add = lambda n: {"adders": {"value": n, "unit": "count"}}
    pts = [
        _row_point("L", "learned", 0.9, {}, 0.0),
        _row_point(2, "asic", 0.7, add(10), 0.08),
        _row_point(4, "asic", 0.88, add(30), 0.001),
        _row_point(8, "asic", 0.9, add(70), 0.0),
        _row_point("m", "metalens", 0.5, {"aperture_diameter": {"value": 1e-4, "unit": "m"}}, 0.2),
    ]
    pts[0]["key"] = "L"
    rows = score_rows([ScoredPoint.from_dict(p) for p in pts])
    lines = advice(rows)
    # the first question first: no matched-rate control ran, so it is said to be unanswered
    assert lines[0].startswith("First question, not answered") and "not requested" in lines[0]
    assert lines[1].startswith(
        "Build ASIC taps (bits 4) (adders 30; no measurable loss (± 0.004), n = 64 clips, 3 seeds"
    )
    assert "bits 8" not in lines[1]  # tied in loss, dearer: the cheaper one is built
    ladder = next(s for s in lines if s.startswith("ASIC taps by budget"))
    assert ladder.index("adders 10") < ladder.index("adders 30")  # ordered by the kind's own cost
    assert "Not recommended" in lines[-1] and "metalens, loss 0.200 [0.196, 0.204]" in lines[-1]
    assert "bits 2" not in lines[-1]  # dominated across kinds, but the cheapest step of the ASIC's ladder
    table = {v["realisation"]: v for v in verdict_table(rows)}
    assert table["ASIC taps (bits 4)"]["verdict"] == "build"
    assert table["ASIC taps (bits 2)"]["verdict"] == "a cheaper option of its kind"
    assert table["metalens"]["verdict"] == "not recommended"  # the table says what the sentences say
    assert table["learned kernel (ideal)"]["loss"] == "0 (the reference)"
    assert table["metalens"]["cost"] == "aperture 100 µm"  # SI prefix, not 0.0001 m
    assert table["ASIC taps (bits 2)"]["n"] == "n = 64 clips, 3 seeds"
    assert all("e-" not in c for v in table.values() for c in v.values())


def test_quantities_each_once_with_definition():
    cost = {
        "lambda_narrow_px": {"value": 1.1, "unit": "px"},
        "lambda_narrow_m": {"value": 5.35e-6, "unit": "m", "description": "narrow space constant"},
        "kernel_error": {"value": 0.2, "unit": "1"},
        "fit_time": {"value": 1.0, "unit": "s"},
        "numerical_aperture": {"value": 0.4223, "unit": "1", "description": "largest local NA of the phase"},
    }
    rows = _quantities("mesh", Cost.from_dict(cost))
    assert rows == [
        {"item": "λ narrow", "value": "5.35 µm (1.1 px)", "definition": "narrow space constant"},
        {"item": "numerical aperture", "value": "0.422", "definition": "largest local NA of the phase"},
    ]


def test_write_report_from_scores_refuses_what_is_not_a_run(tmp_path):
    with pytest.raises(InputError, match="no scores.json"):
        write_report_from_scores(tmp_path, object())
    (tmp_path / "scores.json").write_text("{not json")
    with pytest.raises(InputError, match="not JSON"):
        write_report_from_scores(tmp_path, object())
    (tmp_path / "scores.json").write_text('{"rows": [], "points": [{"status": "ok"}]}')
    with pytest.raises(InputError, match=r"points\[0\]: missing field 'key'"):
        write_report_from_scores(tmp_path, object())
    (tmp_path / "scores.json").write_text('{"rows": [], "points": []}')
    with pytest.raises(InputError, match="design must be a loaded design"):
        write_report_from_scores(tmp_path, "designs/default.toml")


def test_write_report_from_scores_refuses_a_malformed_codesign_json(tmp_path):
    """The redraw of a [codesign] run reads the run's codesign.json: a broken one is an InputError naming it."""
    from fsdvs_hw.design import load_design
    from fsdvs_hw.explore.reporting import report_input

    report = report_input(load_design("designs/codesign.toml"))
    (tmp_path / "scores.json").write_text('{"points": []}')
    for bad, match in (("{not json", "not JSON"), ("[1, 2]", "expected a JSON object with a 'cells' list")):
        (tmp_path / "codesign.json").write_text(bad)
        with pytest.raises(InputError, match=rf"codesign.json: not a co-design summary \({match}"):
            write_report_from_scores(tmp_path, report, to=tmp_path / "redrawn")


def test_each_realisation_keeps_its_registry_colour_and_marker_in_every_figure():
    import matplotlib.pyplot as plt
    from matplotlib.colors import to_hex

    panels = _panels()
    fig = figures.fig_radial(panels, methods=["mannos_sakrison_1974"], pitch_m=4.86e-6, focal_length_m=4e-3)
    for ax in fig.axes[:2]:
        lines = {ln.get_label(): ln for ln in ax.get_lines()}
        for pan in panels:
            assert to_hex(lines[pan.label].get_color()) == style(pan.realisation).colour
            assert lines[pan.label].get_marker() == style(pan.realisation).marker
    plt.close(fig)
    add = lambda n: {"adders": {"value": n, "unit": "count"}}
    rows = score_rows(
        [
            ScoredPoint.from_dict(p)
            for p in (
                _row_point("L", "learned", 0.9, {}, 0.0),
                _row_point(4, "asic", 0.88, add(30), 0.001),
                _row_point("m", "metalens", 0.5, {"aperture_diameter": {"value": 1e-4, "unit": "m"}}, 0.2),
            )
        ]
    )
    for make in (figures.fig_pareto, figures.fig_speed):
        fig = make(rows)
        handles, labels = fig.axes[0].get_legend_handles_labels()
        seen = {}
        for h, lab in zip(handles, labels):
            line = h[0] if isinstance(h, tuple) else h  # errorbar containers: the data line first
            colour = line.get_color() if hasattr(line, "get_color") else line.get_edgecolor()[0]
            seen[lab] = to_hex(colour)
        for name in ("asic", "metalens"):
            assert seen[style(name).title] == style(name).colour, (make.__name__, name)
        plt.close(fig)


@pytest.mark.parametrize("args", [["--out", "{f}"], ["--out", "{d}", "--to", "{f}"], ["--out", "{d}"]])
def test_report_verb_errors_are_one_line(args, tmp_path, capsys):
    from pathlib import Path

    from fsdvs_hw.cli import main

    f = tmp_path / "a_file"
    f.write_text("x")
    d = tmp_path / "empty"
    d.mkdir()
    design = Path(__file__).resolve().parents[1] / "designs" / "default.toml"
    assert main(["report", str(design)] + [a.format(f=f, d=d) for a in args]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "Traceback" not in err and ("a_file" in err or "no scores.json" in err)


HOSTILE = "<script>alert('x')</script> & co"


def test_labels_with_markup_are_escaped_in_the_html():
    """The templates autoescape: a design name, a realisation, a failure reason, artifact names and
    co-design labels holding ``<script>`` and ``&`` appear as text, never as markup."""
    from fsdvs_hw.design import parse_design
    from fsdvs_hw.explore.reporting import report_input
    from fsdvs_hw.report.artifact_links import artifacts_html
    from fsdvs_hw.report.codesign_section import codesign_section
    from fsdvs_hw.report.html import render_html
    from fsdvs_hw.report.report_input import CodesignSummary

    design = parse_design({"design": {"name": HOSTILE}})
    failed = {
        "key": "k",
        "realisation": HOSTILE,
        "params": {},
        "status": "error",
        "result": {"reason": f"RuntimeError: {HOSTILE}"},
        "artifacts": [{"point": HOSTILE, "error": HOSTILE}],
    }
    page = render_html(
        [ScoredPoint.from_dict(failed)], report_input(design), stamp="now", sections=["<h2>given as HTML</h2>"]
    )
    escaped = "&lt;script&gt;alert(&#39;x&#39;)&lt;/script&gt; &amp; co"
    assert "<script" not in page and HOSTILE not in page
    assert page.count(escaped) >= 5  # title, heading, not-scored row (name and reason), artifacts, design JSON
    assert "<h2>given as HTML</h2>" in page  # a section is a fragment of HTML, kept as given
    frag = artifacts_html(
        [
            ScoredPoint.from_dict(
                {
                    "key": "a",
                    "realisation": "asic",
                    "status": "error",
                    "artifacts": [
                        {"point": "asic", "name": "v", "file": "a&b <c>.v", "what": HOSTILE, "checked_by": HOSTILE}
                    ],
                }
            )
        ]
    )
    assert '<a href="a%26b%20%3Cc%3E.v">a&amp;b &lt;c&gt;.v</a>' in frag and "<script" not in frag
    assert f"<code>{escaped}</code>" in frag
    table = codesign_section(CodesignSummary.from_dict({"settings": {"epochs": HOSTILE}, "cells": []}))
    assert f"{escaped} epochs" in table and "<script" not in table
