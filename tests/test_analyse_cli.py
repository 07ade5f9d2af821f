"""The `fsdvs-hw analyse` command end to end: table, figures, JSON, and clear errors."""

from __future__ import annotations

import json

import pytest

from fsdvs_hw.cli import main


def test_analyse_reference_writes_figures_and_metrics(tmp_path, capsys):
    rc = main(["analyse", "dog:size=7,w_surround=0.8", "--focal-mm", "12", "--out", str(tmp_path)])
    assert rc == 0
    out = capsys.readouterr().out
    assert "mannos_sakrison_1974" in out and "band-pass" in out
    metrics = json.loads((tmp_path / "metrics.json").read_text())
    ms = metrics["csf_agreement"]["mannos_sakrison_1974"]
    assert ms["scale_fitted"] is False and ms["pixels_per_degree"] == pytest.approx(43.09, abs=0.01)
    for name in ("kernel.png", "spectrum.png", "radial_csf.png"):
        data = (tmp_path / name).read_bytes()
        assert data[:8] == b"\x89PNG\r\n\x1a\n" and len(data) > 5000


def test_analyse_file_json_output(tmp_path, capsys):
    from fsdvs_hw.kernels import reference_kernel

    path = reference_kernel("log", 9).save(tmp_path / "log.npy")
    assert main(["analyse", str(path), "--csf", "daly", "--json", "--pitch-um", "3"]) == 0
    d = json.loads(capsys.readouterr().out)
    assert list(d["csf_agreement"]) == ["daly_1993"] and d["kernel"]["pitch_m"] == pytest.approx(3e-6)


@pytest.mark.parametrize(
    "argv, fragment",
    [
        (["analyse", "missing.npy"], "not found"),
        (["analyse", "dog:size=8"], "odd"),
        (["analyse", "dog:sigma=abc"], "must be a number"),
        (["analyse", "spiral"], "neither a kernel file"),
        (["analyse", "dog", "--csf", "nope"], "unknown"),
        (["analyse", "dog", "--focal-mm", "-3"], "--focal-mm"),
    ],
)
def test_analyse_bad_input_is_one_clear_line(argv, fragment, capsys):
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert fragment in err and "Traceback" not in err


def test_help_is_useful(capsys):
    with pytest.raises(SystemExit):
        main(["analyse", "--help"])
    text = capsys.readouterr().out
    assert "--focal-mm" in text and "Example" in text


def test_top_level_help_lists_every_command(capsys):
    """`fsdvs-hw --help` renders (argparse %-formats help strings: a '95 % CI' in a verb's HELP
    once crashed it) and names every verb."""
    from fsdvs_hw.cli import COMMANDS, main

    with pytest.raises(SystemExit) as info:
        main(["--help"])
    assert info.value.code == 0
    out = capsys.readouterr().out
    assert all(name in out for name in COMMANDS)
    assert "95 % CI" in out
