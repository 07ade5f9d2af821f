"""``[codesign]`` on a ``[tasks.datasets.<task>]`` task: the swap / finetune / codesign rows on user data.

Frames + label masks (12 frames, 10 clips of 3) with the toy voxel network beside the design, trained
first by the table's ``train`` (1 + 1 epochs); the co-design table fits the ASIC taps to the design's
kernel and measures the three rows in the one user network (1 epoch, 4 training clips drawn from the
clips not scored), scored per clip on the 3 scored clips against the design's kernel.
"""

from __future__ import annotations

import json
from pathlib import Path

import pytest

pytest.importorskip("torch")
from conftest import cheap_design
from test_user_training_design import TABLE, TRAIN, folder  # noqa: F401 (the module fixture)

from fsdvs_hw.design import DesignError, load_design

CODESIGN = '[codesign]\nenabled = true\nrealisations = ["asic"]\nepochs = 1\nn_train = 4\nlr_filter = 0.05\n'


def _design(folder: Path, train: str = TRAIN, name: str = "cd", codesign: str = CODESIGN) -> Path:
    path = folder / f"{name}.toml"
    table = TABLE.format(train=train)
    if not train:
        table = table.replace("train = {  }\n", "")
    path.write_text(cheap_design(name) + "[scoring]\nn_resamples = 200\n" + codesign + table)
    return path


def test_user_data_codesign_rows_cover_their_estimates_and_a_rerun_reuses_every_unit(folder, tmp_path):
    from fsdvs_hw.explore.codesign import codesign_cells, run_codesign, write_codesign
    from fsdvs_hw.report.codesign_section import codesign_section
    from fsdvs_hw.report.report_input import CodesignSummary

    design = load_design(_design(folder))
    assert codesign_cells(design) == [("asic", "segmentation")]
    out = tmp_path / "out"
    summary = run_codesign(design, out, progress=False)
    (cell,) = summary["cells"]
    assert (cell["realisation"], cell["task"], cell["metric_name"]) == ("asic", "segmentation", "miou")
    assert cell["n_seeds"] == 1 and cell["n_clips"] == 3 and cell["clips"] == "shared"
    assert cell["data"] == "user" and "resamples the clips only (n_seeds = 1)" in cell["ci_note"]
    assert set(cell["rows"]) == {"swap", "finetune", "codesign"}
    for row in cell["rows"].values():
        loss = row["loss"]
        assert loss["low"] <= loss["estimate"] <= loss["high"]
        # the loss is the reference's metric minus the row's, on the same clips
        assert loss["estimate"] == pytest.approx(
            cell["reference_metric_per_seed"][0] - row["metric_per_seed"][0], abs=1e-9
        )
    for mode in ("finetune", "codesign"):
        gain = cell["rows"][mode]["gain_over_swap"]
        assert gain["low"] <= gain["estimate"] <= gain["high"]
    # the co-designed row trained the ASIC's own parameters: a buildable design is recorded
    units = sorted((out / "codesign" / "units").glob("*.json"))
    assert len(units) == 4  # the design's kernel (reference) + three rows
    cd_unit = json.loads(next(p for p in units if "_codesign_" in p.name).read_text())
    assert cd_unit["realisation_design"]["kind"] == "asic" and cd_unit["kernel_error_codesign"] >= 0
    prov = json.loads(
        next((out / "codesign" / "networks").glob("asic_segmentation_s0_finetune_*.provenance.json")).read_text()
    )
    entry = design.data["tasks"]["datasets"]["segmentation"]
    from fsdvs_hw.design.user_data_inputs import open_dataset

    scored = set(open_dataset(entry["dataset"], folder, key="k").draw(3, 0).tolist())
    assert len(prov["train_indices"]) == 4 and not scored & set(prov["train_indices"])
    assert [h["stage"] for h in prov["history"]] == ["frozen_filter"]  # the fitted kernel frozen, 1 epoch
    assert prov["learning_rates"]["network_stage_one"] == design.spec.codesign.lr_network
    assert cd_unit["train_s"] > 0 and len(cd_unit["realisation_design"]) > 1

    stamps = [p.stat().st_mtime_ns for p in units]
    again = run_codesign(design, out, progress=False)  # every unit reused, nothing trained or scored
    assert [p.stat().st_mtime_ns for p in sorted((out / "codesign" / "units").glob("*.json"))] == stamps
    assert again["cells"][0]["rows"]["codesign"]["loss"] == cell["rows"]["codesign"]["loss"]
    jpath, cpath = write_codesign(again, out)
    assert cpath.read_text().count("asic,segmentation,") == 3
    assert "resamples the clips only" in codesign_section(CodesignSummary.from_dict(again))


