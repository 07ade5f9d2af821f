"""Every public function that takes a kernel takes what users hold: a Kernel, or taps plus ``pitch_m``.

Each is called with a Kernel and with ``np.asarray(kernel)`` (plus its pitch where the function
takes one) and must give the same answer; a non-kernel is refused with the project's InputError.
"""

from __future__ import annotations

import numpy as np
import pytest

from fsdvs_hw.errors import InputError
from fsdvs_hw.kernels import DEFAULT_PITCH_M, Kernel, as_kernel, reference_kernel

PITCH = 5e-6  # not the default, so a dropped pitch shows


@pytest.fixture(scope="module")
def kernel() -> Kernel:
    return reference_kernel("dog", 5, pitch_m=PITCH)


def test_kernel_converts_to_an_array_of_its_taps(kernel):
    a = np.asarray(kernel)
    assert a.dtype == np.float64 and a.shape == (5, 5) and np.array_equal(a, kernel.taps)


def test_as_kernel_repitch_only_when_asked(kernel):
    with pytest.raises(InputError, match="pitch"):
        as_kernel(kernel, pitch_m=2 * PITCH)
    k2 = as_kernel(kernel, pitch_m=2 * PITCH, repitch=True)
    assert k2.pitch_m == 2 * PITCH and np.array_equal(k2.taps, kernel.taps) and k2.name == kernel.name
    assert as_kernel(np.asarray(kernel)).pitch_m == DEFAULT_PITCH_M


def test_analyse_kernel(kernel):
    from fsdvs_hw.analysis import analyse_kernel
    from fsdvs_hw.csf import Geometry

    g = Geometry(PITCH, 4e-3)
    a, b = analyse_kernel(kernel, geometry=g), analyse_kernel(np.asarray(kernel), pitch_m=PITCH, geometry=g)
    assert b.kernel.pitch_m == PITCH
    assert {m: x.correlation for m, x in a.agreements.items()} == {m: x.correlation for m, x in b.agreements.items()}


def test_fit_asic_taps(kernel):
    from fsdvs_hw.realise.asic import fit_asic_taps

    a, b = fit_asic_taps(kernel, 6), fit_asic_taps(np.asarray(kernel), 6, pitch_m=PITCH)
    assert np.array_equal(a.taps, b.taps) and a.scale == b.scale and b.target.pitch_m == PITCH


def test_fit_resistive_mesh(kernel):
    pytest.importorskip("casadi")
    from fsdvs_hw.realise.mesh import fit_resistive_mesh

    opts = dict(n_init=4, n_starts=1, max_iter=40)
    a, b = fit_resistive_mesh(kernel, **opts), fit_resistive_mesh(np.asarray(kernel), pitch_m=PITCH, **opts)
    assert b.target.pitch_m == PITCH and a.fit["error"] == pytest.approx(b.fit["error"], rel=1e-9, abs=1e-12)
    with pytest.raises(InputError, match="None"):
        fit_resistive_mesh(None)


def test_fit_metalens(kernel):
    pytest.importorskip("torch")
    from fsdvs_hw.realise.metalens import fit_metalens

    opts = dict(n_wavelengths=1, illuminant=555e-9, n_terms=1, n_starts=1, max_iter=10, guard_px=1, n_sub=6)
    a, b = fit_metalens(kernel, **opts), fit_metalens(np.asarray(kernel).tolist(), pitch_m=PITCH, **opts)
    assert b.target.pitch_m == PITCH and np.allclose(a.psfs[0], b.psfs[0], rtol=0, atol=1e-12)


def test_fit_realisation_by_name(kernel):
    from fsdvs_hw.realise.registry import fit_realisation

    a, b = fit_realisation("asic", kernel, {"bits": 5}), fit_realisation("asic", np.asarray(kernel), {"bits": 5})
    assert np.array_equal(a.taps, b.taps)
    assert fit_realisation("learned", np.asarray(kernel)).kernel().size == 5


def test_plots_take_arrays(kernel):
    pytest.importorskip("matplotlib")
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from fsdvs_hw.plots import plot_kernel, plot_radial_vs_csf, plot_spectrum

    try:
        _, ax = plot_kernel(np.asarray(kernel))
        assert ax.get_images()[0].get_array().shape == (5, 5)
        _, ax = plot_spectrum(np.asarray(kernel).tolist())
        assert ax.get_images()
        _, ax = plot_radial_vs_csf(np.asarray(kernel))  # one array: one kernel, plus one CSF curve
        assert len(ax.get_lines()) == 2
        _, ax = plot_radial_vs_csf([kernel, np.asarray(reference_kernel("dog", 7))], labels=["a", "b"])
        assert len(ax.get_lines()) == 3
    finally:
        plt.close("all")


def test_event_simulator_takes_a_kernel_or_its_taps(kernel):
    torch = pytest.importorskip("torch")
    from fsdvs_hw.sensor import SensorConfig, event_frames

    video = torch.rand(1, 4, 10, 10, dtype=torch.float64, generator=torch.Generator().manual_seed(1))
    cfg = SensorConfig.ideal()
    assert torch.equal(event_frames(video, kernel, config=cfg), event_frames(video, np.asarray(kernel), config=cfg))


def test_learn_kernel_init_kernel_is_checked_before_training():
    pytest.importorskip("torch")
    from fsdvs_hw.errors import KernelError
    from fsdvs_hw.tasks.learn import learn_kernel

    with pytest.raises(KernelError, match="init_kernel"):
        learn_kernel("detection", size=7, init_kernel=np.asarray(reference_kernel("dog", 5)), n_train=4, n_test=4)


@pytest.mark.parametrize("bad", [{"taps": 1}, "no/such/kernel.csv", np.ones((2, 2)), [[1.0, float("nan"), 0]] * 3])
def test_what_is_not_a_kernel_is_an_input_error(bad):
    from fsdvs_hw.realise.asic import fit_asic_taps

    with pytest.raises(InputError):
        fit_asic_taps(bad, 6)
