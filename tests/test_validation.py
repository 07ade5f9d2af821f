"""One validation layer: design files and fit functions refuse the same bad options, before any work;
kernels refuse values that would silently turn into something else."""

from __future__ import annotations

import dataclasses
import importlib
import math
from pathlib import Path

import numpy as np
import pytest

from fsdvs_hw.design import DesignError, parse_design
from fsdvs_hw.errors import InputError, KernelError
from fsdvs_hw.kernels import Kernel, load_kernel, reference_kernel
from fsdvs_hw.schema import field_schema, members

# (realisation, option, bad value): the examples and NaN sizes
BAD_OPTIONS = [
    ("asic", "bits", 1),
    ("asic", "bits", 32),
    ("asic", "bits", 7.5),
    ("asic", "bits", True),
    ("mesh", "tol", -1.0),
    ("mesh", "tol", 0.0),
    ("mesh", "fit_size", 4),
    ("mesh", "n_init", math.nan),
    ("mesh", "mismatch_sigma", math.inf),
    ("mesh", "model", "magic"),
    ("metalens", "strategy", "magic"),
    ("metalens", "aperture_m", math.nan),
    ("metalens", "pitch_m", math.nan),
    ("metalens", "n_sub", math.nan),
    ("metalens", "window_pad", 0.0),
    ("metalens", "na_max", 1.0),
    ("metalens", "n_wavelengths", "many"),
    ("asic", "scale", -1.0),
    ("asic", "adder_weight", math.nan),
]


FIT_FUNCTIONS = {
    "mesh": "fsdvs_hw.realise.mesh:fit_resistive_mesh",
    "asic": "fsdvs_hw.realise.asic:fit_asic_taps",
    "metalens": "fsdvs_hw.realise.metalens:fit_metalens",
}


def _fit_function(name):
    module, func = FIT_FUNCTIONS[name].split(":")
    return getattr(importlib.import_module(module), func)


def _options(name):
    from fsdvs_hw.realise.registry import get_realisation

    return get_realisation(name).options


@pytest.mark.parametrize("name,key,value", BAD_OPTIONS, ids=lambda v: str(v))
def test_design_file_refuses_a_bad_fit_option_naming_key_value_and_range(name, key, value):
    with pytest.raises(DesignError) as info:
        parse_design({"realisations": {name: {key: value}}})
    msg = str(info.value)
    assert f"realisations.{name}.{key}" in msg and "allowed" in msg


@pytest.mark.parametrize("name,key,value", BAD_OPTIONS, ids=lambda v: str(v))
def test_fit_function_refuses_the_same_value_before_any_work(name, key, value):
    fit = _fit_function(name)
    with pytest.raises(InputError) as info:
        fit(reference_kernel("dog", 5), **{key: value})
    assert key in str(info.value)
    # refused up front, not after a fit: the fit function's next frame is the schema check
    names = [(Path(str(e.path)).name, e.name) for e in info.traceback]
    at = names.index((Path(fit.__code__.co_filename).name, fit.__name__))
    assert names[at + 1] == ("validation.py", "check_fit_arguments")


@pytest.mark.parametrize("name", sorted(FIT_FUNCTIONS))
def test_the_registry_holds_the_public_fit_functions(name):
    from fsdvs_hw.realise.registry import get_realisation

    assert get_realisation(name).fit is _fit_function(name)


def test_good_options_pass_and_are_normalised():
    from fsdvs_hw.realise.registry import get_realisation

    assert get_realisation("asic").check_option("bits", np.int64(4)) == 4
    sigma = get_realisation("mesh").check_option("mismatch_sigma", 0)  # an int in range (tol: [1e-16, 1e-2], 9b1db6b)
    assert sigma == 0.0 and isinstance(sigma, float)
    d = parse_design({"realisations": {"asic": {"bits": 4}, "mesh": {"pixel_weight": "free"}}})
    assert d.realisation_options("asic") == {"bits": 4}


