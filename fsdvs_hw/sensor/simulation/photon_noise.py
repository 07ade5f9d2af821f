"""Photon shot noise of the scene: Poisson photoelectron counts on every frame, before the kernel.

A pixel of pitch ``p`` under sensor-plane illuminance ``E_v`` collects, in one frame interval
``Δt``, on average

    N = E_v / K_m · λ / (h c) · p² · QE · Δt        (photoelectrons at full-scale intensity)

with ``K_m = 683 lm/W`` (the luminous efficacy of 555 nm light, where the photopic V(λ) peaks).
A frame's linear intensity ``I`` (a fraction of full scale) is replaced by ``n / N`` with
``n ~ Poisson(N · I)``: relative noise ``1/√(N·I)``, largest in the dark, and a log-intensity
noise of the same size that a DVS comparator meets at every frame. The FS-DVS kernel sits before
the log stage, so it filters this noise with the scene: a kernel with a large centre and a
negative surround amplifies it (its noise gain ``‖w‖₂ / Σw`` exceeds 1), which is how a filter
can fire noise events where a plain DVS does not. Dividing the threshold by that gain is what the
"noise avalanche" of a low threshold is made of.

Model assumptions: the photoreceptor integrates photocurrent over one frame interval (its
bandwidth is about the frame rate); counts are independent between pixels and frames; dark
current and read noise are left out (the sensor's own shot and leak events model the pixel's
dark noise, :class:`~fsdvs_hw.sensor.SensorConfig`).

Reference: the photon-transfer model of image sensors, e.g. J. R. Janesick, *Photon Transfer*,
SPIE Press, 2007, ch. 2 (shot noise σ = √N).

Example
-------
>>> n = photoelectrons_per_frame(illuminance_lux=1.0, pitch_m=4.86e-6, quantum_efficiency=0.5,
...                              frame_interval_s=0.01)
>>> round(n)
483
"""

from __future__ import annotations

import hashlib
import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from ...errors import InputError

__all__ = ["LUMINOUS_EFFICACY_LM_PER_W", "PhotonNoise", "photoelectrons_per_frame"]

#: Maximum luminous efficacy of radiation (lm/W at 555 nm), SI definition of the candela.
LUMINOUS_EFFICACY_LM_PER_W = 683.0
_H = 6.62607015e-34  # J s (exact, SI 2019)
_C = 299_792_458.0  # m/s (exact)


def _positive(name: str, value: Any, high: float) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not (0 < value <= high) or math.isnan(value):
        raise InputError(f"{name}={value!r}; allowed: a number in (0, {high:g}]")
    return float(value)


def photoelectrons_per_frame(
    *,
    illuminance_lux: float,
    pitch_m: float,
    quantum_efficiency: float = 0.5,
    frame_interval_s: float = 0.01,
    wavelength_m: float = 555e-9,
) -> float:
    """Mean photoelectrons a pixel collects in one frame interval at full-scale intensity.

    Parameters
    ----------
    illuminance_lux : float
        Illuminance on the sensor plane (lx) at full-scale scene intensity.
    pitch_m : float
        Pixel pitch (m); the photosensitive area is taken as ``pitch²`` (fill factor 1; scale
        ``quantum_efficiency`` by the fill factor otherwise).
    quantum_efficiency : float
        Photoelectrons per photon, in (0, 1].
    frame_interval_s : float
        Integration time (s): one frame interval of the simulated video.
    wavelength_m : float
        Monochromatic equivalent wavelength (m); 555 nm makes lux and watts meet at 683 lm/W.

    Returns
    -------
    float
        Photoelectrons per pixel per frame at full scale.

    Examples
    --------
    >>> photoelectrons_per_frame(illuminance_lux=100.0, pitch_m=4.86e-6, frame_interval_s=0.01) > 4e4
    True
    """
    e = _positive("illuminance_lux", illuminance_lux, 1e7)
    p = _positive("pitch_m", pitch_m, 1e-2)
    qe = _positive("quantum_efficiency", quantum_efficiency, 1.0)
    dt = _positive("frame_interval_s", frame_interval_s, 10.0)
    lam = _positive("wavelength_m", wavelength_m, 1e-5)
    photons_per_s_per_m2 = e / LUMINOUS_EFFICACY_LM_PER_W / (_H * _C / lam)
    return photons_per_s_per_m2 * p * p * qe * dt


@dataclass(frozen=True)
class PhotonNoise:
    """An ``events_fn`` (:func:`fsdvs_hw.tasks.learn.evaluate_kernel`) that adds photon shot noise.

    Each frame's intensity ``I`` becomes ``Poisson(N·I)/N`` before the kernel and the simulator
    (:func:`fsdvs_hw.sensor.event_frames`). The draws depend on the video batch and ``seed`` only,
    not on the kernel: every kernel scored on the same clips meets the same photons (paired).

    Parameters
    ----------
    photoelectrons_full_scale : float
        Mean photoelectrons per pixel per frame at full-scale intensity
        (:func:`photoelectrons_per_frame`), > 0.
    seed : int

    Examples
    --------
    >>> noise = PhotonNoise(photoelectrons_full_scale=483.0)
    >>> round(noise.relative_log_noise(0.1), 3)   # at 10 % of full scale: 1/sqrt(48.3)
    0.144
    """

    photoelectrons_full_scale: float
    seed: int = 0

    def __post_init__(self) -> None:
        _positive("photoelectrons_full_scale", self.photoelectrons_full_scale, 1e12)
        if isinstance(self.seed, bool) or not isinstance(self.seed, int) or not 0 <= self.seed < 2**63:
            raise InputError(f"PhotonNoise.seed={self.seed!r}; allowed: an integer in [0, 2**63)")

    def relative_log_noise(self, intensity: float) -> float:
        """Standard deviation of ``ln I`` from shot noise at ``intensity`` (fraction of full scale)."""
        return 1.0 / math.sqrt(self.photoelectrons_full_scale * max(float(intensity), 1e-12))

    def noisy(self, video: Any) -> Any:
        """``video`` (torch, any shape, linear intensity ≥ 0) with Poisson photon counts, same dtype."""
        import torch

        n = float(self.photoelectrons_full_scale)
        digest = hashlib.sha1(np.ascontiguousarray(video.detach().cpu().numpy()[..., ::7, ::7]).tobytes())
        gen = torch.Generator(device="cpu").manual_seed(
            (int.from_bytes(digest.digest()[:7], "little") + self.seed) % 2**63
        )
        rate = video.detach().cpu().double().clamp(min=0.0) * n
        counts = torch.poisson(rate, generator=gen)
        return (counts / n).to(video.dtype).to(video.device)

    def __call__(self, video: Any, kernel_taps: Any, sensor: Any, timestamps_s: Any) -> Any:
        from .. import event_frames

        return event_frames(self.noisy(video), kernel_taps, timestamps_s=timestamps_s, config=sensor)
