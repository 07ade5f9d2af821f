"""MkDocs hooks of the fsdvs_hw documentation site (``mkdocs.yml``: ``hooks: [docs/hooks.py]``).

Three jobs, all at build time, so that nothing measured is typed by hand into a page:

* **Measured tables from the committed records.** A line ``<!-- bench-tables: NAME -->`` in a page
  becomes every table of benchmark ``NAME`` (``fsdvs-hw bench NAME``), rendered from the records it
  wrote to ``benchmarks/records/NAME.json`` (:func:`benchmarks.harness.read_json`): one Markdown
  table per record table, one row per measured case, one column per metric and unit; a timing shows
  its value, its min–max over the repeats and the number of repeats. Each table is followed by the
  machine, the library versions, the time and the command that produced it.
* **Tables from the shipped results.** ``<!-- rate-table -->`` becomes the learned − w/o
  differences of ``designs/results/rate/TASK_matched_rate.json`` (``fsdvs-hw rate``);
  ``<!-- rate-interpolation-table -->`` the learned − w/o difference at matched rate under each
  interpolation of ``designs/results/rate/*_interpolation_sensitivity.json``
  (``fsdvs-hw rate … --interpolation-sensitivity``);
  ``<!-- codesign-table: NAME -->`` the report's co-design table of
  ``designs/results/NAME/codesign.json``; ``<!-- limits-table -->`` the constants of
  ``fsdvs_hw/limits.py``; ``<!-- v2e-table: NAME -->`` the side-by-side record
  ``benchmarks/records/v2e/NAME.json`` (this simulator against v2e, or two checkouts).
* **Repository files on the site.** ``CONTRIBUTING.md``, ``CHANGELOG.md`` and ``benchmarks/README.md``
  become pages, the README figures (``designs/figures/*.png``) site files, and links from a page to
  those repository paths (``../designs/figures/x.png``) are rewritten to their site address; a link
  to any other repository file keeps its text as code (the site holds the docs, not the source).
"""

from __future__ import annotations

import json
import logging
import math
import re
import sys
from collections import Counter, OrderedDict
from pathlib import Path

from mkdocs.structure.files import File, Files

ROOT = Path(__file__).resolve().parents[1]
LOG = logging.getLogger("mkdocs.hooks.fsdvs_hw")
RECORDS = ROOT / "benchmarks" / "records"
RATE = ROOT / "designs" / "results" / "rate"
FIGURES = ROOT / "designs" / "figures"

#: Repository Markdown files published as pages: repository path -> site path.
REPO_PAGES = {
    "CONTRIBUTING.md": "contributing.md",
    "CHANGELOG.md": "changelog.md",
    "benchmarks/README.md": "benchmark-method.md",
}

_BENCH = re.compile(r"^<!--\s*bench-tables:\s*([a-z0-9_]+)\s*-->\s*$", re.MULTILINE)
_RATE = re.compile(r"^<!--\s*rate-table\s*-->\s*$", re.MULTILINE)
_RATE_INTERP = re.compile(r"^<!--\s*rate-interpolation-table\s*-->\s*$", re.MULTILINE)
_CODESIGN = re.compile(r"^<!--\s*codesign-table:\s*([a-z0-9_]+)\s*-->\s*$", re.MULTILINE)
_V2E = re.compile(r"^<!--\s*v2e-table:\s*([a-z0-9_]+)\s*-->\s*$", re.MULTILINE)
_LIMITS = re.compile(r"^<!--\s*limits-table\s*-->\s*$", re.MULTILINE)
_CONSTANT = re.compile(r"((?:^#:.*\n)+)^([A-Z_]+): \w+ = (.+)$", re.MULTILINE)
_LINK = re.compile(r"(!?)\[([^\]]*)\]\(([^)\s]+)\)")


# ----------------------------------------------------------------------------- repository files


def on_files(files: Files, config) -> Files:
    """Add the repository pages and the README figures to the site."""
    for repo_path, site_path in REPO_PAGES.items():
        source = ROOT / repo_path
        if source.is_file():
            files.append(File.generated(config, site_path, content=source.read_text(encoding="utf-8")))
    for png in sorted(FIGURES.glob("*.png")):
        files.append(File.generated(config, f"figures/{png.name}", abs_src_path=str(png)))
    return files