def test_asic_bit_limits_match_the_arithmetic_module():
    from fsdvs_hw.realise.asic.arith import MAX_TAP_BITS

    bits = field_schema(_options("asic"), "bits")
    assert bits["maximum"] == MAX_TAP_BITS
    assert bits["minimum"] == 2


def test_fit_metalens_does_not_ignore_a_nan_pitch():
    from fsdvs_hw.realise.metalens import fit_metalens

    with pytest.raises(InputError, match="pitch_m"):
        fit_metalens(reference_kernel("dog", 3), pitch_m=float("nan"), max_iter=1, n_starts=1, n_wavelengths=1)


# ---------------------------------------------------------------------- kernels: nothing silently wrong
@pytest.mark.parametrize(
    "taps",
    [
        np.array([["2020-01-01"]], dtype="datetime64[D]"),
        np.array([[1]], dtype="timedelta64[s]"),
        [["1"]],
        [[1, None, 1], [1, 1, 1], [1, 1, 1]],
    ],
    ids=["datetime", "timedelta", "strings", "object"],
)
def test_non_numeric_taps_are_refused(taps):
    with pytest.raises(KernelError, match="numeric"):
        Kernel(taps)


@pytest.mark.parametrize("peak", [1e300, 1e16, 1e-300, 1e-16])
def test_taps_that_overflow_or_vanish_in_float32_are_refused_where_float32_or_hardware_starts(peak, tmp_path):
    torch = pytest.importorskip("torch")
    from fsdvs_hw.sensor.simulation.events import event_frames

    k = Kernel(np.full((3, 3), peak))  # a float64 kernel; its (scale-invariant) analysis is fine
    for name in ("mesh", "asic", "metalens"):
        with pytest.raises(KernelError, match="largest"):
            _fit_function(name)(k)
    with pytest.raises(KernelError, match="largest"):
        _fit_function("mesh")(np.full((3, 3), peak))  # taps given as an array
    with pytest.raises(KernelError, match="largest"):
        event_frames(torch.ones(1, 2, 8, 8), k)
    with pytest.raises(KernelError, match="largest"):
        event_frames(torch.ones(1, 2, 8, 8), torch.full((3, 3), peak, dtype=torch.float64))
    k.save(tmp_path / "k.json")
    (tmp_path / "d.toml").write_text('[kernel]\nsource = "file"\npath = "k.json"\n')
    from fsdvs_hw.design import load_design

    with pytest.raises(DesignError, match=r"kernel\.path.*largest"):
        load_design(tmp_path / "d.toml")


def test_extreme_but_allowed_taps_stay_finite_in_float32():
    k = Kernel(np.full((3, 3), 1e15))
    t = k.taps.astype(np.float32)
    assert np.isfinite(t).all() and np.isfinite((t.astype(np.float32) ** 2).sum())


def test_complex_pt_kernel_is_refused_not_truncated(tmp_path):
    torch = pytest.importorskip("torch")
    k = torch.zeros(3, 3, dtype=torch.complex64)
    k[1, 1] = 1 + 1j
    torch.save(k, tmp_path / "c.pt")
    with pytest.raises(KernelError, match="complex"):
        load_kernel(tmp_path / "c.pt")


@pytest.mark.parametrize(
    "suffix,content",
    [
        (".npy", b""),
        (".npy", b"garbage"),
        (".npy", b"\x93NUMPY\x01\x00"),
        (".pt", b""),
        (".pt", b"garbage"),
        (".pt", b"PK\x03\x04broken zip"),
        (".json", b"\xff\xfe{"),
        (".json", b"{"),
        (".json", b"[" * 100000),
        (".json", b'{"taps": [[1, 2], [3]]}'),
        (".csv", b"\xff\xfe1"),
        (".csv", b""),
        (".csv", b"1,2\n3\n"),
        (".csv", b"# fsdvs_hw [1]\n1\n"),
    ],
)
def test_malformed_kernel_files_give_one_kernel_error_naming_the_file(tmp_path, suffix, content):
    p = tmp_path / f"bad{suffix}"
    p.write_bytes(content)
    with pytest.raises(KernelError) as info:
        load_kernel(p)
    assert str(p) in str(info.value)


