"""The design-sweep notebooks execute (nbclient) on small settings, so they never rot.

Each notebook asserts its own physics (error falls with bits, bounds respected, fractions in
[0, 1], delta uncorrelated with every CSF); an assertion or any exception fails the test. Each
also writes the numbers it computed to ``OUT/<notebook>.json``, and the test checks those values
itself. ``make notebooks`` (notebooks/execute.py) runs the same notebooks at full size and stores
them with their outputs; :func:`test_stored_notebooks_carry_their_outputs` checks that they were.
"""

from __future__ import annotations

import json
import math
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
    client = nbclient.NotebookClient(
        nb, timeout=300, kernel_name="python3", resources={"metadata": {"path": str(path.parent)}}
    )
    client.execute()
    text = "\n".join(o.get("text", "") for c in nb.cells if c.cell_type == "code" for o in c.get("outputs", []))
    assert "quick settings" in text
    assert "points:" in text  # the sweep summary was printed
    assert list(tmp_path.glob("*.sqlite")), "the notebook must write its results store"
    _CHECKS[path.stem](json.loads((tmp_path / f"{path.stem}.json").read_text()))


def _check_asic(s: dict) -> None:
    """2, 4, 8 bits: each doubling of the tap range at least halves the error here, 8 bits is within
    2 % of the target, adders grow with bits, and 8-bit taps keep the learned CSF agreement."""
    assert s["bits"] == [2, 4, 8]
    err = s["kernel_error"]
    assert err[1] < 0.5 * err[0] and err[2] < 0.5 * err[1] and err[2] < 0.02
    assert s["cost_adders"] == sorted(s["cost_adders"]) and s["cost_adders"][-1] > 0
    assert abs(s["csf_agreement"][-1] - s["learned_csf_agreement"]) < 0.05


def _check_csf(s: dict) -> None:
    """The delta is flat (correlation 0 with every model); the learned kernel correlates with each,
    and the 6-bit ASIC (kernel error < 10 %) stays within 0.05 of it for every model."""
    models = ("mannos_sakrison_1974", "barten_1999", "daly_1993", "watson_ahumada_2005", "fitted")
    assert set(s) == {"learned", "delta", "asic", "mesh"}
    assert all(s["delta"][m] == 0.0 for m in models)
    assert all(0.3 < s["learned"][m] <= 1.0 for m in models)
    assert s["learned"]["kernel_error"] == 0.0 and s["asic"]["kernel_error"] < 0.1
    assert all(abs(s["asic"][m] - s["learned"][m]) < 0.05 for m in models)


def _check_mesh(s: list) -> None:
    """The narrower range cannot fit better than the widest (solver tolerance 1e-3), both errors are
    below 1 (better than no kernel), and each fitted vertical conductance lies in its range."""
    assert len(s) == 2 and (s[0]["g_min_S"], s[0]["g_max_S"]) == (1e-13, 1e-3)
    assert s[1]["kernel_error"] >= s[0]["kernel_error"] - 1e-3
    assert all(0 <= r["kernel_error"] < 1 for r in s)
    for r in s:
        assert all(r["g_min_S"] * (1 - 1e-6) <= g <= r["g_max_S"] * (1 + 1e-6) for g in r["g_vertical_S"])


def _check_metalens(s: list) -> None:
    """One lens (D 60 µm, f 200 µm): efficiency and pedestal are fractions, the aperture is the one
    asked for, and the fit beats no kernel (error < 1)."""
    (r,) = s
    assert math.isclose(r["D_m"], 60e-6) and math.isclose(r["aperture_diameter"], 60e-6)
    assert 0 < r["optical_efficiency"] <= 1 and 0 <= r["pedestal_fraction"] <= 1
    assert 0 <= r["kernel_error"] < 1


_CHECKS = {
    "asic_bitwidth_sweep": _check_asic,
    "csf_fit_comparison": _check_csf,
    "mesh_conductance_sweep": _check_mesh,
    "metalens_aperture_sweep": _check_metalens,
}


@pytest.mark.parametrize("path", NOTEBOOKS, ids=lambda p: p.stem)
def test_stored_notebooks_carry_their_outputs(path):
    """Stored by ``make notebooks`` at full size: every code cell ran, figures are embedded, the
    run time is recorded, and no cell failed."""
    nbformat = pytest.importorskip("nbformat")
    nb = nbformat.read(path, as_version=4)
    code = [c for c in nb.cells if c.cell_type == "code"]
    assert all(c.get("execution_count") for c in code), "run `make notebooks` and commit the executed notebooks"
    outputs = [o for c in code for o in c.get("outputs", [])]
    assert not any(o.get("output_type") == "error" for o in outputs)
    assert any("image/png" in o.get("data", {}) for o in outputs), "no figure stored"
    meta = nb.metadata.get("fsdvs_hw", {})
    assert meta.get("settings") == "full" and meta.get("wall_s", 0) > 0
    assert "\r" not in "".join(o.get("text", "") for o in outputs)  # progress bars stored in their final state


def test_execute_stores_progress_bars_in_their_final_state():
    """notebooks/execute.py merges a cell's stream outputs and keeps each bar's last redraw."""
    import importlib.util

    nbformat = pytest.importorskip("nbformat")
    spec = importlib.util.spec_from_file_location("nb_execute", NOTEBOOKS[0].parent / "execute.py")
    ex = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(ex)
    out = nbformat.v4.new_output
    cell = nbformat.v4.new_code_cell(
        "x",
        outputs=[
            out("stream", name="stderr", text="\rpts:   0%| 0/2"),
            out("stream", name="stderr", text="\rpts:  50%| 1/2"),
            out("stream", name="stderr", text="\rpts: 100%| 2/2\n"),
            out("stream", name="stdout", text="done\n"),
        ],
    )
    nb = nbformat.v4.new_notebook(cells=[cell])
    ex.tidy_streams(nb)
    assert [(o.name, o.text) for o in nb.cells[0].outputs] == [("stderr", "pts: 100%| 2/2\n"), ("stdout", "done\n")]