def _origin(page) -> Path:
    """The repository folder a page's relative links are written against."""
    src = page.file.src_uri
    for repo_path, site_path in REPO_PAGES.items():
        if src == site_path:
            return (ROOT / repo_path).parent
    return (ROOT / "docs" / src).parent


def _site_target(target: Path, page_dir: Path) -> str | None:
    """The site address (relative to the page) of a repository path, or None if not on the site."""
    try:
        rel = target.relative_to(ROOT).as_posix()
    except ValueError:
        return None
    site = REPO_PAGES.get(rel)
    if site is None and rel.startswith("designs/figures/") and target.suffix == ".png":
        site = f"figures/{target.name}"
    if site is None and rel.startswith("docs/"):
        site = rel[len("docs/") :]
    if site is None:
        return None
    return Path(*([".."] * len(page_dir.parts)), site).as_posix() if page_dir.parts else site


def _rewrite_links(markdown: str, page) -> str:
    origin = _origin(page)
    page_dir = Path(page.file.src_uri).parent
    page_dir = Path() if str(page_dir) == "." else page_dir

    def fix(m: re.Match) -> str:
        bang, text, url = m.groups()
        if re.match(r"^[a-z]+:|^#|^/", url):
            return m.group(0)
        path, _, anchor = url.partition("#")
        target = (origin / path).resolve()
        if (ROOT / "docs") in target.parents and origin == ROOT / "docs":
            return m.group(0)  # an ordinary link between pages
        if not target.exists():
            LOG.warning("%s links to %r, which does not exist in the repository", page.file.src_uri, url)
        site = _site_target(target, page_dir)
        if site is not None:
            return f"{bang}[{text}]({site}{'#' + anchor if anchor else ''})"
        return text if text.startswith("`") else f"`{text}`"

    parts = re.split(r"(^```.*?^```[ \t]*$)", markdown, flags=re.MULTILINE | re.DOTALL)
    return "".join(part if part.startswith("```") else _LINK.sub(fix, part) for part in parts)


# ----------------------------------------------------------------------------- measured tables


def _records(name: str) -> list:
    if str(ROOT) not in sys.path:
        sys.path.insert(0, str(ROOT))
    from benchmarks.harness import read_json

    path = RECORDS / f"{name}.json"
    return read_json(path) if path.is_file() else []


def _split_case(case: str, headers: tuple[str, ...] | None = None) -> list[tuple[str, str]]:
    """``"method=angular; knobs=n_freq=129"`` -> ``[("method", "angular"), ("knobs", "n_freq=129")]``.

    A record's case is its text cells joined as ``header=text; header=text``; a cell's text may itself
    hold ``"; "``. With ``headers`` (the table's text columns, in order) a part starts a new column
    only where its key is the next header; any other part belongs to the cell before it. A case with
    no ``=`` (a value quoted in a bench's text) is one ``case`` column.
    """
    out: list[list[str]] = []
    for item in case.split("; "):
        key, sep, value = item.partition("=")
        new_column = sep and (headers is None or (len(out) < len(headers) and key == headers[len(out)]))
        if new_column:
            out.append([key, value])
        elif out:
            out[-1][1] += "; " + item
        else:
            out.append(["case", item])
    return [(k, v) for k, v in out]


def _headers(records: list) -> tuple[str, ...]:
    """The text columns of one table: the most frequent shortest key sequence of its cases."""
    seqs = [tuple(k for k, _ in _split_case(r.case)) for r in records if "=" in r.case]
    if not seqs:
        return ()
    shortest = min(map(len, seqs))
    return Counter(s for s in seqs if len(s) == shortest).most_common(1)[0][0]


def _number(x: float) -> str:
    if x == 0 or not math.isfinite(x):
        return f"{x:g}"
    return f"{x:.4g}" if 1e-3 <= abs(x) < 1e6 else f"{x:.3e}"


