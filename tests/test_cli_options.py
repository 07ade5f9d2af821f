"""From a verb's flags to its options object (fsdvs_hw.cli._options): each verb's options equal the
ones its flags gave when every field was written out (before options_from_args)."""

from __future__ import annotations

import argparse
import dataclasses
import sys
from pathlib import Path

import pytest

from fsdvs_hw.cli import main
from fsdvs_hw.cli._options import command_line, options_from_args

ROOT = Path(__file__).resolve().parents[1]
DESIGN = str(ROOT / "designs" / "default.toml")


@dataclasses.dataclass(frozen=True)
class _Toy:
    sizes: tuple = ()
    flag: bool = False
    kept: int = 7
    progress: bool | None = None
    command: str = ""
    derived: int = dataclasses.field(init=False, default=0)


def test_options_from_args_rules(monkeypatch):
    monkeypatch.setattr(sys, "argv", ["fsdvs-hw", "toy", "--sizes", "3", "5"])
    args = argparse.Namespace(command="toy", sizes=[3, 5], flag=True, no_progress=True, derived=9, other=1)
    opts = options_from_args(_Toy, args)
    assert opts == _Toy(sizes=(3, 5), flag=True, kept=7, progress=False, command="fsdvs-hw toy --sizes 3 5")
    assert opts.derived == 0  # not an init field: never taken from a flag
    assert options_from_args(_Toy, args, flag=False, command="given").flag is False
    assert options_from_args(_Toy, argparse.Namespace(command="toy", no_progress=False)).progress is None
    monkeypatch.setattr(sys, "argv", ["fsdvs-hw", "toy"])
    assert command_line("toy") == "fsdvs-hw toy"


class _CapturedError(Exception):
    """Raised by the stand-in study function once it has the options."""


def _capture(monkeypatch, target: str) -> list:
    got: list = []

    def fake(options, *rest):
        got.append(options)
        raise _CapturedError

    monkeypatch.setattr(target, fake)
    return got


def _run(argv: list[str]) -> None:
    with pytest.raises(_CapturedError):
        main(argv)


def test_rate_options(monkeypatch, tmp_path):
    from fsdvs_hw.studies.rate_study import RateOptions

    got = _capture(monkeypatch, "fsdvs_hw.studies.rate_study.run_rate_study")
    argv = ["rate", DESIGN, "--out", str(tmp_path), "--thresholds", "0.1", "0.3", "--networks", "2"]
    argv += ["--seeds", "3", "--resolution", "20", "10", "--realisations", "asic", "--no-progress"]
    monkeypatch.setattr(sys, "argv", ["fsdvs-hw", *argv])
    _run(argv)
    from fsdvs_hw.cli import rate

    parser = argparse.ArgumentParser()
    rate.add_arguments(parser)
    args = parser.parse_args([a for a in argv[1:] if a != "--no-progress"])  # a flag of every verb
    assert got[0] == RateOptions(  # as the command wrote it out before options_from_args
        design=args.design,
        task=args.task,
        out=args.out,
        thresholds=tuple(args.thresholds),
        n_networks=args.networks,
        n_test=args.n_test,
        realisations=tuple(args.realisations),
        illuminance_lux=args.illuminance_lux,
        quantum_efficiency=args.quantum_efficiency,
        protocol=args.protocol,
        seeds=tuple(range(args.seeds)),
        n_train=args.n_train,
        zero_shot=args.zero_shot,
        resolution_px=(args.resolution[0], args.resolution[1]),
        n_resamples=args.n_resamples,
        interpolation_sensitivity=args.interpolation_sensitivity,
        progress=False,
        command="fsdvs-hw " + " ".join(argv),
    )
    assert (got[0].seeds, got[0].resolution_px, got[0].n_networks) == ((0, 1, 2), (20, 10), 2)


def test_information_options(monkeypatch, tmp_path):
    from fsdvs_hw.studies.information import InformationOptions

    got = _capture(monkeypatch, "fsdvs_hw.studies.information.run_information_study")
    argv = ["information", DESIGN, "--out", str(tmp_path), "--networks", "4", "--bins", "5"]
    argv += ["--no-matched-rate", "--rate-thresholds", "0.2", "--no-progress"]
    monkeypatch.setattr(sys, "argv", ["fsdvs-hw", *argv])
    _run(argv)
    opts = got[0]
    assert isinstance(opts, InformationOptions)
    assert (opts.n_networks, opts.n_bins, opts.matched_rate, opts.rate_thresholds) == (4, 5, False, (0.2,))
    assert (opts.out, opts.progress, opts.command) == (tmp_path, False, "fsdvs-hw " + " ".join(argv))


def test_ablation_options(monkeypatch, tmp_path):
    from fsdvs_hw.studies.kernel_size_ablation import AblationOptions

    got = _capture(monkeypatch, "fsdvs_hw.studies.kernel_size_ablation.run_ablation_study")
    argv = ["ablation", "--sizes", "3", "5", "--seeds", "1", "--out", str(tmp_path), "--no-progress"]
    monkeypatch.setattr(sys, "argv", ["fsdvs-hw", *argv])
    _run(argv)
    assert got[0] == dataclasses.replace(
        AblationOptions(),
        sizes=(3, 5),
        seeds=(1,),
        out=tmp_path,
        progress=False,
        command="fsdvs-hw " + " ".join(argv),
    )


def test_simulate_options(monkeypatch, tmp_path):
    got = _capture(monkeypatch, "fsdvs_hw.sensor.eventfiles.video_to_file.simulate_video_to_file")
    out = tmp_path / "e.npz"
    _run(["simulate", "example:carphone", "--out", str(out), "--size", "12x16", "--frames", "3", "--no-progress"])
    opts = got[0]
    assert (opts.out, opts.size, opts.frames, opts.progress) == (out, (12, 16), 3, False)
    assert (opts.preset, opts.kernel, opts.start_frame, opts.input_mapping) == ("default", None, 0, "linear_light")
