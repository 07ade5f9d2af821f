"""The design-sweep notebooks execute (nbclient) on small settings, so they never rot.

Each notebook asserts its own physics (error falls with bits, bounds respected, fractions in
[0, 1], delta uncorrelated with every CSF); an assertion or any exception fails the test.
"""

from __future__ import annotations

import os
from pathlib import Path

import pytest

NOTEBOOKS = sorted((Path(__file__).resolve().parents[1] / "notebooks").glob("*.ipynb"))
_NEEDS = {
    "asic_bitwidth_sweep.ipynb": ["fsdvs_hw.realise.asic"],
    "mesh_conductance_sweep.ipynb": ["fsdvs_hw.realise.mesh"],
    "metalens_aperture_sweep.ipynb": ["fsdvs_hw.realise.metalens"],
    "csf_fit_comparison.ipynb": ["fsdvs_hw.realise.asic", "fsdvs_hw.realise.mesh"],
}


def test_every_notebook_is_covered():
    assert {p.name for p in NOTEBOOKS} == set(_NEEDS)


@pytest.mark.parametrize("path", NOTEBOOKS, ids=lambda p: p.stem)
def test_notebook_executes_on_small_settings(path, tmp_path, monkeypatch):
    nbformat = pytest.importorskip("nbformat")
    nbclient = pytest.importorskip("nbclient")
    for module in _NEEDS[path.name]:
        pytest.importorskip(module)
    monkeypatch.setenv("FSDVS_NOTEBOOK_QUICK", "1")
    monkeypatch.setenv("FSDVS_NOTEBOOK_OUT", str(tmp_path))
    monkeypatch.setenv("MPLBACKEND", "Agg")
    monkeypatch.setenv("OMP_NUM_THREADS", "1")
    nb = nbformat.read(path, as_version=4)
    client = nbclient.NotebookClient(nb, timeout=300, kernel_name="python3",
                                     resources={"metadata": {"path": str(path.parent)}})
    client.execute()
    text = "\n".join(o.get("text", "") for c in nb.cells if c.cell_type == "code" for o in c.get("outputs", []))
    assert "quick settings" in text
    assert "points:" in text  # the sweep summary was printed
    assert list(tmp_path.glob("*.sqlite")), "the notebook must write its results store"
