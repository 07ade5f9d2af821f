"""Physical costs across kinds: each cost model against a hand computation, the
readout-limit breach in the verdict, the [costs] design keys, and the cross-kind front."""

from __future__ import annotations

import math

import pytest

from fsdvs_hw.costs import CostAssumptions, physical_cost
from fsdvs_hw.costs.asic import asic_cost
from fsdvs_hw.costs.mesh import mesh_cost, thermal_voltage_v
from fsdvs_hw.costs.metalens import PHOTONS_PER_LUX_S_M2, metalens_cost
from fsdvs_hw.costs.process import HOROWITZ_2014, adder_area_m2, adder_energy_j, sram_energy_per_bit_j
from fsdvs_hw.costs.readout import readout_figures
from fsdvs_hw.design import DesignError, parse_design

A = CostAssumptions()
PITCH = 4.86e-6


def test_horowitz_table_is_the_published_one_and_scales_as_stated():
    # Horowitz, ISSCC 2014, 45 nm 0.9 V: add 8/32 bit 0.03/0.1 pJ, mult 0.2/3.1 pJ, 8 KB SRAM 64-bit read 10 pJ;
    # areas add 36/137 µm², mult 282/3495 µm²
    assert dict(HOROWITZ_2014) == pytest.approx(
        {
            "add_8bit_j": 0.03e-12,
            "add_32bit_j": 0.1e-12,
            "mult_8bit_j": 0.2e-12,
            "mult_32bit_j": 3.1e-12,
            "sram_8kb_read_64bit_j": 10e-12,
            "add_8bit_m2": 36e-12,
            "add_32bit_m2": 137e-12,
            "mult_8bit_m2": 282e-12,
            "mult_32bit_m2": 3495e-12,
        },
        rel=1e-12,
    )
    assert adder_energy_j(32) == pytest.approx(0.1e-12)
    assert adder_energy_j(20) == pytest.approx(0.065e-12)  # halfway between 8 and 32 bits
    # E ∝ F·V²: 90 nm at 1.8 V is 2 x 4 = 8 times 45 nm at 0.9 V; A ∝ F²
    assert adder_energy_j(8, node_m=90e-9, supply_v=1.8) == pytest.approx(8 * 0.03e-12)
    assert adder_area_m2(8, node_m=90e-9) == pytest.approx(4 * 36e-12)
    assert sram_energy_per_bit_j() == pytest.approx(10e-12 / 64)


def test_mesh_cost_against_hand_computation():
    items = {
        "g_lateral_narrow": 1e-8,
        "g_vertical_narrow": 4e-8,
        "g_lateral_wide": 1e-8,
        "g_vertical_wide": 2e-8,
        "node_capacitance": 1e-13,
        "tau_narrow": 2.5e-6,
        "tau_wide": 5e-6,
    }
    figs, flags = mesh_cost(items, A, pitch_m=PITCH)
    ut = 1.380649e-23 * 300 / 1.602176634e-19  # kT/q = 25.852 mV
    assert thermal_voltage_v(300) == pytest.approx(0.025852, abs=1e-6)
    # HRes bias I = 2 U_T g per conductance: 2 lateral + 1 vertical per mesh per pixel
    i_mesh = 2 * ut * (2 * (1e-8 + 1e-8) + 4e-8 + 2e-8)  # 5.170e-9 A
    # 5 OTAs at I = 2 U_T mean(g_v) / kappa = 2 * 0.025852 * 3e-8 / 0.7 = 2.216e-9 A each
    i_ota = 5 * 2 * ut * 3e-8 / 0.7
    p_pixel = 1.8 * (i_mesh + i_ota)  # 2.925e-8 W
    assert p_pixel == pytest.approx(2.925e-8, rel=1e-3)
    assert figs["power_per_pixel_w"].value == pytest.approx(p_pixel, rel=1e-12)
    assert figs["power_w"].value == pytest.approx(p_pixel * 720 * 1280, rel=1e-12)  # 26.96 mW
    # area: (6 x 4 + 5 x 5) = 49 transistors x 80 F² at 45 nm = 7.938 µm², + 2 x 100 fF / 2 fF/µm² = 100 µm²
    assert figs["area_m2"].value == pytest.approx(49 * 80 * (45e-9) ** 2 + 2 * 1e-13 / 2e-3, rel=1e-12)
    assert figs["area_m2"].value == pytest.approx(107.938e-12, rel=1e-6)
    assert figs["fill_factor"].value == 0.0 and "does not fit" in flags[0]  # 108 µm² > 23.6 µm² pixel
    assert figs["latency_s"].value == 5e-6  # the slower mesh's tau
    assert "mismatch_error" not in figs
    # mismatch: sensitivity 3.28 x sigma 0.05 = 0.164 relative kernel error
    assert mesh_cost({**items, "mismatch_sensitivity": 3.28}, A, pitch_m=PITCH)[0][
        "mismatch_error"
    ].value == pytest.approx(0.164)
    # a smaller capacitor fits: 2 x 10 fF / 2 fF/µm² = 10 µm²; fill factor 1 - 17.938 / 23.62
    figs, flags = mesh_cost({**items, "node_capacitance": 1e-14}, A, pitch_m=PITCH)
    assert figs["fill_factor"].value == pytest.approx(1 - 17.938e-12 / PITCH**2, rel=1e-6) and not flags
    # the static bias power does not depend on the node; the transistors' area scales as F²
    big = mesh_cost(items, CostAssumptions(process_node_m=90e-9), pitch_m=PITCH)[0]
    assert big["power_w"].value == pytest.approx(mesh_cost(items, A, pitch_m=PITCH)[0]["power_w"].value)
    assert big["area_m2"].value == pytest.approx(4 * 7.938e-12 + 100e-12, rel=1e-6)


