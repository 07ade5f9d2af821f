"""Photon shot noise of the scene (fsdvs_hw.sensor.simulation.photon_noise) and the noise budget by source
(fsdvs_hw.studies.noise_budget): the photometry by hand, Poisson statistics, pairing across kernels,
and which noise fires the events."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from fsdvs_hw.errors import InputError
from fsdvs_hw.sensor.simulation.photon_noise import PhotonNoise, photoelectrons_per_frame

torch = pytest.importorskip("torch")
KERNELS = Path(__file__).parents[1] / "designs" / "kernels"


def test_photoelectrons_by_hand():
    # 1 lx at 555 nm = 1/683 W/m²; a photon carries hc/λ = 3.5793e-19 J
    photons_per_s_m2 = (1 / 683) / (6.62607015e-34 * 299792458 / 555e-9)
    assert photons_per_s_m2 == pytest.approx(4.0906e15, rel=1e-4)
    by_hand = photons_per_s_m2 * (4.86e-6) ** 2 * 0.5 * 0.01  # pitch², QE, 10 ms
    n = photoelectrons_per_frame(illuminance_lux=1.0, pitch_m=4.86e-6, quantum_efficiency=0.5, frame_interval_s=0.01)
    assert n == pytest.approx(by_hand, rel=1e-12) and n == pytest.approx(483.1, abs=0.1)
    assert photoelectrons_per_frame(
        illuminance_lux=10.0, pitch_m=9.72e-6, quantum_efficiency=0.5, frame_interval_s=0.01
    ) == pytest.approx(40 * n, rel=1e-12)  # ∝ E · p²


@pytest.mark.parametrize("bad", [0, -1.0, float("nan"), True, "1", 1e9])
def test_bad_photometry_is_refused_by_name(bad):
    with pytest.raises(InputError, match="illuminance_lux"):
        photoelectrons_per_frame(illuminance_lux=bad, pitch_m=4.86e-6)


def test_poisson_counts_keep_the_mean_and_have_variance_i_over_n_and_are_paired():
    noise = PhotonNoise(photoelectrons_full_scale=50.0, seed=3)
    video = torch.full((8, 5, 64, 64), 0.2, dtype=torch.float64)
    video[:, :, :, 32:] = 0.8
    a = noise.noisy(video)
    dark, bright = a[..., :32].numpy().ravel(), a[..., 32:].numpy().ravel()
    # mean I, variance I/N, and counts/N on the lattice of 1/N
    assert dark.mean() == pytest.approx(0.2, rel=0.01) and bright.mean() == pytest.approx(0.8, rel=0.01)
    assert dark.var() == pytest.approx(0.2 / 50, rel=0.03) and bright.var() == pytest.approx(0.8 / 50, rel=0.03)
    assert np.allclose(dark * 50, np.round(dark * 50))
    assert torch.equal(noise.noisy(video), a)  # the same clips meet the same photons ...
    assert not torch.equal(PhotonNoise(50.0, seed=4).noisy(video), a)  # ... another seed, other photons
    assert noise.relative_log_noise(0.2) == pytest.approx(1 / np.sqrt(10.0), rel=1e-12)
    with pytest.raises(InputError, match="photoelectrons_full_scale"):
        PhotonNoise(photoelectrons_full_scale=0.0)


def test_noise_budget_names_photon_noise_in_the_dark_and_the_avalanche_at_low_threshold():
    """Shipped detection clips, 4 of them: with few photons the photon noise adds most events, a still
    scene fires more at a lower threshold, and a centre-surround kernel amplifies the noise floor."""
    from fsdvs_hw.kernels import load_kernel
    from fsdvs_hw.studies.noise_budget import noise_budget

    ckpt = KERNELS / "networks" / "detection_with_learned_detection_7x7_s0.safetensors"
    learned = load_kernel(KERNELS / "learned_detection_7x7.json")
    dim = noise_budget(None, "detection", ckpt, (0.1, 0.3), photoelectrons_full_scale=50.0, n_test=4)
    bright = noise_budget(None, "detection", ckpt, (0.1, 0.3), photoelectrons_full_scale=5e6, n_test=4)
    for r in dim:
        assert r["dominant"] == "photon" and r["photon"] > r["signal"] > 0
        # the pixel's own shot and leak events (0.001 and 0.01 Hz) barely add to the photon noise
        assert r["all"] == pytest.approx(r["photon"], rel=0.01) and 0 < r["noise_fraction"] < 1
    assert dim[0]["static"] > dim[1]["static"]  # lower threshold: more noise events
    for d, b in zip(dim, bright):  # more photons: less noise, same signal
        assert b["signal"] == d["signal"] and b["photon"] < d["photon"] and b["static"] < d["static"]
    filt = noise_budget(learned, "detection", ckpt, (0.1, 0.3), photoelectrons_full_scale=50.0, n_test=4)
    gain = np.linalg.norm(learned.taps) / abs(np.sum(learned.taps))
    assert gain > 1 and filt[0]["static"] > dim[0]["static"]  # the surround amplifies the photon noise
    with pytest.raises(InputError, match="thresholds"):
        noise_budget(None, "detection", ckpt, (0.1,), photoelectrons_full_scale=50.0, n_test=4)
