"""The built wheel, installed in a fresh virtual environment outside the checkout, runs the main job.

What happens (module fixture ``installed``, ~15 s; the explore run ~60-90 s on 2 shared cores):

1. A copy of the working tree (no .git, out/, .venv/, build/) is built into a wheel in a temporary
   folder with ``pip wheel --no-deps --no-build-isolation`` (so nothing is written into the
   checkout, and no build backend is downloaded).
2. A fresh venv is created in another temporary folder and the wheel is installed there with
   ``pip install --no-deps --no-index``: fsdvs_hw and its data come from the wheel and nowhere else.
3. Dependencies. Default (``FSDVS_WHEEL_DEPS=shared``): a ``.pth`` file in the fresh venv appends
   the running interpreter's site-packages to ``sys.path`` *after* the venv's own, so torch, casadi,
   ... (~1.5 GB) are not reinstalled. Path lines in a ``.pth`` add folders without running the
   ``.pth`` files inside them, so the checkout's editable install of fsdvs_hw (an import hook
   loaded from a ``.pth``) stays invisible; the test checks that ``fsdvs_hw`` and its designs load
   from the fresh venv. ``FSDVS_WHEEL_DEPS=index`` instead installs the dependencies from the
   package index into the venv (``torch==2.13.0`` first, the CPU build; minutes) — what a new user
   does.
4. In a working directory outside the checkout (no designs/ there) ``fsdvs-hw explore --out DIR``
   runs the **embedded default design**, made quick with ``--set`` (one network per task, 16 test
   clips, simulator track only, 200 bootstrap resamples); DIR/report.html and the scores must exist
   and name every realisation. The full default job (5 points, 32-64 networks per task, both
   tracks; ~5 min on 2 cores) runs when ``FSDVS_WHEEL_FULL=1``.
"""

from __future__ import annotations

import csv
import json
import os
import shutil
import subprocess
import sys
import sysconfig
import venv
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
_IGNORE = shutil.ignore_patterns(
    ".git",
    "out",
    ".venv",
    "build",
    "dist",
    "*.egg-info",
    "__pycache__",
    ".pytest_cache",
    ".hypothesis",
    ".ipynb_checkpoints",
    "mutation",
)
QUICK = [
    "--set",
    "tasks.checkpoints={"
    + ", ".join(
        f'{t}="kernels/networks/{t}_with_learned_detection_7x7_s0.safetensors"'
        for t in ("detection", "recognition", "segmentation")
    )
    + "}",
    "--set",
    "tasks.n_test={detection=16, recognition=16, segmentation=16}",
    "--set",
    'tasks.tracks=["simulator"]',
    "--set",
    "emulation.enabled=false",
    "--set",
    "scoring.n_resamples=200",
]

pytestmark = pytest.mark.slow


def _run(cmd: list[str], *, cwd: Path, env: dict[str, str] | None = None, timeout: float = 900) -> str:
    proc = subprocess.run(cmd, cwd=cwd, env=env, capture_output=True, text=True, timeout=timeout)
    assert proc.returncode == 0, f"{cmd[:4]} exited {proc.returncode}\n{proc.stdout[-3000:]}\n{proc.stderr[-3000:]}"
    return proc.stdout


@pytest.fixture(scope="module")
def installed(tmp_path_factory):
    """(venv folder, environment for its commands, a working folder outside the checkout)."""
    root = tmp_path_factory.mktemp("wheel")
    assert REPO not in root.parents
    src = root / "src"
    shutil.copytree(REPO, src, ignore=_IGNORE)
    _run(
        [
            sys.executable,
            "-m",
            "pip",
            "wheel",
            "--no-deps",
            "--no-build-isolation",
            "-q",
            "-w",
            str(root / "dist"),
            str(src),
        ],
        cwd=root,
    )
    (wheel,) = (root / "dist").glob("fsdvs_hw-*.whl")
    env_dir = root / "venv"
    mode = os.environ.get("FSDVS_WHEEL_DEPS", "shared")
    venv.create(env_dir, with_pip=(mode == "index"), clear=True)
    py = env_dir / "bin" / "python"
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "PYTHONHOME", "VIRTUAL_ENV")}
    env["PATH"] = f"{env_dir / 'bin'}{os.pathsep}{env.get('PATH', '')}"
    if mode == "index":
        _run([str(py), "-m", "pip", "install", "-q", "torch==2.13.0"], cwd=root, env=env, timeout=1800)
        _run([str(py), "-m", "pip", "install", "-q", str(wheel)], cwd=root, env=env, timeout=1800)
    else:
        _run(
            [sys.executable, "-m", "pip", "--python", str(py), "install", "-q", "--no-deps", "--no-index", str(wheel)],
            cwd=root,
            env=env,
        )
        site = Path(
            _run(
                [str(py), "-c", "import sysconfig; print(sysconfig.get_paths()['purelib'])"], cwd=root, env=env
            ).strip()
        )
        (site / "zz_fsdvs_test_dependencies.pth").write_text(sysconfig.get_paths()["purelib"] + "\n")
    work = root / "elsewhere"
    work.mkdir()
    return env_dir, env, work


