"""Every runnable code block of README.md and of the documentation pages runs, as a reader would run it.

The documents are :data:`DOCUMENTS`: the README and the pages of docs/ that hold its former
reference sections (a new page with runnable blocks goes into that list).

* ```python blocks: each is run on its own (a fresh interpreter, so every block is complete in
  itself and can be copied alone).
* ```bash blocks: run by bash with ``set -euo pipefail``; ``fsdvs-hw`` and ``python`` are the
  interpreter running the tests (``python -m fsdvs_hw.cli``), as in an activated venv.
* Blocks are run in a fresh folder holding only a ``designs`` link to the checkout's designs/,
  as a reader's commands run from the repository folder; whatever they write stays in that folder.
  Each run checks that designs/ is unchanged afterwards (names, sizes and modification times):
  no README command writes into designs/.
* ```console blocks are shown, not run; each must follow a ``<!-- readme-test: skip (reason) -->``
  marker, and the set of skipped blocks (over all documents) is listed here (:data:`SKIPPED`):
  adding one means editing this test. Blocks without a language or in json are output, not code.
"""

from __future__ import annotations

import os
import re
import shutil
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
README = REPO / "README.md"
#: The documents whose blocks run: the README and the documentation pages with runnable blocks.
DOCUMENTS: tuple[Path, ...] = (
    README,
    *(
        REPO / "docs" / f"{name}.md"
        for name in (
            "getting-started",
            "analyse",
            "simulator",
            "tasks",
            "mesh",
            "asic",
            "metalens",
            "explore",
            "sweeps",
            "codesign",
            "rate",
            "security",
            "measured",
            "index",
        )
    ),
)
RUNNABLE = {"python", "bash", "sh", "shell", "console"}

#: Blocks shown but not run (first command line → why). Keep this short.
SKIPPED: dict[str, str] = {
    "make demo": "sets up .venv and runs the full main job (~8 min); tests/test_wheel.py runs the job",
    "fsdvs-hw explore --out out/demo": "the full main job (~8 min); the quick variant below runs",
    "fsdvs-hw learn detection --init-kernel": "trains a network (minutes); tests/test_codesign_learn.py",
    "fsdvs-hw ablation --seeds 0 1 2": "45 trainings (48 min)",
    "make notebooks": "runs every notebook at full size (~30 min); tests/test_notebooks.py runs them small",
    "fsdvs-hw report designs/default.toml": "needs out/demo from the main job; tests/test_report.py redraws a run",
    "apt-get install -y chromium": "installs Debian packages; tests/test_report_browser.py is the browser test",
    "openssl req -x509 -nodes -newkey rsa:4096": "needs a Dask cluster; tests/test_inputs_safety.py runs TLS locally",
    "pip install -e '.[docs]'": "installs packages and serves the site; tests/test_docs.py builds it",
    "fsdvs-hw bench csf --json benchmarks/records/csf.json": "rewrites a committed benchmark record",
    "python -m fsdvs_hw.realise.metalens.meta_atoms": "recomputes the committed RCWA library (~25 min)",
}

#: Blocks that take more than ~20 s (first code line(s), prefix). CPU seconds measured one by one on
#: the shared 2-core machine (2026-11-25): tour fits 22, quick explore 30, simulator 54, metalens 77;
#: every other block 0.6-12.
SLOW: tuple[str, ...] = (
    "import numpy as np\nimport fsdvs_hw as fh",  # tour: mesh, taps and lens fits
    "fsdvs-hw explore --out out/quick",
    "import torch\nfrom fsdvs_hw.kernels",  # event simulator on a real clip
    "from fsdvs_hw import fit_metalens",  # metalens: differential fit, 2-D propagation
)

_FENCE = re.compile(r"^```([A-Za-z0-9_+-]*)\s*$")
_SKIP = re.compile(r"^<!--\s*readme-test:\s*skip\s*\((.+)\)\s*-->\s*$")


@dataclass(frozen=True)
class Block:
    """One fenced code block of a document (README.md or a documentation page)."""

    lang: str
    code: str
    line: int  # line of the opening fence (1-based)
    skip_reason: str | None
    document: str = "README.md"  # path relative to the repository

    @property
    def key(self) -> str:
        """The block's first line that is code (not a comment), to name it."""
        lines = [ln.strip() for ln in self.code.splitlines() if ln.strip() and not ln.strip().startswith("#")]
        return lines[0] if lines else ""

    @property
    def slow(self) -> bool:
        body = "\n".join(ln for ln in self.code.splitlines() if ln.strip() and not ln.lstrip().startswith("#"))
        return any(body.startswith(prefix) for prefix in SLOW)


def readme_blocks(text: str | None = None, document: Path = README) -> list[Block]:
    """Every fenced block of a document (default the README), with the skip marker that precedes it (if any)."""
    lines = (document.read_text(encoding="utf-8") if text is None else text).splitlines()
    name = document.relative_to(REPO).as_posix()
    blocks: list[Block] = []
    i = 0
    while i < len(lines):
        m = _FENCE.match(lines[i])
        if not m:
            i += 1
            continue
        start, lang = i, m.group(1).lower()
        j = i + 1
        while j < len(lines) and not lines[j].startswith("```"):
            j += 1
        prev = next((lines[k] for k in range(start - 1, -1, -1) if lines[k].strip()), "")
        skip = _SKIP.match(prev.strip())
        blocks.append(Block(lang, "\n".join(lines[start + 1 : j]), start + 1, skip.group(1) if skip else None, name))
        i = j + 1
    return blocks


