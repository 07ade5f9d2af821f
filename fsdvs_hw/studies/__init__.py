"""Studies: separate experiments built on the exploration pipeline.

A study asks one question of its own with the pipeline's parts (design files, fits, scoring, the
sweep executor and store, rate curves, paired per-clip evidence, all in :mod:`fsdvs_hw.explore`)
and writes its own tables; the pipeline (``fsdvs-hw explore`` / ``sweep``) never imports a study.
Each has its own command in :mod:`fsdvs_hw.cli`.

Modules
-------
:mod:`~fsdvs_hw.studies.rate_study`
    Equal-rate curves: each kernel's losses at the same event rate (``fsdvs-hw rate``).
:mod:`~fsdvs_hw.studies.rate_retrained`
    The rate curves with a network retrained per kernel and threshold (``--protocol retrained``).
:mod:`~fsdvs_hw.studies.noise_budget`
    Which noise source fires the events at each threshold (``noise_budget.json`` of ``fsdvs-hw rate``).
:mod:`~fsdvs_hw.studies.information`
    Mutual information and bits per event (``fsdvs-hw information``).
:mod:`~fsdvs_hw.studies.kernel_size_ablation`
    The kernel-size ablation (w/o, 3×3 … 9×9) sharded over the sweep executor, resumable
    (``fsdvs-hw ablation``); the runs and tables themselves are :mod:`fsdvs_hw.tasks.ablation`.
:mod:`~fsdvs_hw.studies.user_kernel_size_ablation`
    The kernel-size ablation on a user-data task (``fsdvs-hw ablation --design``).
:mod:`~fsdvs_hw.studies.codesign_pilot`
    The co-design pilot: how much of a realisation's loss retraining and co-design recover
    (``fsdvs-hw codesign-pilot``).

The package imports none of them: import the module you need (each loads torch and the task
models only when its functions run).
"""

from __future__ import annotations

__all__ = [
    "codesign_pilot",
    "information",
    "kernel_size_ablation",
    "noise_budget",
    "rate_retrained",
    "rate_study",
    "user_kernel_size_ablation",
]
