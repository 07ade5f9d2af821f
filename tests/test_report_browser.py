"""The HTML report in a real headless browser: Playwright driving the Debian ``chromium`` package.

A small exploration (learned, delta, 4-bit ASIC taps, resistive mesh; no task networks) is run
once, paired task losses with CIs are attached to its stored points (the shape ``explore`` gives
them), and the report is loaded offline from ``file://`` at a 1280×800 viewport. Checked: no
console errors, page errors or failed requests; nothing but the file itself and inline data is
requested; the page does not scroll sideways, with every ``<details>`` toggle closed or open;
every image or SVG sits in a ``<figure>`` with a caption and an alt text of several words, drawn
at twice its displayed size; the verdict comes first.

Needs ``pip install playwright`` (the ``test`` extra) and Debian's ``chromium`` (``make
system-deps``); Playwright's own browser download is not used. Set ``FSDVS_CHROMIUM`` to another
Chromium binary, and ``FSDVS_REPORT_SHOTS`` to a folder to keep 1280×800 screenshots.
"""

from __future__ import annotations

import json
import os
import re
import shutil
from pathlib import Path

import pytest

from fsdvs_hw.cli import main
from fsdvs_hw.design import load_design
from fsdvs_hw.explore.reporting import report_input
from fsdvs_hw.records import ScoredPoint
from fsdvs_hw.report import write_report

VIEWPORT = {"width": 1280, "height": 800}


def _chromium() -> str | None:
    env = os.environ.get("FSDVS_CHROMIUM")
    if env:
        return env if Path(env).is_file() else None
    for name in ("chromium", "chromium-browser", "google-chrome"):
        found = shutil.which(name)
        if found:
            return found
    return None


sync_api = pytest.importorskip(
    "playwright.sync_api", reason="Playwright is not installed (pip install playwright; it is in the 'test' extra)"
)
CHROMIUM = _chromium()
pytestmark = pytest.mark.skipif(
    CHROMIUM is None,
    reason="no Chromium binary: install the Debian package "
    "(apt-get install chromium; `make system-deps` does) or set FSDVS_CHROMIUM",
)


def _ci(est: float, h: float, n: int, seeds: int) -> dict:
    lo, hi = est - h, est + h
    text = f"no measurable loss (± {h:.3f})" if lo <= 0 <= hi else f"{est:.3f} [{lo:.3f}, {hi:.3f}]"
    return {
        "estimate": est,
        "low": lo,
        "high": hi,
        "half_width": h,
        "confidence": 0.95,
        "n_clips": n,
        "n_seeds_reference": seeds,
        "text": text,
    }


@pytest.fixture(scope="module")
def report(tmp_path_factory) -> Path:
    tmp = tmp_path_factory.mktemp("browser")
    design = tmp / "tiny.toml"
    design.write_text(
        '[realisations]\ninclude = ["learned", "delta", "asic", "mesh"]\n[realisations.asic]\nbits = 4\n'
        '[analysis]\ncsf_methods = ["mannos_sakrison_1974", "barten_1999"]\n'
        "[emulation]\nenabled = false\n[run]\nworkers = 1\n"
    )
    assert main(["explore", str(design), "--out", str(tmp / "run"), "--no-progress"]) == 0
    points = json.loads((tmp / "run" / "scores.json").read_text())["points"]
    ref = next(p["key"] for p in points if p["realisation"] == "learned")
    losses = {"learned": (0.0, 0.0), "delta": (0.09, 0.004), "asic": (0.012, 0.004), "mesh": (0.001, 0.003)}
    for p in points:  # the shape explore attaches (fsdvs_hw.explore.scoring.with_paired_losses)
        est, h = losses[p["realisation"]]
        p["paired_loss"] = {
            "status": "ok",
            "reference": ref,
            "simulator": {
                "detection": _ci(est, h, 64, 3),
                "recognition": _ci(est * 1.5, h, 384, 3),
                "weighted": _ci(est * 1.25, h, 448, 3),
                "weights": {"detection": 1.0, "recognition": 1.0},
            },
        }
    return write_report([ScoredPoint.from_dict(p) for p in points], report_input(load_design(design)), tmp / "report")