def test_asic_cost_against_hand_computation():
    items = {"adders": 64, "accumulator_bits": 17, "nonzero_taps": 45}
    figs, flags = asic_cost(items, A, kernel_size=7, input_bits=8)
    # 64 adders at 17 bits: 0.03 + 0.07 * 9/24 = 0.05625 pJ each -> 3.6 pJ;
    # line buffer: 1 write + 6 reads of 8 bits at 10 pJ / 64 bits -> 56 x 0.15625 = 8.75 pJ
    assert figs["energy_per_pixel_j"].value == pytest.approx(12.35e-12, rel=1e-12)
    # 1280 x 720 pixels at 1 kHz: 12.35 pJ x 921.6e6 /s = 11.38 mW
    assert figs["power_w"].value == pytest.approx(11.38176e-3, rel=1e-9)
    # lanes: ceil(921.6 MHz / 200 MHz) = 5; adders 5 x 64 x (36 + 101 x 9/24 = 73.875 µm²) = 23 640 µm²;
    # SRAM 6 x 1280 x 8 = 61 440 cells x 171 x (45 nm)² = 0.346275 µm² -> 21 275.1 µm²; per pixel / 921 600
    assert figs["lanes"].value == 5
    array = 5 * 64 * 73.875e-12 + 61440 * 171 * (45e-9) ** 2
    assert figs["array_area_m2"].value == pytest.approx(array, rel=1e-12)
    assert figs["area_m2"].value == pytest.approx(array / 921600, rel=1e-12)  # 0.0487 µm²
    # latency: 3 rows of ceil(1280/5) = 256 cycles + 3 pixels + ceil(log2 45) = 6 stages = 777 cycles at
    # 200 MHz = 3.885 µs, + half a 1 ms sample period
    assert figs["latency_s"].value == pytest.approx(777 / 200e6 + 0.5e-3, rel=1e-12)
    assert not flags
    # energy ∝ F V²: at 180 nm and 0.9 V four times the power
    slow = asic_cost(items, CostAssumptions(process_node_m=180e-9), kernel_size=7, input_bits=8)[0]
    assert slow["power_w"].value == pytest.approx(4 * figs["power_w"].value)


def test_metalens_photon_budget_against_hand_computation():
    items = {"optical_efficiency": 0.72, "contrast_factor": 0.4658, "pedestal_fraction": 0.6, "sensor_distance": 187e-6}
    figs, _ = metalens_cost(items, A, pitch_m=PITCH)
    # photons per lux-second-m² at 555 nm: (1/683 W/m²) / (h c / 555 nm = 3.5793e-19 J) = 4.0906e15
    assert pytest.approx(4.0906e15, rel=1e-4) == PHOTONS_PER_LUX_S_M2
    # N = 10 lx x 4.0906e15 x (4.86 µm)² x QE 0.5 x 1 ms x 0.72 = 347.9 photoelectrons
    assert figs["photoelectrons"].value == pytest.approx(10 * 4.0906e15 * PITCH**2 * 0.5 * 1e-3 * 0.72, rel=1e-4)
    # ΔSNR = 20 log10(0.4658) + 10 log10(0.72) = -6.636 - 1.427 = -8.063 dB
    assert figs["photon_snr_change_db"].value == pytest.approx(-8.063, abs=2e-3)
    assert figs["dynamic_range_cost_db"].value == pytest.approx(7.959, abs=1e-3)  # -20 log10(0.4)
    assert figs["power_w"].value == 0.0 and figs["area_m2"].value == 0.0 and figs["thickness_m"].value == 187e-6
    # shot-noise limit: the change does not depend on the light level, the absolute SNR does (+10 dB per 10x)
    bright = metalens_cost(items, CostAssumptions(sensor_illuminance_lux=100.0), pitch_m=PITCH)[0]
    assert bright["photon_snr_change_db"].value == pytest.approx(figs["photon_snr_change_db"].value)
    assert bright["photon_snr_db"].value - figs["photon_snr_db"].value == pytest.approx(10.0)


