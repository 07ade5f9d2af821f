"""Task evaluators and end-to-end kernel learning.

* :mod:`~fsdvs_hw.tasks.metrics` — detection mAP (pycocotools), top-1 and segmentation scores
  (torchmetrics).
* :mod:`~fsdvs_hw.tasks.networks` — small CPU networks on event frames.
* :mod:`~fsdvs_hw.tasks.evaluators` — the :class:`TaskEvaluator` plug-in interface, the detection /
  recognition / segmentation evaluators and their registry.
* :mod:`~fsdvs_hw.tasks.learn` — :func:`learn_kernel` and :func:`evaluate_kernel`.
* :mod:`~fsdvs_hw.tasks.training` — the training engine every training path runs (a
  :class:`~fsdvs_hw.tasks.training.TrainingConfig` per stage, one epoch loop);
  :mod:`~fsdvs_hw.tasks.checkpoints` — checkpoint files and the partial state a run resumes from;
  :mod:`~fsdvs_hw.tasks.event_inputs` — clips through the simulator to the network's input;
  :mod:`~fsdvs_hw.tasks.synthetic_data` — the cached synthetic clips.
* :mod:`~fsdvs_hw.tasks.user_networks` — a user network by import path (``"pkg.mod:factory"``), its
  event representation, user weights; :mod:`~fsdvs_hw.tasks.dataset_eval` — :func:`evaluate_on_dataset`
  scores a kernel on a user dataset (:mod:`fsdvs_hw.scenes.datasets`);
  :mod:`~fsdvs_hw.tasks.dataset_training` trains a network and a kernel on one, its clips streamed
  with bounded memory by :mod:`~fsdvs_hw.tasks.clip_stream` and sampled (clips per video, crop,
  flip) by :mod:`~fsdvs_hw.tasks.clip_sampling`.
* :mod:`~fsdvs_hw.tasks.reconstruction` — events → intensity (a small E2VID-like network), task
  ``"reconstruction"``, registered when that module is imported (the information study,
  :mod:`fsdvs_hw.studies.information`).
* :mod:`~fsdvs_hw.tasks.ablation` — one run of the kernel-size ablation (the paper's Tables I-III)
  and its tables; :mod:`fsdvs_hw.studies.kernel_size_ablation` shards the runs over the sweep executor.

Names are imported lazily so ``import fsdvs_hw.tasks`` does not import torch.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from .._lazy import lazy_exports

_LAZY = {
    "detection_map": "fsdvs_hw.tasks.metrics",
    "top1_accuracy": "fsdvs_hw.tasks.metrics",
    "segmentation_scores": "fsdvs_hw.tasks.metrics",
    "TaskEvaluator": "fsdvs_hw.tasks.evaluators",
    "EVALUATORS": "fsdvs_hw.tasks.evaluators",
    "get_evaluator": "fsdvs_hw.tasks.evaluators",
    "register_evaluator": "fsdvs_hw.tasks.evaluators",
    "learn_kernel": "fsdvs_hw.tasks.learn",
    "evaluate_kernel": "fsdvs_hw.tasks.learn",
    "LearnResult": "fsdvs_hw.tasks.learn",
    "Evaluation": "fsdvs_hw.tasks.learn",
    "heldout_targets": "fsdvs_hw.tasks.learn",
    "load_network_factory": "fsdvs_hw.tasks.user_networks",
    "load_weights": "fsdvs_hw.tasks.user_networks",
    "EventInput": "fsdvs_hw.tasks.user_networks",
    "evaluate_on_dataset": "fsdvs_hw.tasks.dataset_eval",
    "DatasetEvaluation": "fsdvs_hw.tasks.dataset_eval",
    "ReconstructionEvaluator": "fsdvs_hw.tasks.reconstruction",
    "IntensityReconstructor": "fsdvs_hw.tasks.reconstruction",
    "ablation_jobs": "fsdvs_hw.tasks.ablation",
    "run_job": "fsdvs_hw.tasks.ablation",
}

__all__, __getattr__, __dir__ = lazy_exports("fsdvs_hw.tasks", _LAZY, globals())

if TYPE_CHECKING:  # the same names, visible to IDEs and type checkers
    from .ablation import ablation_jobs, run_job
    from .dataset_eval import DatasetEvaluation, evaluate_on_dataset
    from .evaluators import EVALUATORS, TaskEvaluator, get_evaluator, register_evaluator
    from .learn import Evaluation, LearnResult, evaluate_kernel, heldout_targets, learn_kernel
    from .metrics import detection_map, segmentation_scores, top1_accuracy
    from .reconstruction import IntensityReconstructor, ReconstructionEvaluator
    from .user_networks import EventInput, load_network_factory, load_weights