def _cell(record) -> str:
    text = _number(record.value)
    if record.repeats is None:
        return text  # not a timing
    if record.repeats > 1 and record.spread_min is not None and record.spread_max is not None:
        return text + f" [{_number(record.spread_min)}–{_number(record.spread_max)}], n={record.repeats}"
    return text + f", n={record.repeats}"


def _provenance(records: list) -> str:
    first = records[0]
    machine, versions = first.machine, first.versions
    libs = ", ".join(f"{k} {versions[k]}" for k in ("python", "numpy", "torch", "scipy", "casadi") if k in versions)
    load = machine.get("load_average_1min")
    load_text = f", load average {load:.1f} at the start" if isinstance(load, int | float) else ""
    threads = sorted({r.threads for r in records if r.threads is not None})
    threads_text = f"; torch threads {', '.join(map(str, threads))}" if threads else ""
    quick = " (quick mode: small problem sizes)" if first.settings.get("quick") else ""
    return (
        f"*Measured {first.timestamp.replace('T', ' ').replace('+00:00', ' UTC')} on "
        f"{machine.get('cpu_count', '?')} CPU cores ({machine.get('platform', '?')}{load_text}){threads_text}; "
        f"{libs}{quick}. Records: `benchmarks/records/{first.bench}.json`, written by "
        f"`fsdvs-hw bench {first.bench} --json benchmarks/records/{first.bench}.json`.*"
    )


def _blocks(records: list) -> list[tuple[str, list]]:
    """Records cut into tables of ``(title, [(record, parsed case), ...])``: the records of one title
    together (in order of first appearance), and a new table where the title or the case's columns
    change, or where a (case, metric) repeats; the title is given only where it changes."""
    order = list(dict.fromkeys(r.table for r in records))  # titles in order of first appearance
    records = sorted(records, key=lambda r: order.index(r.table))  # stable: a bench may interleave two tables
    headers = {title: _headers([r for r in records if r.table == title]) for title in order}
    blocks: list[tuple[str, list]] = []
    title, keys, seen = None, None, set()
    for r in records:
        parts = _split_case(r.case, headers[r.table])
        case_keys = tuple(k for k, _ in parts)
        if r.table != title or case_keys != keys or (r.case, r.metric, r.unit) in seen:
            blocks.append((r.table if r.table != title else "", []))
            title, keys, seen = r.table, case_keys, set()
        seen.add((r.case, r.metric, r.unit))
        blocks[-1][1].append((r, parts))
    return blocks


def bench_tables(name: str) -> str:
    """Every table of benchmark ``name`` as Markdown, from its committed records."""
    records = _records(name)
    if not records:
        return (
            f"*No committed records for `{name}` yet: `fsdvs-hw bench {name} --json "
            f"benchmarks/records/{name}.json` writes them.*"
        )
    out = []
    for title, rows in _blocks(records):
        text_cols: list[str] = []
        value_cols: list[tuple[str, str]] = []
        cases: OrderedDict[str, dict] = OrderedDict()
        for r, parts in rows:
            for key, _ in parts:
                if key not in text_cols:
                    text_cols.append(key)
            if (r.metric, r.unit) not in value_cols:
                value_cols.append((r.metric, r.unit))
            cases.setdefault(r.case, {"text": dict(parts), "values": {}})["values"][(r.metric, r.unit)] = r
        heads = text_cols + [f"{m} ({u})" if u else m for m, u in value_cols]
        lines = [f"### {title}", ""] if title else []
        lines += ["| " + " | ".join(heads) + " |", "|" + "---|" * len(heads)]
        for row in cases.values():
            cells = [row["text"].get(c, "") for c in text_cols]
            cells += [_cell(row["values"][v]) if v in row["values"] else "—" for v in value_cols]
            lines.append("| " + " | ".join(c.replace("|", "\\|") for c in cells) + " |")
        out += [*lines, ""]
    out.append(_provenance(records))
    return "\n".join(out)