def test_readout_rate_scales_to_the_array_and_is_flagged_above_the_limit():
    figs, flags = readout_figures(
        {
            "detection": {"mean": 1000.0, "low": 900.0, "high": 1100.0},
            "recognition": {"mean": 1200.0, "low": 1100.0, "high": 1300.0},
        },
        A,
    )
    # busiest task: 1200 events/pixel/s x 921 600 pixels = 1.106 Geps > 1.066 Geps
    assert figs["event_rate_eps"].value == pytest.approx(1.10592e9)
    assert (figs["event_rate_eps"].low, figs["event_rate_eps"].high) == pytest.approx((1.01376e9, 1.19808e9))
    assert len(flags) == 1 and "exceeds the readout limit" in flags[0]
    assert not readout_figures({"detection": {"mean": 1000.0}}, A)[1]
    assert math.isnan(readout_figures({}, A)[0]["event_rate_eps"].value)


def _asic_point(rate_per_pixel_s: float, *, key: str = "a", realisation: str = "asic", bits: int = 8):
    from fsdvs_hw.explore.scoring import fit_realisation, score
    from fsdvs_hw.kernels import reference_kernel
    from fsdvs_hw.records import TaskScores

    target = reference_kernel("dog", 5)
    real, _ = fit_realisation(realisation, target, {"bits": bits} if realisation == "asic" else {})
    s = score(real, target=target, csf_methods=["mannos_sakrison_1974"]).with_(realisation=real.to_dict())
    rate = {"mean": rate_per_pixel_s, "low": 0.9 * rate_per_pixel_s, "high": 1.1 * rate_per_pixel_s}
    s = s.with_(
        tasks=TaskScores.from_dict(
            {
                "status": "ok",
                "detection": {
                    "simulator": {"status": "ok", "metric": 0.5, "n_seeds": 1, "n_clips": 4, "event_rate_per_s": rate}
                },
            }
        )
    )
    return {"key": key, "realisation": realisation, "params": {}, "status": "ok", "result": s.to_dict()}


def test_readout_breach_is_flagged_in_the_verdict():
    from fsdvs_hw.explore.costing import with_physical_costs
    from fsdvs_hw.records import ScoredPoint
    from fsdvs_hw.report.costs import cost_section, with_cost_columns
    from fsdvs_hw.report.tables import score_rows
    from fsdvs_hw.report.verdict import advice

    design = parse_design(
        {"realisations": {"include": ["learned", "asic"]}, "costs": {"readout_limit_eps": 1e9, "loss_budget": 0.5}}
    )
    # 2000 events/pixel/s x 921 600 pixels = 1.84 Geps > 1 Geps
    points = with_physical_costs([ScoredPoint.from_dict(_asic_point(2000.0))], design)
    rows = with_cost_columns(score_rows(points), points)
    assert rows[0]["event_rate_eps"] == pytest.approx(1.8432e9) and rows[0]["readout_exceeded"] is True
    said = " ".join(advice(rows))
    assert "Readout limit exceeded: ASIC taps fires 1.84 Geps, more than the 1 Geps the readout carries" in said
    assert "Readout limit exceeded" in cost_section(rows, points)
    # under the limit: no breach said
    points = with_physical_costs([ScoredPoint.from_dict(_asic_point(500.0))], design)
    assert "Readout limit exceeded" not in " ".join(advice(with_cost_columns(score_rows(points), points)))


def test_reference_costs_nothing_and_unknown_kind_says_so():
    from fsdvs_hw.kernels import reference_kernel
    from fsdvs_hw.records import Score

    k = reference_kernel("delta", 3)
    s = Score(
        kind="reference",
        label="delta",
        describe="",
        kernel=k,
        kernel_error=0.0,
        kernel_error_gain_free=0.0,
        dc_gain=1.0,
        asymmetry=0.0,
    )
    pc = physical_cost(s, A)
    assert [pc.value(c) for c in ("power_w", "area_m2", "latency_s")] == [0.0, 0.0, 0.0] and pc.status == "ok"
    other = physical_cost(s.with_(kind="hologram"), A)
    assert other.status.startswith("no cost model for kind 'hologram'") and math.isnan(other.value("power_w"))


@pytest.mark.parametrize(
    ("costs", "words"),
    [
        ({"process_node_m": 1.0}, ["costs.process_node_m", "1", "[3e-09, 1e-06]"]),
        ({"digital_supply_v": "high"}, ["costs.digital_supply_v", "high"]),
        ({"array_resolution": [720]}, ["costs.array_resolution"]),
        ({"readout_limit_eps": 0}, ["costs.readout_limit_eps", "0"]),
        ({"proces_node_m": 45e-9}, ["costs.proces_node_m", "unknown key"]),
    ],
)
def test_bad_cost_keys_are_refused_naming_the_key(costs, words):
    with pytest.raises(DesignError) as err:
        parse_design({"costs": costs})
    for w in words:
        assert w in str(err.value)


