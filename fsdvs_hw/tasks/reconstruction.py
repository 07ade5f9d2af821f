"""Intensity reconstruction from events: a small E2VID-like network and its task evaluator.

The FS-DVS paper measures the information an event stream carries by reconstructing intensity
frames from it with E2VID (Rebecq et al., TPAMI 2021: a recurrent UNet trained on simulated events)
and computing the mutual information between reconstruction and ground truth (Sec. IV-E). E2VID's
published weights are not used here (no downloaded weights; its 10 M parameters are not
CPU-scale). Instead :class:`IntensityReconstructor` is a UNet-ish convolutional network of about
30 k parameters (the task backbone :class:`~fsdvs_hw.tasks.networks.EventBackbone`: full-resolution
and stride-2 features, the coarse ones upsampled and fused with the fine ones, one skip level), fed
the whole clip's event frames at once (the clip is 40 ms: no recurrence is needed to span it), and
trained here, per kernel condition, on the synthetic clips.

Ground truth: the **noise-free** linear intensity of the clip's last frame (the scene rendered
again without photon noise, :attr:`~fsdvs_hw.scenes.synthetic.SceneConfig.photon_count` = 0; clip
``i`` is bit-identical otherwise), divided by the scene's illuminance (mean ≈ 1). Events are relative
(log changes), so a reconstruction from one clip recovers where intensity changed and by how much,
plus the scene statistics the network has learnt; the network predicts a residual around the mean.

Loss: mean squared error. Scores (:meth:`ReconstructionEvaluator.score`): ``r2``, the squared
Pearson correlation of reconstruction and ground truth over all test pixels (for a jointly Gaussian
pair, MI = −½ log2(1 − r²) bits), and ``ssim`` (torchmetrics' structural similarity, Wang et al.,
IEEE TIP 2004, clipped to [0, 1]). The information measurement itself is
:mod:`fsdvs_hw.studies.information`.

The evaluator registers as task ``"reconstruction"`` when this module is imported, so
:func:`~fsdvs_hw.tasks.learn.learn_kernel` trains it (with the kernel frozen:
``learn_filter=False``) and :func:`~fsdvs_hw.tasks.learn.evaluate_kernel` scores it.

Examples
--------
>>> import torch
>>> net = IntensityReconstructor(in_channels=8, width=16)
>>> net(torch.zeros(2, 8, 32, 32)).shape
torch.Size([2, 32, 32])
"""

from __future__ import annotations

from typing import Any, cast

import numpy as np
import torch
from torch import nn
from torch.nn import functional as F

from ..errors import InputError
from ..scenes.synthetic import SceneBatch, SceneConfig, make_scenes, scene_regime
from .evaluators import EVALUATORS, TaskEvaluator, register_evaluator
from .networks import EventBackbone, conv_block

__all__ = ["RECONSTRUCTION_METRICS", "IntensityReconstructor", "ReconstructionEvaluator", "clean_last_frame"]

RECONSTRUCTION_METRICS: tuple[str, ...] = ("r2", "ssim")


class IntensityReconstructor(nn.Module):
    """Events → intensity: :class:`EventBackbone`, coarse features upsampled and fused, one output map.

    Parameters
    ----------
    in_channels : int
        ``2(T − 1)`` event-count channels (:func:`~fsdvs_hw.tasks.networks.event_representation`).
    width : int
        Channels of the full-resolution features (``2·width`` at stride 2).

    The output ``(B, H, W)`` is ``1 + head(features)``: intensity relative to the scene mean.
    """

    def __init__(self, in_channels: int, width: int = 16) -> None:
        super().__init__()
        self.backbone = EventBackbone(in_channels, width)
        c = self.backbone.out_channels + self.backbone.fine_channels
        self.head = nn.Sequential(conv_block(c, width), nn.Conv2d(width, 1, 1))

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        fine, coarse = self.backbone(x)
        up = F.interpolate(coarse, size=fine.shape[-2:], mode="bilinear", align_corners=False)
        return 1.0 + self.head(torch.cat([fine, up], dim=1))[:, 0]


def clean_last_frame(batch: SceneBatch) -> np.ndarray:
    """Noise-free linear intensity of each clip's last frame over the illuminance, ``(N, H, W)``.

    Re-renders the batch without photon noise (same config otherwise, same seed: the photon noise
    is drawn last from each clip's own random stream, so the clean clip is the same scene).

    Raises
    ------
    InputError
        A batch that is not the whole output of one ``make_scenes`` call (its clips could not be
        re-rendered).
    """
    cfg = batch.config
    if cfg.photon_count > 0:
        clean = make_scenes(cfg.with_(photon_count=0.0), len(batch), seed=batch.seed)
        if clean.video.shape != batch.video.shape:
            raise InputError("clean_last_frame: the batch could not be re-rendered without photon noise")
        video = clean.video
    else:
        video = batch.video
    return (video[:, -1] / cfg.illuminance).astype(np.float32)


class ReconstructionEvaluator(TaskEvaluator):
    """Task ``"reconstruction"``: events → the last frame's noise-free intensity; r² (primary), SSIM."""

    name = "reconstruction"
    metric_names = RECONSTRUCTION_METRICS
    primary_metric = "r2"
    staged = False

    def default_scene(self, regime: str = "clutter") -> SceneConfig:
        return scene_regime(regime, motion="random", n_objects=(1, 2))

    def build_network(self, in_channels: int, width: int = 16) -> nn.Module:
        return IntensityReconstructor(in_channels, width)

    def targets(self, batch: SceneBatch) -> dict[str, torch.Tensor]:
        return {"image": torch.from_numpy(clean_last_frame(batch))}

    def loss(self, output: torch.Tensor, target: dict[str, torch.Tensor]) -> torch.Tensor:
        return F.mse_loss(output, target["image"].to(output.dtype))

    def predict(self, output: torch.Tensor) -> dict[str, torch.Tensor]:
        return {"image": output.detach()}

    def score(self, prediction: dict[str, torch.Tensor], target: dict[str, torch.Tensor]) -> dict[str, float]:
        from torchmetrics.functional.image import structural_similarity_index_measure

        p = prediction["image"].double()
        t = target["image"].double()
        if p.shape != t.shape:
            raise InputError(f"reconstruction score: prediction {tuple(p.shape)} vs target {tuple(t.shape)}")
        r = torch.corrcoef(torch.stack([p.ravel(), t.ravel()]))[0, 1]
        r2 = float(r**2) if torch.isfinite(r) else 0.0
        span = float(t.max() - t.min()) or 1.0
        # one tensor: neither the full SSIM image nor the contrast sensitivity is asked for
        ssim = float(cast(torch.Tensor, structural_similarity_index_measure(p[:, None], t[:, None], data_range=span)))
        return {"r2": r2, "ssim": min(max(ssim, 0.0), 1.0)}


def _register() -> Any:
    existing = EVALUATORS.get(ReconstructionEvaluator.name)
    if isinstance(existing, ReconstructionEvaluator):
        return existing
    return register_evaluator(ReconstructionEvaluator())


_register()