def test_the_wheel_carries_the_designs_and_imports_from_the_venv(installed):
    env_dir, env, work = installed
    got = json.loads(
        _run(
            [
                str(env_dir / "bin" / "python"),
                "-c",
                "import json, fsdvs_hw; from fsdvs_hw.resources import designs_dir, shipped_designs;"
                "print(json.dumps([fsdvs_hw.__file__, str(designs_dir()), shipped_designs()]))",
            ],
            cwd=work,
            env=env,
        )
    )
    module, designs, names = got
    assert Path(module).is_relative_to(env_dir) and Path(designs).is_relative_to(env_dir), got
    assert Path(designs) == Path(module).parent / "designs"
    assert "default.toml" in names and "sweep_asic_bits.toml" in names
    shipped = {p.relative_to(REPO / "designs") for p in (REPO / "designs").rglob("*") if p.is_file()}
    inside = {p.relative_to(designs) for p in Path(designs).rglob("*") if p.is_file()}
    assert shipped <= inside  # every design file, kernel, checkpoint and figure
    assert (Path(module).parent / "realise" / "asic" / "data" / "fsdvs_demo45.lib").is_file()
    # the event simulator's C source ships too, and builds from the installed package
    assert (Path(module).parent / "sensor" / "native" / "_crossings.c").is_file()
    cache = work / "kernel-cache"
    built = _run(
        [
            str(env_dir / "bin" / "python"),
            "-c",
            "from fsdvs_hw.sensor.native import library as n; print(n.available(), n.why_unavailable())",
        ],
        cwd=work,
        env={**env, "FSDVS_HW_CACHE": str(cache)},
    )
    assert built.strip().startswith("True"), built
    assert list(cache.glob("crossings-*.so"))


def _check_report(out: Path, *, n_test: int | None) -> None:
    html = (out / "report.html").read_text(encoding="utf-8")
    assert len(html) > 10_000 and "<img" in html
    rows = list(csv.DictReader((out / "scores.csv").open(encoding="utf-8")))
    kinds = {r["realisation"] for r in rows}
    assert kinds == {"learned", "delta", "mesh", "asic", "metalens"}
    assert all(r["status"] == "ok" for r in rows)
    assert json.loads((out / "scores.json").read_text())
    if n_test is not None:
        delta = next(r for r in rows if r["realisation"] == "delta")
        assert int(float(delta["detection_n_clips"])) == n_test


def test_installed_fsdvs_hw_explore_runs_the_embedded_default_outside_the_checkout(installed):
    env_dir, env, work = installed
    out = work / "quick"
    stdout = _run(
        [str(env_dir / "bin" / "fsdvs-hw"), "explore", "--out", str(out), "--no-progress", "--workers", "1", *QUICK],
        cwd=work,
        env=env,
    )
    assert f"report: {out / 'report.html'}" in stdout
    _check_report(out, n_test=16)
    assert not (work / "designs").exists() and not (work / "out").exists()  # wrote only where told


@pytest.mark.skipif(
    os.environ.get("FSDVS_WHEEL_FULL") != "1",
    reason="the full main job takes ~5 min on 2 cores: set FSDVS_WHEEL_FULL=1",
)
def test_installed_fsdvs_hw_explore_full_main_job(installed):
    env_dir, env, work = installed
    out = work / "demo"
    _run(
        [str(env_dir / "bin" / "fsdvs-hw"), "explore", "--out", str(out), "--no-progress"],
        cwd=work,
        env=env,
        timeout=3600,
    )
    _check_report(out, n_test=None)
