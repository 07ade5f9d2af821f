"""The example user networks (fsdvs_hw.tasks.example_networks) and the output contract their docstring states.

A hand-made output must decode, through the task's own evaluator, to exactly the box, class or mask
the contract says: detection heatmap logits (the evaluator applies the sigmoid), size in input
pixels, offset in stride-2 cells.
"""

from __future__ import annotations

import math

import pytest

torch = pytest.importorskip("torch")

from fsdvs_hw.tasks.evaluators import get_evaluator
from fsdvs_hw.tasks.user_networks import load_network_factory


@pytest.mark.parametrize(
    ("factory", "task", "shape"),
    [
        ("classifier", "recognition", (2, 3)),
        ("segmenter", "segmentation", (2, 3, 16, 24)),
        ("detector", "detection", {"heatmap": (2, 3, 8, 12), "size": (2, 2, 8, 12), "offset": (2, 2, 8, 12)}),
    ],
)
def test_each_example_loads_by_import_path_and_returns_what_its_evaluator_reads(factory, task, shape):
    net = load_network_factory(f"fsdvs_hw.tasks.example_networks:{factory}", in_channels=6, num_classes=3)
    assert hasattr(net, "backbone") and hasattr(net, "head")  # the decoupled stage-two rates apply
    with torch.no_grad():
        out = net(torch.rand(2, 6, 16, 24))
    got = {k: tuple(v.shape) for k, v in out.items()} if isinstance(out, dict) else tuple(out.shape)
    assert got == shape
    evaluator = get_evaluator(task)
    evaluator.predict(out)  # the evaluator reads it
    if task == "detection":
        assert float(out["size"].min()) >= 0.0 and 0.0 < float(out["offset"].min()) <= float(out["offset"].max()) < 1.0
        # the untrained detector starts near the focal-loss prior p = 0.05
        assert float(torch.sigmoid(out["heatmap"]).mean()) == pytest.approx(0.05, abs=0.03)


def test_detection_contract_heatmap_logits_size_in_pixels_offset_in_cells():
    b, c, gh, gw = 1, 2, 8, 12
    heat = torch.full((b, c, gh, gw), -10.0)
    heat[0, 1, 3, 5] = 5.0  # class 1, row 3, column 5
    size = torch.zeros(b, 2, gh, gw)
    size[0, :, 3, 5] = torch.tensor([6.0, 4.0])  # width, height in input pixels
    offset = torch.zeros(b, 2, gh, gw)
    offset[0, :, 3, 5] = torch.tensor([0.25, 0.75])  # x, y within the cell, in cells
    pred = get_evaluator("detection").predict({"heatmap": heat, "size": size, "offset": offset})
    cx, cy = (5 + 0.25) * 2, (3 + 0.75) * 2  # pixels
    assert pred["boxes"][0, 0].tolist() == pytest.approx([cx - 3, cy - 2, cx + 3, cy + 2])
    assert int(pred["labels"][0, 0]) == 1
    assert float(pred["scores"][0, 0]) == pytest.approx(1 / (1 + math.exp(-5.0)))  # the sigmoid of the logit


def test_recognition_and_segmentation_contracts_are_arg_max_of_logits():
    logits = torch.tensor([[0.1, 2.0, -1.0], [3.0, 0.0, 0.0]])
    assert torch.equal(get_evaluator("recognition").predict(logits)["logits"], logits)
    seg = torch.zeros(1, 3, 2, 2)
    seg[0, 2, 0, 1] = 1.0
    assert get_evaluator("segmentation").predict(seg)["mask"].tolist() == [[[0, 2], [0, 0]]]
