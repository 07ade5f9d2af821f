"""A user clip dataset made on demand from its index (no files), for the streaming tests.

``ProceduralClips(n, size, n_frames)``: clip ``i`` is a bright bar moving right (class 0) or left
(class 1) over a seeded noisy background, generated when it is asked for, so a dataset of any
size costs no disk and no memory until its clips are read: what the streaming loader's memory
bound is measured against (tests/test_user_data_streaming.py).
"""

from __future__ import annotations

import numpy as np

from fsdvs_hw.scenes.datasets import Clip, ClipDataset

__all__ = ["ProceduralClips"]


class ProceduralClips(ClipDataset):
    """``n`` recognition clips of ``n_frames`` frames of ``size`` px, two classes (bar moving right / left)."""

    task = "recognition"
    num_classes = 2
    class_names = ("right", "left")

    def __init__(self, n: int, size: tuple[int, int] = (64, 64), n_frames: int = 8, fps: float = 25.0) -> None:
        super().__init__()
        self.n, self.size, self.n_frames, self.fps = int(n), (int(size[0]), int(size[1])), int(n_frames), float(fps)
        self.loads = 0

    def __len__(self) -> int:
        return self.n

    def _load(self, i: int) -> Clip:
        self.loads += 1
        h, w = self.size
        rng = np.random.default_rng(i)
        label = i % 2
        frames = 0.2 + 0.05 * rng.random((self.n_frames, h, w))
        x0 = int(rng.integers(0, w // 2))
        for t in range(self.n_frames):
            x = x0 + (2 * t if label == 0 else -2 * t) % (w // 2)
            frames[t, :, x : x + 4] = 0.8
        ts = np.arange(self.n_frames) / self.fps
        return Clip(frames, ts, {"motion": np.int64(label)}, f"procedural clip {i}", i)