def all_blocks() -> list[Block]:
    """Every fenced block of every document in :data:`DOCUMENTS`."""
    return [b for doc in DOCUMENTS for b in readme_blocks(document=doc)]


def _runnable() -> list[Block]:
    """The blocks to run; a block repeated verbatim in another document runs once."""
    seen: set[tuple[str, str]] = set()
    out = []
    for b in all_blocks():
        if b.lang in RUNNABLE and b.skip_reason is None and (b.lang, b.code) not in seen:
            seen.add((b.lang, b.code))
            out.append(b)
    return out


def _snapshot(folder: Path) -> dict[str, tuple[int, int]]:
    return {
        str(p.relative_to(folder)): (p.stat().st_size, p.stat().st_mtime_ns)
        for p in sorted(folder.rglob("*"))
        if p.is_file()
    }


def test_the_parser_finds_blocks_and_markers():
    text = (
        "x\n<!-- readme-test: skip (too long) -->\n```console\nmake demo\n```\n\n```python\n# c\nprint(1)\n```\n"
        "```\noutput\n```\n"
    )
    a, b, c = readme_blocks(text)
    assert (a.lang, a.key, a.skip_reason, a.line) == ("console", "make demo", "too long", 3)
    assert (b.lang, b.key, b.skip_reason) == ("python", "print(1)", None)
    assert (c.lang, c.code) == ("", "output")


def test_every_document_exists_and_the_readme_is_short():
    assert all(doc.is_file() for doc in DOCUMENTS), [str(d) for d in DOCUMENTS if not d.is_file()]
    assert len(README.read_text(encoding="utf-8").splitlines()) <= 300


def test_skipped_blocks_are_exactly_the_listed_ones_and_console_blocks_are_skipped():
    blocks = all_blocks()
    skipped = {b.key: b for b in blocks if b.skip_reason is not None}
    assert all(any(k.startswith(p) for k in skipped) for p in SKIPPED), (sorted(skipped), sorted(SKIPPED))
    assert all(any(k.startswith(p) for p in SKIPPED) for k in skipped), sorted(skipped)
    assert all(b.skip_reason is not None for b in blocks if b.lang == "console"), [
        (b.document, b.line) for b in blocks if b.lang == "console" and b.skip_reason is None
    ]
    assert len(_runnable()) >= 8  # the tour and the reference snippets


def test_no_readme_command_names_designs_as_an_output():
    """Flags that write (--out, --ship-dir, --figures, --store, --report) never point into designs/."""
    text = "\n".join(doc.read_text(encoding="utf-8") for doc in DOCUMENTS)
    bad = re.findall(r"--(?:out|ship-dir|figures|store|report|json)[ =]designs/\S*", text)
    assert bad == []
    cli = "\n".join(p.read_text(encoding="utf-8") for p in (REPO / "fsdvs_hw" / "cli").glob("*.py"))
    assert re.findall(r"--(?:out|ship-dir|figures|store|report)[ =]designs/\S*", cli) == []


_PRELUDE = """set -euo pipefail
fsdvs-hw() { "$FSDVS_TEST_PYTHON" -m fsdvs_hw.cli "$@"; }
python() { "$FSDVS_TEST_PYTHON" "$@"; }
"""


def _needs_tools(code: str) -> list[str]:
    need = []
    if ".simulate(" in code or "simulate_rtl" in code:
        need.append("iverilog")
    if ".synthesise(" in code or "synthesise_verilog" in code:
        need.append("yosys")
    if "run_ngspice" in code or "simulate_mesh_step_spice" in code:
        need.append("ngspice")
    return [t for t in need if shutil.which(t) is None]


@pytest.mark.parametrize(
    "block",
    [
        pytest.param(b, id=f"{Path(b.document).stem}-L{b.line}-{b.lang}", marks=[pytest.mark.slow] if b.slow else [])
        for b in _runnable()
    ],
)
def test_readme_block_runs(block: Block, tmp_path: Path):
    missing = _needs_tools(block.code)
    if missing:
        pytest.skip(f"{block.document} line {block.line} needs {', '.join(missing)} (not on PATH)")
    (tmp_path / "designs").symlink_to(REPO / "designs", target_is_directory=True)
    env = {**os.environ, "PYTHONPATH": str(REPO), "FSDVS_TEST_PYTHON": sys.executable, "MPLBACKEND": "Agg"}
    before = _snapshot(REPO / "designs")
    if block.lang == "python":
        script = tmp_path / "block.py"
        script.write_text(block.code + "\n", encoding="utf-8")
        cmd = [sys.executable, str(script)]
    else:
        script = tmp_path / "block.sh"
        script.write_text(_PRELUDE + block.code + "\n", encoding="utf-8")
        cmd = ["bash", str(script)]
    proc = subprocess.run(cmd, cwd=tmp_path, env=env, capture_output=True, text=True, timeout=1200)
    assert proc.returncode == 0, (
        f"{block.document} line {block.line} ({block.lang}) failed:\n{block.code}\n"
        f"--- stdout\n{proc.stdout[-3000:]}\n--- stderr\n{proc.stderr[-5000:]}"
    )
    assert _snapshot(REPO / "designs") == before, f"{block.document} line {block.line} changed designs/"