def rate_table() -> str:
    """Learned − w/o differences per task from ``designs/results/rate/TASK_matched_rate.json``."""
    tasks = [t for t in ("detection", "segmentation", "recognition") if (RATE / f"{t}_matched_rate.json").is_file()]
    if not tasks:
        return "*No shipped matched-rate results.*"
    data = {t: json.loads((RATE / f"{t}_matched_rate.json").read_text(encoding="utf-8")) for t in tasks}

    def ci(est: float, low: float, high: float) -> str:
        return f"{est:+.3f} [{low:+.3f}, {high:+.3f}]".replace("-", "−")

    rows = {
        "same threshold": [],
        "w/o with its threshold lowered to fire as many events as the learned kernel": [],
        "learned with its threshold raised to fire as few events as w/o": [],
    }
    names = list(rows)
    for t in tasks:
        up = data[t]["comparisons"]["learned_vs_wo_at_learned_rate"]
        down = data[t]["comparisons"]["wo_vs_learned_at_wo_rate"]
        rows[names[0]].append(ci(up["raw_estimate"], up["raw_low"], up["raw_high"]))
        rows[names[1]].append(f"**{ci(up['estimate'], up['low'], up['high'])}** (w/o at {up['matched_threshold']:.2f})")
        rows[names[2]].append(
            f"{ci(-down['estimate'], -down['high'], -down['low'])} (learned at {down['matched_threshold']:.2f})"
        )
    ref = data[tasks[0]]["settings"]["reference_threshold"]
    lines = [
        "| learned − w/o | "
        + " | ".join(f"{t} ({data[t]['comparisons']['learned_vs_wo_at_learned_rate']['metric_name']})" for t in tasks)
        + " |",
        "|---|" + "---|" * len(tasks),
    ]
    lines += [
        f"| {name.replace('same threshold', f'same threshold {ref}')} | " + " | ".join(cells) + " |"
        for name, cells in rows.items()
    ]
    n = {
        t: (
            data[t]["comparisons"]["learned_vs_wo_at_learned_rate"]["n_clips"],
            data[t]["comparisons"]["learned_vs_wo_at_learned_rate"]["n_networks"],
        )
        for t in tasks
    }
    lines += [
        "",
        "*"
        + "; ".join(f"{t}: n = {c} clips, {k} networks" for t, (c, k) in n.items())
        + f"; {int(100 * data[tasks[0]]['settings']['confidence'])} % percentile bootstrap, "
        f"{data[tasks[0]]['settings']['n_resamples']} resamples. Generated from "
        "`designs/results/rate/TASK_matched_rate.json`, written by: "
        + "; ".join(f"`{data[t]['provenance']['command']}`" for t in tasks)
        + ".*",
    ]
    return "\n".join(lines)


def codesign_table(name: str) -> str:
    """The report's co-design table (:func:`fsdvs_hw.report.codesign_section.codesign_section`) of the shipped
    ``designs/results/NAME/codesign.json``, without its heading."""
    if str(ROOT) not in sys.path:
        sys.path.insert(0, str(ROOT))
    from fsdvs_hw.report.codesign_section import codesign_section
    from fsdvs_hw.report.report_input import CodesignSummary

    path = ROOT / "designs" / "results" / name / "codesign.json"
    html = codesign_section(CodesignSummary.from_dict(json.loads(path.read_text(encoding="utf-8"))))
    note = " ".join(_html_text(p) for p in re.findall(r"<p[^>]*>(.*?)</p>", html, flags=re.DOTALL))
    rows = [
        [_html_text(c) for c in re.findall(r"<t[hd][^>]*>(.*?)</t[hd]>", row, flags=re.DOTALL)]
        for row in re.findall(r"<tr[^>]*>(.*?)</tr>", html, flags=re.DOTALL)
    ]
    lines = ["| " + " | ".join(rows[0]) + " |", "|" + "---|" * len(rows[0])]
    lines += ["| " + " | ".join(c.replace("|", "\\|") for c in row) + " |" for row in rows[1:]]
    return "\n".join(
        [
            *lines,
            "",
            f"*{note} Generated from the shipped `designs/results/{name}/codesign.json` "
            "by the report's own co-design section.*",
        ]
    )


