"""The toolkit's results chain: learn → weights → explore, and a kernel the network was not trained with is refused.

On a tiny UCF101-layout set (2 classes × 4 videos of 16 × 16 px that brighten or darken):
``fsdvs-hw learn --design`` writes the kernel the design's ``[kernel] path`` names (the file did
not exist when the design was written); its checkpoint loads as another design's ``weights``;
``explore`` scores with them; and a design whose kernel is not the one the network was trained
with is refused, by fingerprint, with the fix in the message.
"""

from __future__ import annotations

import json
from pathlib import Path

import imageio.v2 as imageio
import numpy as np
import pytest

torch = pytest.importorskip("torch")

from conftest import cheap_design

from fsdvs_hw.design import load_design
from fsdvs_hw.errors import InputError
from fsdvs_hw.tasks.checkpoints import is_task_checkpoint, kernel_fingerprint, load_checkpoint

SIDE = 16

DATASET = 'dataset = { format = "video_folder", root = "ucf", n_frames = 4, fps = 25.0 }\n'
TRAIN = "train = { kernel_size = 3, epochs_frozen = 0, epochs_joint = 1, batch_size = 4 }\n"


@pytest.fixture(scope="module")
def folder(tmp_path_factory) -> Path:
    """A design folder with ``ucf/<class>/<video>.mp4``: class 'Brighten' and 'Darken', 4 videos each."""
    root = tmp_path_factory.mktemp("chain")
    rng = np.random.default_rng(0)
    for cls, gain in (("Brighten", 1.4), ("Darken", 0.7)):
        (root / "ucf" / cls).mkdir(parents=True)
        for v in range(4):
            base = 40 + 60 * rng.random((SIDE, SIDE, 1))
            frames = [np.clip(base * gain**t, 0, 255).astype(np.uint8).repeat(3, axis=2) for t in range(4)]
            path = root / "ucf" / cls / f"v_{cls}_g0{v}.mp4"
            with imageio.get_writer(str(path), fps=25, codec="libx264", quality=9, macro_block_size=1) as w:
                for f in frames:
                    w.append_data(f)
    return root


def _design(folder: Path, name: str, kernel: str, table: str) -> Path:
    text = cheap_design(name) + kernel + "[tasks.datasets.recognition]\n" + DATASET + "n_clips = 3\n" + table
    path = folder / f"{name}.toml"
    path.write_text(text)
    return path


def _file_kernel(path: str) -> str:
    return f'[kernel]\nsource = "file"\npath = "{path}"\n'


@pytest.fixture(scope="module")
def learned(folder) -> dict:
    """``fsdvs-hw learn recognition --design`` on a design whose [kernel] path names a file not there yet."""
    from fsdvs_hw.cli import main

    design = _design(folder, "learn", _file_kernel("kernels/mine.json"), TRAIN)
    before = load_design(design)  # loads although kernels/mine.json does not exist: learn writes it
    assert before.pending_kernel_task == "recognition" and before.target.size == 3
    assert not (folder / "kernels" / "mine.json").exists()
    assert main(["learn", "recognition", "--design", str(design)]) == 0
    return {"design": design, "ckpt": folder / "trained" / "recognition.safetensors"}


def test_learn_writes_the_kernel_the_design_names_and_its_fingerprint(folder, learned):
    ckpt = learned["ckpt"]
    provenance, _, kernel = load_checkpoint(ckpt)
    assert provenance["kernel_fingerprint"] == kernel_fingerprint(kernel.taps)
    mine = json.loads((folder / "kernels" / "mine.json").read_text())
    assert kernel_fingerprint(mine["taps"]) == kernel_fingerprint(kernel.taps)  # the learned taps, not a delta
    assert not np.allclose(kernel.taps, np.eye(3)[1][:, None] * np.eye(3)[1])
    after = load_design(learned["design"])
    assert after.pending_kernel_task is None and kernel_fingerprint(after.target.taps) == kernel_fingerprint(
        kernel.taps
    )


