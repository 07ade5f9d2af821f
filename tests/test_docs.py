"""The documentation site builds warning-free, and what it generates is what the records hold.

``mkdocs build --strict`` (mkdocs.yml at the top level) turns every warning into a failure: a broken
link or anchor, a page missing from the docs folder, a docstring section griffe cannot parse. The
whole site (user guide, API pages of every public module, generated tables) builds in ~10-15 s, so
the full build is in the fast suite. Needs the ``docs`` extra (``pip install -e '.[docs]'``).
"""

from __future__ import annotations

import importlib.util
import json
import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

pytest.importorskip("mkdocs", reason="the docs extra is not installed: pip install -e '.[docs]'")
pytest.importorskip("mkdocstrings", reason="the docs extra is not installed: pip install -e '.[docs]'")

REPO = Path(__file__).resolve().parents[1]


def _hooks():
    spec = importlib.util.spec_from_file_location("fsdvs_docs_hooks", REPO / "docs" / "hooks.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def _build(out: Path) -> Path:
    env = {**os.environ, "PYTHONPATH": str(REPO), "NO_MKDOCS_2_WARNING": "1"}
    proc = subprocess.run(
        [sys.executable, "-m", "mkdocs", "build", "--strict", "-f", str(REPO / "mkdocs.yml"), "-d", str(out)],
        cwd=REPO,
        env=env,
        capture_output=True,
        text=True,
        timeout=600,
    )
    log = proc.stdout + proc.stderr
    assert proc.returncode == 0, log[-5000:]
    assert "WARNING" not in log, log[-5000:]
    return out


def _text(html: str) -> str:
    return re.sub(r"\s+", " ", re.sub(r"<[^>]+>", " ", html))


def test_the_site_builds_strict_and_shows_the_docstrings_records_and_shipped_results(tmp_path: Path):
    """One build (a module fixture would build once per xdist worker), three checks."""
    site = _build(tmp_path / "site")
    _api_pages_render_docstrings_and_turn_sphinx_roles_into_links(site)
    _the_measured_tables_are_the_committed_records(site)
    _the_matched_rate_table_and_the_readme_quote_the_shipped_results(site)
    _the_readme_links_resolve(site)
    _the_codesign_tables_are_the_shipped_results(site)


def _the_codesign_tables_are_the_shipped_results(site: Path):
    text = _text((site / "codesign" / "index.html").read_text(encoding="utf-8"))
    for name in ("codesign", "codesign_budget"):
        summary = json.loads((REPO / "designs" / "results" / name / "codesign.json").read_text(encoding="utf-8"))
        for cell in summary["cells"]:
            loss = cell["rows"]["swap"]["loss"]
            assert f"{loss['estimate']:.4f} [{loss['low']:.4f}, {loss['high']:.4f}]" in text, (name, cell["task"])


def _the_readme_links_resolve(site: Path):
    """Every relative link of the README names a file; a link into docs/ with an anchor, a heading."""
    readme = (REPO / "README.md").read_text(encoding="utf-8")
    links = re.findall(r"\]\(([^)\s]+)\)", readme)
    assert links
    for link in links:
        if re.match(r"^[a-z]+:", link):
            continue
        path, _, anchor = link.partition("#")
        assert (REPO / path).exists(), link
        if anchor and path.startswith("docs/"):
            page = site / Path(path).relative_to("docs").with_suffix("") / "index.html"
            assert f'id="{anchor}"' in page.read_text(encoding="utf-8"), link


def _api_pages_render_docstrings_and_turn_sphinx_roles_into_links(site: Path):
    html = (site / "api" / "kernels" / "index.html").read_text(encoding="utf-8")
    # reference_kernel's docstring, and its :func:/:class: roles as links to the objects' anchors
    assert 'id="fsdvs_hw.kernels.reference_kernel"' in html
    assert 'href="#fsdvs_hw.kernels.Kernel"' in html
    for page in (site / "api").rglob("index.html"):
        text = page.read_text(encoding="utf-8")
        assert not re.search(r":(func|class|meth|mod|data|attr):`", text), page


def _the_measured_tables_are_the_committed_records(site: Path):
    hooks = _hooks()
    text = _text((site / "measured" / "index.html").read_text(encoding="utf-8"))
    records_dir = REPO / "benchmarks" / "records"
    files = sorted(records_dir.glob("*.json"))
    assert files, "no committed benchmark records"
    for path in files:
        for record in json.loads(path.read_text(encoding="utf-8"))["records"]:
            cell = hooks._number(record["value"])
            assert cell in text, (path.name, record["case"], record["metric"], cell)


def _the_matched_rate_table_and_the_readme_quote_the_shipped_results(site: Path):
    text = _text((site / "rate" / "index.html").read_text(encoding="utf-8"))
    readme = (REPO / "README.md").read_text(encoding="utf-8")
    units = {"detection": "mAP", "recognition": "top-1", "segmentation": "mIoU"}
    for task, unit in units.items():
        data = json.loads((REPO / "designs" / "results" / "rate" / f"{task}_matched_rate.json").read_text())
        c = data["comparisons"]["learned_vs_wo_at_learned_rate"]
        quoted = f"{c['estimate']:+.3f} [{c['low']:+.3f}, {c['high']:+.3f}]".replace("-", "−")
        assert quoted in text, (task, quoted)
        assert f"{task} {quoted} {unit}" in readme.replace("\n", " "), (task, quoted)
        assert f"{c['raw_estimate']:+.3f}" in readme


def test_bench_tables_split_where_a_case_repeats_and_show_spread():
    from benchmarks.harness import BenchRecord

    hooks = _hooks()
    rows = [
        BenchRecord("b", "T", "bits=2", "error", "", 0.5),
        BenchRecord("b", "T", "bits=2", "time", "ms", 1.5, 3, 1.0, 2.0),
        BenchRecord("b", "T", "bits=2", "error", "", 0.25),  # same case and metric again: a second table
        BenchRecord("b", "T", "fitted scale", "time", "ms", 7.0),
    ]
    blocks = hooks._blocks(rows)
    assert [(title, len(r)) for title, r in blocks] == [("T", 2), ("", 1), ("", 1)]
    # two tables measured interleaved (per bit width, one row of each) come out as two tables
    mixed = [BenchRecord("b", t, f"bits={k}", "error", "", 0.1 * k) for k in (2, 3) for t in ("A", "B")]
    assert [(title, [r.case for r, _ in rows]) for title, rows in hooks._blocks(mixed)] == [
        ("A", ["bits=2", "bits=3"]),
        ("B", ["bits=2", "bits=3"]),
    ]
    # a cell holding "; " stays one cell when the table's headers are known
    case = "target=DoG; at a bound=pixel_weight; lambda ratio at 1.5; size=7x7"
    assert hooks._split_case(case, ("target", "at a bound", "size")) == [
        ("target", "DoG"),
        ("at a bound", "pixel_weight; lambda ratio at 1.5"),
        ("size", "7x7"),
    ]
    assert hooks._split_case("method=angular; knobs=n_freq=129, n_angles=8") == [
        ("method", "angular"),
        ("knobs", "n_freq=129, n_angles=8"),
    ]
    assert hooks._cell(rows[1]) == "1.5 [1–2], n=3"
    assert hooks._cell(rows[0]) == "0.5"
    assert hooks._cell(BenchRecord("b", "T", "one run", "time", "s", 4.0, 1, 4.0, 4.0)) == "4, n=1"