def v2e_table(name: str) -> str:
    """A side-by-side record ``benchmarks/records/v2e/NAME.json`` (``python -m benchmarks.sim
    --v2e / --v2e-command / --against ... --json``) as its table and provenance line."""
    if str(ROOT) not in sys.path:
        sys.path.insert(0, str(ROOT))
    from benchmarks.sim import comparison_markdown

    path = RECORDS / "v2e" / f"{name}.json"
    return comparison_markdown(json.loads(path.read_text(encoding="utf-8"))) + f" *Record: `{path.relative_to(ROOT)}`.*"


def _html_text(fragment: str) -> str:
    """The text of an HTML fragment (tags dropped, entities decoded, whitespace collapsed)."""
    import html

    return re.sub(r"\s+", " ", html.unescape(re.sub(r"<[^>]+>", " ", fragment))).strip()


def limits_table() -> str:
    """The documented constants of ``fsdvs_hw/limits.py`` (name, value, what it bounds)."""
    if str(ROOT) not in sys.path:
        sys.path.insert(0, str(ROOT))
    import fsdvs_hw.limits as limits

    source = (ROOT / "fsdvs_hw" / "limits.py").read_text(encoding="utf-8")
    lines = ["| constant | value | what it bounds |", "|---|---|---|"]
    for comment, name, _ in _CONSTANT.findall(source):
        text = " ".join(line[2:].strip() for line in comment.strip().splitlines()).replace("``", "`")
        value = getattr(limits, name)
        shown = f"{value:,}".replace(",", " ") if isinstance(value, int) else repr(value)
        lines.append(f"| `{name}` | {shown} | {text} |")
    return "\n".join(lines)


def rate_interpolation_table() -> str:
    """Learned − w/o at the learned kernel's rate under each interpolation, from ``*_interpolation_sensitivity.json``."""
    files = sorted(RATE.glob("*_interpolation_sensitivity.json"))
    if not files:
        return "*No shipped interpolation-sensitivity results.*"
    comparison = "learned_vs_wo_at_learned_rate"
    lines, commands, hows = [], [], None
    for path in files:
        data = json.loads(path.read_text(encoding="utf-8"))
        rows = [r for r in data["rows"] if r["comparison"] == comparison]
        if hows is None:
            hows = [r["interpolation"] for r in rows]
            lines += [
                "| result (learned − w/o at the learned kernel's rate) | n clips, networks | "
                + " | ".join(hows)
                + " |",
                "|---|---|" + "---|" * len(hows),
            ]
        cells = []
        for r in rows:
            if r["status"] != "ok":
                cells.append(r["status"])
            else:
                cells.append(f"{r['estimate']:+.4f} [{r['low']:+.4f}, {r['high']:+.4f}]".replace("-", "−"))
        name = path.name.removesuffix("_interpolation_sensitivity.json").replace("_", ", ")
        lines.append(
            f"| {name} ({rows[0]['metric_name']}) | {rows[0]['n_clips']}, {rows[0]['n_networks']} | "
            + " | ".join(cells)
            + " |"
        )
        commands.append(f"`{data['provenance']['command']}`")
    first = json.loads(files[0].read_text(encoding="utf-8"))["settings"]
    lines += [
        "",
        f"*{int(100 * first['confidence'])} % percentile bootstrap, {first['n_resamples']} resamples, the same "
        "for every interpolation. Generated from `designs/results/rate/*_interpolation_sensitivity.json`, "
        "written by: " + "; ".join(commands) + ".*",
    ]
    return "\n".join(lines)


def on_page_markdown(markdown: str, page, config, files) -> str:
    """Expand the generated tables and rewrite links to repository files."""
    markdown = _BENCH.sub(lambda m: bench_tables(m.group(1)), markdown)
    markdown = _RATE.sub(lambda m: rate_table(), markdown)
    markdown = _RATE_INTERP.sub(lambda m: rate_interpolation_table(), markdown)
    markdown = _LIMITS.sub(lambda m: limits_table(), markdown)
    markdown = _CODESIGN.sub(lambda m: codesign_table(m.group(1)), markdown)
    markdown = _V2E.sub(lambda m: v2e_table(m.group(1)), markdown)
    return _rewrite_links(markdown, page)