def test_the_toolkit_checkpoint_loads_as_weights(folder, learned):
    from fsdvs_hw.design.user_data_inputs import open_dataset, open_untrained_network

    assert is_task_checkpoint(learned["ckpt"])
    path = _design(
        folder,
        "weights",
        _file_kernel("trained/recognition.json"),
        'weights = "trained/recognition.safetensors"\n',
    )
    design = load_design(path)  # was refused: missing parameters [...], unexpected ['kernel', 'network.…']
    entry = design.spec.tasks.datasets["recognition"].model_dump()
    ds = open_dataset(entry["dataset"], folder, key="k")
    net = open_untrained_network(entry, ds, folder, key="k")
    state = load_checkpoint(learned["ckpt"])[1]
    assert set(net.state_dict()) == set(state)
    for k, v in net.state_dict().items():
        assert torch.equal(v, state[k])


def test_round_trip_learn_weights_explore(folder, learned, tmp_path):
    from fsdvs_hw.cli import main

    path = _design(
        folder, "explore", _file_kernel("kernels/mine.json"), 'weights = "trained/recognition.safetensors"\n'
    )
    out = tmp_path / "out"
    assert main(["explore", str(path), "--out", str(out), "--no-progress"]) == 0
    blob = json.loads((out / "scores.json").read_text())
    rows = {r["realisation"]: r for r in blob["rows"]}
    assert rows["learned"]["recognition_loss"] == 0.0 and rows["delta"]["recognition_n_clips"] == 3
    points = {p["realisation"]: p for p in blob["points"]}
    rec = points["learned"]["result"]["tasks"]["recognition"]["simulator"]
    assert 0.0 <= rec["metric"] <= 1.0


@pytest.mark.parametrize(
    ("kernel", "why"),
    [
        ('[kernel]\nsource = "reference"\nsize = 3\n', "[kernel] source = 'reference'"),
        (_file_kernel("other.json"), "[kernel] path = 'other.json'"),
    ],
)
def test_a_kernel_the_network_was_not_trained_with_is_refused_with_the_fix(folder, learned, tmp_path, kernel, why):
    from fsdvs_hw.explore.explore import run_exploration

    (folder / "other.json").write_text(json.dumps({"taps": np.eye(3).tolist()}))
    for name, table in (("w", 'weights = "trained/recognition.safetensors"\n'), ("t", TRAIN)):
        design = load_design(_design(folder, f"mismatch_{name}", kernel, table))
        with pytest.raises(InputError) as err:
            run_exploration(design, tmp_path / name, progress=False)
        msg = str(err.value)
        assert why in msg and "is not the kernel tasks.datasets.recognition's network was trained with" in msg
        assert "Fix: set [kernel] source = 'file' and path = 'trained/recognition.json'" in msg
        assert not (tmp_path / name / "scores.json").exists()  # refused before any point was scored


def test_sweep_refuses_the_mismatch_and_a_kernel_not_trained_yet(folder, learned, tmp_path, capsys):
    from fsdvs_hw.cli import main

    wrong = _design(
        folder, "sweep_w", '[kernel]\nsource = "reference"\nsize = 3\n', 'weights = "trained/recognition.safetensors"\n'
    )
    assert main(["sweep", str(wrong), "--store", str(tmp_path / "s.sqlite"), "--no-progress"]) == 2
    assert "Fix: set [kernel] source = 'file'" in capsys.readouterr().err
    table = TRAIN.replace("kernel_size = 3", 'kernel_size = 3, out = "trained/other"')
    pending = _design(folder, "sweep_p", _file_kernel("kernels/never.json"), table)
    assert main(["sweep", str(pending), "--store", str(tmp_path / "p.sqlite"), "--no-progress"]) == 2
    err = capsys.readouterr().err
    assert "kernels/never.json" in err and "has not trained yet; run `fsdvs-hw learn recognition --design" in err
    assert not (tmp_path / "s.sqlite").exists() and not (tmp_path / "p.sqlite").exists()