def test_bad_cost_sweep_value_is_refused_naming_the_axis():
    with pytest.raises(DesignError, match=r"sweep\.axes\.costs\.digital_supply_v.*9"):
        parse_design({"sweep": {"axes": {"costs.digital_supply_v": [0.9, 9.0]}}})


def test_design_without_costs_keeps_its_content_and_cost_axes_build_no_points():
    from fsdvs_hw.explore.sweep import expand_points

    plain = parse_design({"realisations": {"include": ["learned", "asic"]}})
    assert "costs" not in plain.to_dict() and plain.spec.costs == CostAssumptions()
    swept = parse_design(
        {"realisations": {"include": ["learned", "asic"]}, "sweep": {"axes": {"costs.process_node_m": [45e-9, 180e-9]}}}
    )
    assert [p.key for p in expand_points(swept)] == [p.key for p in expand_points(plain)]
    assert parse_design({"costs": {"clock_hz": 1e9}}).spec.costs.clock_hz == 1e9


def test_cost_sweep_recosts_points_and_the_power_ranking_flips():
    from fsdvs_hw.explore.costing import with_physical_costs
    from fsdvs_hw.records import ScoredPoint
    from fsdvs_hw.report.costs import cost_advice, sweep_rows, with_cost_columns
    from fsdvs_hw.report.tables import score_rows

    # a dense node capacitor (50 fF/µm²) so that the mesh fits in the pixel and competes (a mesh that
    # does not fit is never cheapest: tests/test_verdict_guards.py)
    design = parse_design(
        {
            "realisations": {"include": ["learned", "mesh", "asic"]},
            "costs": {"loss_budget": 1.0, "capacitor_density_f_m2": 0.05},
            "sweep": {"axes": {"costs.process_node_m": [45e-9, 180e-9]}},
        }
    )
    raw = [_asic_point(100.0, key="a"), _asic_point(100.0, key="m", realisation="mesh")]
    points = with_physical_costs([ScoredPoint.from_dict(p) for p in raw], design)
    asic, mesh = (p.physical_cost_sweep for p in points)
    p_asic = [e.physical_cost.value("power_w") for e in asic]
    p_mesh = [e.physical_cost.value("power_w") for e in mesh]
    assert p_asic[1] == pytest.approx(4 * p_asic[0]) and p_mesh[1] == pytest.approx(p_mesh[0])
    rows = sweep_rows(with_cost_columns(score_rows(points), points), points)
    assert len(rows) == 4
    said = cost_advice(rows)
    cheaper_at = ["ASIC taps" if a < m else "resistive mesh" for a, m in zip(p_asic, p_mesh)]
    assert cheaper_at == ["ASIC taps", "resistive mesh"]  # the ASIC's F·V² energy overtakes the mesh's bias
    # ... but at 180 nm the mesh's 49 transistors (127 µm²) no longer fit in the 4.86 µm pixel: a
    # realisation that breaks a hard limit is never the cheapest, and the limit is said
    assert "least power: ASIC taps (" in said[0] and "least power: ASIC taps (" in said[1]
    assert said[0].startswith("At process_node_m = 45 nm") and said[1].startswith("At process_node_m = 180 nm")
    assert any("resistive mesh, process_node_m = 180 nm: the mesh (131 µm²) does not fit" in line for line in said)


def test_cross_kind_front_respects_the_loss_cis():
    from fsdvs_hw.report.costs import mark_cost_fronts

    def row(kind, loss, lo, hi, power):
        return {
            "status": "ok",
            "realisation": kind,
            "params": "{}",
            "weighted_loss": loss,
            "weighted_loss_ci95_low": lo,
            "weighted_loss_ci95_high": hi,
            "power_w": power,
            "area_m2": 0.0,
            "latency_s": 0.0,
            "event_rate_eps": math.nan,
        }

    rows = [
        row("mesh", 0.01, 0.0, 0.02, 2.0),
        row("asic", 0.015, 0.005, 0.025, 1.0),
        row("metalens", 0.1, 0.09, 0.11, 3.0),
        row("learned", 0.0, 0.0, 0.0, 0.0),
    ]
    mark_cost_fronts(rows)
    # mesh and asic overlap in loss: neither dominates; the metalens is worse in both beyond the CIs
    assert [r["front_power_w"] for r in rows] == [True, True, False, False]
    assert not any(r["front_event_rate_eps"] for r in rows)  # no measured rate: on no front
