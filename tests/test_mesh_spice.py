"""SPICE export of a dual mesh and agreement of a real ngspice run with the casadi circuit model."""

from __future__ import annotations

import numpy as np
import pytest

from conftest import require_tool
from fsdvs_hw.errors import InputError, ToolMissingError
from fsdvs_hw.realise.mesh import MeshDesign
from fsdvs_hw.realise.mesh.response import casadi_mesh_model
from fsdvs_hw.realise.mesh.spice import run_ngspice, simulate_mesh_spice, to_spice_netlist


def _design() -> MeshDesign:
    return MeshDesign.from_space_constants(0.8, 2.5, 1.5, 1.2, size=7, g_lateral_s=3e-8)


def test_netlist_has_every_element_of_the_network():
    d = _design()
    text = to_spice_netlist(d, half_width=4, i_in_a=2e-9)
    n = 9
    lines = text.splitlines()
    lateral = [ln for ln in lines if ln.startswith(("RHn", "RVn"))]
    vertical = [ln for ln in lines if ln.startswith("RGn")]
    caps = [ln for ln in lines if ln.startswith("Cw")]
    assert len(lateral) == 2 * n * (n - 1) and len(vertical) == n * n and len(caps) == n * n
    assert float(lateral[0].split()[-1]) == pytest.approx(1 / 3e-8, rel=1e-15)
    assert float(vertical[0].split()[-1]) == pytest.approx(1 / d.g_vertical_narrow_s, rel=1e-15)
    assert "IINN 0 n4_4 DC 2e-09" in text and ".op" in text


@pytest.mark.tools
def test_ngspice_node_voltages_agree_with_the_casadi_model():
    require_tool("ngspice")
    d = _design()
    h = 10
    res = simulate_mesh_spice(d, half_width=h)
    n = 2 * h + 1
    i_in = np.zeros(n * n)
    i_in[h * n + h] = res.i_in_a
    model = casadi_mesh_model(h)
    for v_spice, g_l, g_v in (
        (res.v_narrow_v, d.g_lateral_narrow_s, d.g_vertical_narrow_s),
        (res.v_wide_v, d.g_lateral_wide_s, d.g_vertical_wide_s),
    ):
        v_model = np.array(model(g_l, g_v, i_in)).reshape(n, n)
        assert np.abs(v_spice - v_model).max() <= 1e-6 * np.abs(v_model).max()
    # and the kernel read from the SPICE voltages is the design's kernel up to the patch truncation
    k = res.kernel_taps[h - 3 : h + 4, h - 3 : h + 4]
    assert np.abs(k - d.kernel_taps(7)).max() < 1e-3 * np.abs(d.kernel_taps(7)).max()


@pytest.mark.tools
def test_ngspice_error_is_reported():
    require_tool("ngspice")
    with pytest.raises(InputError, match="ngspice"):
        run_ngspice("* broken deck\nR1 a 0\n.op\n.end\n")


def test_missing_ngspice_is_a_clear_error(monkeypatch):
    import shutil

    monkeypatch.setattr(shutil, "which", lambda name: None)
    with pytest.raises(ToolMissingError, match="apt-get install ngspice"):
        run_ngspice("* x\n.end\n")


def test_netlist_bad_input():
    d = _design()
    with pytest.raises(InputError, match="half_width"):
        to_spice_netlist(d, half_width=40)
    with pytest.raises(InputError, match="i_in_a"):
        to_spice_netlist(d, half_width=3, i_in_a=-1.0)
    with pytest.raises(InputError, match="MeshDesign"):
        to_spice_netlist({"kind": "mesh"})


@pytest.mark.tools
def test_ngspice_transient_agrees_with_the_exact_step_response():
    from fsdvs_hw.realise.mesh.dynamics import mesh_step_response
    from fsdvs_hw.realise.mesh.spice import simulate_mesh_step_spice

    require_tool("ngspice")
    d = _design()
    h = 5
    res = simulate_mesh_step_spice(d, t_stop_s=3 * d.tau_wide_s, half_width=h, n_points=50)
    assert res.t_s[0] == 0.0 and res.t_s[-1] == pytest.approx(3 * d.tau_wide_s, rel=1e-9)
    # the deck samples the requested n_points steps (interpolated output every t_stop / n_points)
    assert len(res.t_s) >= 50 and np.diff(res.t_s).max() <= 3 * d.tau_wide_s / 50 * (1 + 1e-9)
    for v, g_l, g_v in (
        (res.v_narrow_v, d.g_lateral_narrow_s, d.g_vertical_narrow_s),
        (res.v_wide_v, d.g_lateral_wide_s, d.g_vertical_wide_s),
    ):
        exact = mesh_step_response(g_l, g_v, d.node_capacitance_f, h, res.t_s) * res.i_in_a
        # a real SPICE transient carries time-integration error: ~3e-6 with the deck's tolerances
        assert np.abs(v - exact).max() <= 2e-5 * np.abs(exact).max()
