"""Which noise fires the events: a kernel's event rate split by source at each contrast threshold.

Lowering a DVS threshold buys events from the scene and from noise; below some threshold the
noise events take over (the "noise avalanche" of the FS-DVS paper's bandwidth analysis). For a
kernel, a task's held-out clips and a checkpoint's simulator settings, :func:`noise_budget`
measures at each threshold the event rate (events/pixel/s, ON + OFF)

* ``signal``: moving scene, no temporal noise (threshold mismatch kept: it is fixed pattern);
* ``photon``, ``shot``, ``leak``: the signal plus that one source alone — photon shot noise of
  the scene (:class:`~fsdvs_hw.sensor.simulation.photon_noise.PhotonNoise`, before the kernel), the pixel's
  shot-noise events and its leak events (:class:`~fsdvs_hw.sensor.SensorConfig`);
* ``all``: every source together, and ``static``: every source on a still scene (the first
  frame held), i.e. the noise floor a pixel fires with nothing moving;

and names the **dominant source** (the largest ``source − signal``) and the noise fraction
``(all − signal) / all``. The same photon draws meet every kernel (paired), so kernels compare.

Example
-------
>>> rows = noise_budget(None, "detection", "designs/kernels/networks/"
...                     "detection_with_learned_detection_7x7_s0.safetensors", [0.1, 0.2],
...                     photoelectrons_full_scale=483.0, n_test=8)        # doctest: +SKIP
>>> rows[0]["dominant"]                                                    # doctest: +SKIP
'photon'
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import InputError
from ..explore.rate import check_thresholds
from ..kernels import Kernel

__all__ = ["NOISE_SOURCES", "noise_budget"]

#: The temporal noise sources separated, in the order they are reported.
NOISE_SOURCES = ("photon", "shot", "leak")


def _rate(video: Any, taps: Any, sensor: Any, ts: np.ndarray, photon: Any) -> float:
    """Event rate of ``video`` through ``taps`` in events/pixel/s (ON + OFF, over the clips' span ``ts`` in s);
    ``photon`` (or None) adds its shot noise to the video first."""
    from ..sensor import event_frames

    v = photon.noisy(video) if photon is not None else video
    ev = event_frames(v, taps, timestamps_s=ts, config=sensor)
    span = float(ts[-1] - ts[0])
    return float(ev.sum()) / (ev.shape[0] * ev.shape[-2] * ev.shape[-1] * span)


def noise_budget(
    kernel: Kernel | None,
    task: str,
    checkpoint: str | Path,
    thresholds: Sequence[float],
    *,
    photoelectrons_full_scale: float,
    n_test: int = 64,
    seed: int = 0,
) -> list[dict[str, Any]]:
    """The event rate of ``kernel`` by noise source at each threshold (see the module docstring).

    Parameters
    ----------
    kernel : Kernel or None
        None: w/o (a plain DVS).
    task : str
        Whose held-out clips (the checkpoint's scene and test seed) are simulated.
    checkpoint : path
        A trained network's ``.safetensors`` (its scene, test seed and simulator settings).
    thresholds : sequence of float
        ON = OFF contrast thresholds (log units), at least 2.
    photoelectrons_full_scale : float
        Photon noise level: mean photoelectrons per pixel per frame at full scale
        (:func:`fsdvs_hw.sensor.simulation.photon_noise.photoelectrons_per_frame`).
    n_test : int
        Clips simulated.
    seed : int
        Seed of the photon draws.

    Returns
    -------
    list of dict
        One per threshold: ``threshold``, ``signal``, ``photon``, ``shot``, ``leak``, ``all``,
        ``static`` (events/pixel/s), ``dominant`` (the source adding most events), ``noise_fraction``.

    Raises
    ------
    InputError
        Bad thresholds, counts or checkpoint.
    """
    import torch

    from ..scenes.synthetic import SceneConfig
    from ..sensor import SensorConfig
    from ..sensor.simulation.photon_noise import PhotonNoise
    from ..tasks import get_evaluator
    from ..tasks.checkpoints import load_checkpoint
    from ..tasks.synthetic_data import synthetic_dataset

    ts_list = check_thresholds(thresholds)
    if isinstance(n_test, bool) or not isinstance(n_test, int) or not 1 <= n_test <= 100_000:
        raise InputError(f"noise_budget: n_test={n_test!r}; allowed: an integer in [1, 100000]")
    photon = PhotonNoise(photoelectrons_full_scale=photoelectrons_full_scale, seed=seed)
    prov = load_checkpoint(checkpoint)[0]
    scene = SceneConfig.from_dict(prov["scene"])
    video, _ = synthetic_dataset(scene, n_test, int(prov["test_seed"]), get_evaluator(task).name, "float64")
    static = video[:, :1].expand_as(video).contiguous()
    ts = scene.timestamps_s
    taps = torch.as_tensor(np.ones((1, 1)) if kernel is None else np.array(kernel.taps, dtype=np.float64))
    base = SensorConfig(**prov["sensor"])
    rows = []
    with torch.no_grad():
        for t in ts_list:
            s = dataclasses.replace(base, threshold_on=t, threshold_off=t)
            quiet = dataclasses.replace(s, shot_noise_rate_hz=0.0, leak_rate_hz=0.0)
            r: dict[str, Any]  # rates (float), then the dominant source and the unit (str)
            r = {
                "threshold": t,
                "signal": _rate(video, taps, quiet, ts, None),
                "photon": _rate(video, taps, quiet, ts, photon),
                "shot": _rate(
                    video, taps, dataclasses.replace(quiet, shot_noise_rate_hz=s.shot_noise_rate_hz), ts, None
                ),
                "leak": _rate(video, taps, dataclasses.replace(quiet, leak_rate_hz=s.leak_rate_hz), ts, None),
                "all": _rate(video, taps, s, ts, photon),
                "static": _rate(static, taps, s, ts, photon),
            }
            added = {k: r[k] - r["signal"] for k in NOISE_SOURCES}
            r["dominant"] = max(added, key=lambda k: added[k]) if max(added.values()) > 0 else "none"
            r["noise_fraction"] = (r["all"] - r["signal"]) / r["all"] if r["all"] > 0 else 0.0
            r["unit"] = "events/pixel/s"
            rows.append(r)
    return rows
