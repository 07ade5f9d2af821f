"""learn_kernel(realisation=...): the network and the realisation's own parameters train together
(co-design); the kernel stays the realisation's at every step."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

torch = pytest.importorskip("torch")

from fsdvs_hw.errors import InputError  # noqa: E402
from fsdvs_hw.kernels import load_kernel  # noqa: E402
from fsdvs_hw.realise.asic import AsicDesign  # noqa: E402
from fsdvs_hw.tasks import learn_kernel  # noqa: E402
from fsdvs_hw.tasks.learn import TrainingSettings  # noqa: E402

LEARNED = Path(__file__).resolve().parents[1] / "designs" / "kernels" / "learned_detection_7x7.json"


def test_asic_codesign_trains_integer_taps_and_saves_the_design():
    settings = TrainingSettings(epochs_frozen=1, epochs_joint=2, batch_size=16, lr_filter=0.5, dtype="float32")
    res = learn_kernel(
        "recognition",
        7,
        seed=0,
        n_train=64,
        n_test=32,
        settings=settings,
        init_kernel=load_kernel(LEARNED),
        realisation="asic",
    )
    prov = res.kernel.provenance
    assert prov["realisation"] == "asic"
    start = AsicDesign.from_dict(prov["realisation_initial"])
    final = AsicDesign.from_dict(prov["realisation_design"])
    assert final.fit_info["codesigned"] and final.bits == start.bits
    # the learned kernel is exactly the final integer design's (buildable at every step)
    np.testing.assert_allclose(np.asarray(res.kernel), final.kernel().taps, rtol=0, atol=1e-6)
    assert not np.array_equal(final.taps, start.taps)  # the integer taps moved with lr 0.5 per step
    assert 0.0 <= res.metrics["top1"] <= 1.0


def test_codesign_needs_an_initial_kernel_and_a_differentiable_realisation():
    with pytest.raises(InputError, match="needs init_kernel"):
        learn_kernel("recognition", 7, n_train=8, n_test=4, realisation="asic")
    with pytest.raises(InputError, match="has no differentiable form"):
        learn_kernel("recognition", 7, n_train=8, n_test=4, init_kernel=load_kernel(LEARNED), realisation="delta")


@pytest.mark.parametrize("name", ["mesh", "metalens"])
def test_mesh_and_metalens_codesign_run_and_keep_the_kernel_the_realisations(name):
    from fsdvs_hw.realise.registry import get_realisation

    settings = TrainingSettings(epochs_frozen=1, epochs_joint=1, batch_size=16, dtype="float32")
    res = learn_kernel(
        "recognition",
        7,
        seed=0,
        n_train=32,
        n_test=16,
        settings=settings,
        init_kernel=load_kernel(LEARNED),
        realisation=name,
    )
    prov = res.kernel.provenance
    final = get_realisation(name).record_type.from_dict(prov["realisation_design"])
    assert final.kind == name and (final.fit if name == "mesh" else final.fit_info)["codesigned"]
    np.testing.assert_allclose(np.asarray(res.kernel), np.asarray(final.kernel()), rtol=1e-6, atol=1e-9)
    assert any(h["stage"] == "joint" for h in res.history)


def test_codesign_pilot_checks_its_inputs_before_training_and_measures_csf_drift(tmp_path):
    from fsdvs_hw.csf import csf_agreement
    from fsdvs_hw.explore.codesign import csf_drift
    from fsdvs_hw.realise.asic import fit_asic_taps
    from fsdvs_hw.studies.codesign_pilot import run_pilot

    with pytest.raises(InputError, match="no differentiable form"):
        run_pilot("recognition", "delta", [0], tmp_path)
    with pytest.raises(InputError, match="no shipped reference network .*_s11"):
        run_pilot("recognition", "asic", [11], tmp_path)  # seed 11 never trained: not shipped
    with pytest.raises(InputError, match="distinct"):
        run_pilot("recognition", "asic", [0, 0], tmp_path)
    assert not any(tmp_path.iterdir())  # nothing trained or written
    rec = fit_asic_taps(load_kernel(LEARNED), bits=4)
    moved = rec.__class__.from_dict({**rec.to_dict(), "scale": rec.scale * 2})  # shape unchanged
    d = csf_drift({"realisation_initial": rec.to_dict(), "realisation_design": moved.to_dict()})
    expected = csf_agreement(rec.kernel(), method="mannos_sakrison_1974").correlation
    assert d["ms_correlation_initial"] == pytest.approx(expected, abs=1e-12)
    assert d["ms_correlation_final"] == pytest.approx(expected, abs=1e-9)  # a gain does not change the shape
