"""The synthetic clips a task trains and is scored on, generated once per process and cached.

:func:`synthetic_dataset` makes the video and the evaluator's targets of ``n`` clips of a scene
family (:func:`fsdvs_hw.scenes.synthetic.make_scenes`, seeded) and keeps them, least recently used
first out beyond :data:`DATASET_CACHE_BYTES` (test sets are re-scored for every realised kernel).
"""

from __future__ import annotations

import collections
from typing import Any

from .training import select_clips

__all__ = ["DATASET_CACHE_BYTES", "synthetic_dataset"]

#: Bytes of scene video :func:`synthetic_dataset` keeps (test sets are re-scored for every realised
#: kernel; the exploration's default design holds about 0.9 GB of them).
DATASET_CACHE_BYTES: int = 2 * 1024**3
_DATASET_CACHE: collections.OrderedDict[tuple[Any, ...], tuple[Any, Any, int]] = collections.OrderedDict()


def synthetic_dataset(scene: Any, n: int, seed: int, task_name: str, dtype: str = "float64") -> tuple[Any, Any]:
    """(video tensor (N, T, H, W) of ``dtype``, targets) of ``n`` clips of a scene family.

    Parameters
    ----------
    scene : SceneConfig
        The scene family.
    n : int
        Number of clips; clip ``i`` does not depend on ``n``, so a request for fewer clips than a
        cached set is served as its first ``n``.
    seed : int
        Seed of the clips.
    task_name : str
        The evaluator whose :meth:`~fsdvs_hw.tasks.evaluators.TaskEvaluator.targets` are made.
    dtype : {"float64", "float32"}
        Precision of the video.

    Returns
    -------
    video : torch.Tensor, shape (n, T, H, W)
        Linear intensity.
    targets : dict of str to torch.Tensor
        The evaluator's training targets, first axis = clips.
    """
    import torch

    from ..scenes.synthetic import make_scenes
    from .evaluators import get_evaluator

    key = (scene, int(seed), task_name, dtype)
    hit = _DATASET_CACHE.get(key)
    if hit is not None and hit[2] >= n:
        _DATASET_CACHE.move_to_end(key)
        video, targets, n_cached = hit
        return (video, targets) if n_cached == n else (video[:n], select_clips(targets, slice(0, n)))
    batch = make_scenes(scene, n, seed=seed)
    video = torch.from_numpy(batch.video).to(getattr(torch, dtype))
    targets = get_evaluator(task_name).targets(batch)
    _DATASET_CACHE[key] = (video, targets, n)
    used = sum(v.element_size() * v.nelement() for v, _, _ in _DATASET_CACHE.values())
    while used > DATASET_CACHE_BYTES and len(_DATASET_CACHE) > 1:
        old, _, _ = _DATASET_CACHE.popitem(last=False)[1]
        used -= old.element_size() * old.nelement()
    return video, targets