def test_user_data_codesign_needs_a_trained_network(folder):
    with pytest.raises(DesignError) as err:
        load_design(_design(folder, train="", name="untrained"))
    msg = str(err.value)
    assert "untrained.toml" in msg and "tasks.datasets.segmentation" in msg and "weights" in msg


def test_codesign_tasks_may_name_a_user_data_task_but_not_an_unknown_one(folder):
    design = load_design(_design(folder, name="named", codesign=CODESIGN + 'tasks = ["segmentation"]\n'))
    assert design.data["codesign"]["tasks"] == ["segmentation"]
    with pytest.raises(DesignError, match="not a task in tasks.checkpoints or tasks.datasets; allowed: segmentation"):
        load_design(_design(folder, name="unknown", codesign=CODESIGN + 'tasks = ["detection"]\n'))


def test_a_killed_co_design_training_resumes_to_the_uninterrupted_result(folder, tmp_path, monkeypatch):
    import numpy as np

    import fsdvs_hw.tasks.dataset_training as dt
    from fsdvs_hw.explore.user_data import finetune_user_network
    from fsdvs_hw.realise.registry import fit_realisation

    design = load_design(_design(folder))
    entry = design.data["tasks"]["datasets"]["segmentation"]
    fit = fit_realisation("asic", design.target, design.realisation_options("asic"), seed=0)
    kw = {"realisation": fit, "epochs": 2, "n_train": 4, "lr_filter": 0.05, "fingerprint": {"run": 1}}
    whole = finetune_user_network("segmentation", entry, folder, out=tmp_path / "whole", **kw)
    assert whole.epochs_trained == 2 and [h["stage"] for h in whole.history] == ["joint", "joint"]
    assert whole.history[-1]["kernel_change_l1"] > 0  # the ASIC's parameters moved the kernel

    save = dt.save_partial

    def killed_after_first_epoch(*args, **kwargs):
        save(*args, **kwargs)
        raise KeyboardInterrupt

    monkeypatch.setattr(dt, "save_partial", killed_after_first_epoch)
    with pytest.raises(KeyboardInterrupt):
        finetune_user_network("segmentation", entry, folder, out=tmp_path / "killed", **kw)
    monkeypatch.setattr(dt, "save_partial", save)
    assert (tmp_path / "killed.partial.pt").is_file()
    resumed = finetune_user_network("segmentation", entry, folder, out=tmp_path / "killed", **kw)
    assert resumed.epochs_trained == 1 and not (tmp_path / "killed.partial.pt").exists()
    np.testing.assert_allclose(np.array(resumed.kernel.taps), np.array(whole.kernel.taps), rtol=0, atol=1e-10)
    assert resumed.provenance["realisation_design"] == whole.provenance["realisation_design"]


def test_too_many_codesign_training_clips_name_the_key_and_the_clips_left(folder):
    from fsdvs_hw.errors import InputError
    from fsdvs_hw.explore.user_data import finetune_user_network

    design = load_design(_design(folder))
    entry = design.data["tasks"]["datasets"]["segmentation"]
    with pytest.raises(InputError) as err:
        finetune_user_network("segmentation", entry, folder, kernel=design.target, n_train=9)
    msg = str(err.value)
    assert "codesign.n_train = 9" in msg and "7 of the 10 clips are left" in msg and "2 to 7" in msg, msg