def _open(page, path: Path, problems: list[str]) -> None:
    page.on(
        "console", lambda m: problems.append(f"console {m.type}: {m.text}") if m.type in ("error", "warning") else None
    )
    page.on("pageerror", lambda e: problems.append(f"page error: {e}"))
    page.on("requestfailed", lambda r: problems.append(f"request failed: {r.url}"))

    def only_local(route):  # offline: the report may load itself and inline data, nothing else
        url = route.request.url
        if url.startswith(("file://", "data:")):
            route.continue_()
        else:
            problems.append(f"request to the network: {url}")
            route.abort()

    page.route("**/*", only_local)
    page.goto(path.as_uri(), wait_until="load")


def test_report_in_headless_chromium(report: Path) -> None:
    problems: list[str] = []
    with sync_api.sync_playwright() as pw:
        browser = pw.chromium.launch(executable_path=CHROMIUM, args=["--no-sandbox"])
        try:
            page = browser.new_page(viewport=VIEWPORT)
            _open(page, report, problems)
            shots = os.environ.get("FSDVS_REPORT_SHOTS")
            if shots:
                Path(shots).mkdir(parents=True, exist_ok=True)
                page.screenshot(path=str(Path(shots) / "report_1280x800.png"))
            width = page.evaluate("Math.max(document.documentElement.scrollWidth, document.body.scrollWidth)")
            assert width <= VIEWPORT["width"], f"page is {width} px wide at a 1280 px window"
            n_details = page.evaluate("document.querySelectorAll('details').length")
            assert n_details >= 5  # the long tables are behind toggles
            page.evaluate("document.querySelectorAll('details').forEach(d => d.open = true)")
            width_open = page.evaluate("Math.max(document.documentElement.scrollWidth, document.body.scrollWidth)")
            assert width_open <= VIEWPORT["width"], f"with every toggle open the page is {width_open} px wide"
            if shots:
                page.screenshot(path=str(Path(shots) / "report_1280x800_open_full.png"), full_page=True)
            figs = page.evaluate("""() => [...document.querySelectorAll('img, svg')].map(el => {
                const fig = el.closest('figure');
                const cap = fig ? fig.querySelector('figcaption') : null;
                return {tag: el.tagName, alt: el.getAttribute('alt') || el.getAttribute('aria-label') || '',
                        inFigure: !!fig, caption: cap ? cap.textContent.trim() : '',
                        natural: el.naturalWidth || 0, shown: el.getBoundingClientRect().width,
                        declared: Number(el.getAttribute('width') || 0), complete: el.complete !== false};
            })""")
            assert len(figs) >= 5
            for f in figs:
                assert f["inFigure"], f"an {f['tag']} outside a <figure>: {f['alt']!r}"
                assert len(f["caption"].split()) >= 8, f"figure {f['alt']!r} has no real caption: {f['caption']!r}"
                assert len(f["alt"].split()) >= 6, f"alt text of a few words needed, got {f['alt']!r}"
                if f["tag"] == "IMG":
                    assert f["complete"] and f["natural"] > 0, f"image did not load: {f['alt']!r}"
                    assert f["natural"] == 2 * f["declared"], "figures are drawn at 2x their displayed size"
                    assert 0 < f["shown"] <= VIEWPORT["width"]
            order = page.evaluate("[...document.querySelectorAll('h2, figure')].map(e => e.id || e.tagName)")
            assert order[0] == "verdict", f"the report must open with the verdict, not {order[:2]}"
            verdict = page.inner_text("table.verdict")
            assert "ASIC taps" in verdict and "resistive mesh" in verdict and "asic" not in verdict.split()
            assert "0.015 [0.011, 0.019]" in verdict  # the ASIC's weighted loss with its CI ...
            assert "448 clips, 3 seeds" in verdict  # ... and n
            prose = page.evaluate("""() => { const b = document.body.cloneNode(true);
                b.querySelectorAll('pre, code').forEach(e => e.remove()); return b.textContent; }""")
            assert not re.search(r"\de[-+]?\d", prose), "e-notation in the prose or tables (JSON in <pre> is data)"
        finally:
            browser.close()
    assert not problems, "\n".join(problems)