def test_kernel_file_errors_never_echo_the_files_content(tmp_path):
    p = tmp_path / "s.csv"
    p.write_text("1,TOPSECRET,3\n")
    with pytest.raises(KernelError) as info:
        load_kernel(p)
    assert "TOPSECRET" not in str(info.value) and "line 1, column 2" in str(info.value)


# ---------------------------------------------------------------------- half precision in the simulator
def test_float16_video_counts_do_not_overflow_to_inf():
    torch = pytest.importorskip("torch")
    from fsdvs_hw.sensor import SensorConfig
    from fsdvs_hw.sensor.simulation.events import event_frames

    v = torch.full((1, 2, 8, 8), 1e-3, dtype=torch.float16)
    v[:, 1] = 1000.0
    cfg = dataclasses.replace(SensorConfig.ideal(), threshold_on=1e-4, threshold_off=1e-4)
    f16 = event_frames(v, None, config=cfg)
    f32 = event_frames(v.float(), None, config=cfg)
    assert torch.isfinite(f16).all()
    assert float(f32.max()) > 65504  # more events than float16 can count
    torch.testing.assert_close(f16, f32)


def test_float16_frames_with_an_fft_sized_kernel_work():
    torch = pytest.importorskip("torch")
    from fsdvs_hw.sensor.simulation.events import event_frames

    g = torch.Generator().manual_seed(0)
    v = torch.rand(1, 3, 64, 64, generator=g) + 0.1
    out16 = event_frames(v.half(), reference_kernel("dog", 5))
    out32 = event_frames(v.half().float(), reference_kernel("dog", 5))
    torch.testing.assert_close(out16, out32)


@pytest.mark.parametrize("peak", [1e15, 1.0001e-15])
def test_fits_at_the_tap_range_extremes_report_finite_errors(peak):
    """On main, 1e200 taps gave a mesh design with error NaN and 1e-300 taps a LinAlgError; such
    kernels are now refused, and at the allowed extremes every fitter's error stays finite."""
    import warnings

    from fsdvs_hw.realise.asic import fit_asic_taps
    from fsdvs_hw.realise.mesh import fit_resistive_mesh

    k = reference_kernel("dog", 5)
    t = k.scaled(peak / np.abs(k.taps).max())
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        mesh = fit_resistive_mesh(t, max_iter=10, n_init=3)
    assert math.isfinite(mesh.fit["error"])
    assert all(math.isfinite(v) for v in mesh.fit.values() if isinstance(v, float))
    asic = fit_asic_taps(t, 4)
    assert np.isfinite(asic.kernel().taps).all()


def test_choices_in_the_table_are_the_fit_modules_own_registries():
    from fsdvs_hw.csf import CSF_METHODS
    from fsdvs_hw.realise.asic import OBJECTIVES, SCALE_MODES
    from fsdvs_hw.realise.asic.arith import SYMMETRIES
    from fsdvs_hw.realise.mesh import MESH_MODELS
    from fsdvs_hw.realise.metalens import DISPERSION_MODELS, STRATEGIES

    def choices(name, key):  # the allowed words in the model's JSON Schema
        return tuple(c for m in members(field_schema(_options(name), key)) for c in m.get("enum", ()))

    assert choices("asic", "csf_method") == tuple(CSF_METHODS)
    assert choices("asic", "objective") == tuple(OBJECTIVES)
    assert choices("asic", "scale") == tuple(SCALE_MODES)
    assert set(choices("asic", "symmetry")) == {"auto", *SYMMETRIES}
    assert choices("mesh", "model") == tuple(MESH_MODELS)
    assert choices("metalens", "strategy") == tuple(STRATEGIES)
    assert choices("metalens", "dispersion") == tuple(DISPERSION_MODELS)
