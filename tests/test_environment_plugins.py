"""One prefix for every environment variable (fsdvs_hw.environment), and realisation plugins that an
installed package declares in the ``fsdvs_hw.realisations`` entry-point group: a fresh interpreter
knows them without any environment variable, and a broken one is a warning naming it."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

from fsdvs_hw.environment import ENVIRONMENT, env, set_env

PLUGINS = Path(__file__).parent / "plugins"


def test_new_names_win_and_former_names_still_work_with_a_warning(monkeypatch):
    for name, (former, _) in ENVIRONMENT.items():
        assert name.startswith("FSDVS_HW_") and all(not f.startswith("FSDVS_HW_") for f in former)
        monkeypatch.delenv(name, raising=False)
        for f in former:
            monkeypatch.delenv(f, raising=False)
    assert env("FSDVS_HW_WORKER_THREADS") is None
    monkeypatch.setenv("FSDVS_SWEEP_THREADS", "3")
    with pytest.warns(DeprecationWarning, match=r"\$FSDVS_SWEEP_THREADS is deprecated; set \$FSDVS_HW_WORKER_THREADS"):
        assert env("FSDVS_HW_WORKER_THREADS") == "3"
    monkeypatch.setenv("FSDVS_HW_WORKER_THREADS", "2")
    assert env("FSDVS_HW_WORKER_THREADS") == "2"  # the new name wins, no warning
    set_env("FSDVS_HW_WORKER_THREADS", "1", default=True)
    assert os.environ["FSDVS_HW_WORKER_THREADS"] == "2"  # default=True keeps a value already set
    set_env("FSDVS_HW_WORKER_THREADS", None)
    assert "FSDVS_HW_WORKER_THREADS" not in os.environ
    with pytest.raises(KeyError):
        env("FSDVS_HW_NOT_A_VARIABLE")


def test_allocation_limit_reads_the_new_name(monkeypatch):
    from fsdvs_hw.limits import max_alloc_bytes

    monkeypatch.delenv("FSDVS_MAX_ALLOC_BYTES", raising=False)
    monkeypatch.setenv("FSDVS_HW_MAX_ALLOC_BYTES", "12345")
    assert max_alloc_bytes() == 12345


def _installed_plugin(root: Path, value: str) -> Path:
    """A site folder holding an installed distribution whose entry point names ``value``."""
    dist = root / "toy_plugin-0.1.dist-info"
    dist.mkdir(parents=True)
    (dist / "METADATA").write_text("Metadata-Version: 2.1\nName: toy-plugin\nVersion: 0.1\n")
    (dist / "entry_points.txt").write_text(f"[fsdvs_hw.realisations]\nbox = {value}\n")
    return root


def _fresh(site: Path, code: str) -> subprocess.CompletedProcess:
    env_ = {k: v for k, v in os.environ.items() if not k.endswith("REALISATION_PLUGINS")}
    env_["PYTHONPATH"] = os.pathsep.join([str(site), str(PLUGINS), str(Path(__file__).parents[1])])
    return subprocess.run(
        [sys.executable, "-W", "always", "-c", code], capture_output=True, text=True, env=env_, timeout=300
    )


def test_an_installed_plugin_is_known_in_a_fresh_process_without_any_variable(tmp_path):
    site = _installed_plugin(tmp_path / "site", "toy_realisation")
    res = _fresh(site, "from fsdvs_hw.realise import realisation_names; print(realisation_names('hardware'))")
    assert res.returncode == 0, res.stderr
    assert "'box'" in res.stdout and "'mesh'" in res.stdout


def test_a_broken_plugin_is_a_warning_naming_it_and_the_rest_still_works(tmp_path):
    site = _installed_plugin(tmp_path / "site", "no_such_module_xyz")
    res = _fresh(site, "from fsdvs_hw.realise import realisation_names; print(realisation_names('hardware'))")
    assert res.returncode == 0, res.stderr
    assert "realisation plugin 'box' (no_such_module_xyz) failed to load: ModuleNotFoundError" in res.stderr
    assert "'mesh'" in res.stdout and "'box'" not in res.stdout
