"""The mesh fit's options model and the fit's own checks accept the same values.

``MeshOptions`` (what a design file is checked against when it is loaded) and the fit's first step
(``check_fit_arguments``, which every call runs before any work) must refuse the same values, or a design
is accepted and fails after work has started (it did: ``tol = 0.1`` passed the loader, the fit
refused anything above 1e-2). For every numeric option with a range, values at each bound and just
beyond it are put to both; the options whose range depends on others or on the target
(``g_lateral_s`` within ``bounds.conductance_s``, ``fit_size`` at least the kernel's size,
``grid_half_width`` at least its radius) are left out here: the realisation contract test puts
every option of every realisation to a design file and to the fit.
"""

from __future__ import annotations

import math

import pytest
from _schema_view import view
from pydantic import ValidationError

from fsdvs_hw.design import DesignError, parse_design
from fsdvs_hw.errors import InputError
from fsdvs_hw.kernels import reference_kernel
from fsdvs_hw.realise.mesh.options import MeshOptions
from fsdvs_hw.validation import check_fit_arguments

CONTEXT = {"g_lateral_s", "fit_size", "grid_half_width", "pitch_m", "bounds"}
DEFAULTS = {name: f.default for name, f in MeshOptions.model_fields.items() if name != "pitch_m"}


def _range(name: str) -> tuple[float, float]:
    """The option's declared bounds (its JSON Schema, as the contract test reads them; ±inf: none)."""
    opt = view(MeshOptions, name)
    return (-math.inf if opt.lo is None else float(opt.lo), math.inf if opt.hi is None else float(opt.hi))


def _numeric() -> list[str]:
    """Options that are one number (not a number or a word) with an upper bound."""
    return [
        n
        for n in MeshOptions.model_fields
        if n not in CONTEXT and view(MeshOptions, n).kinds in ({"int"}, {"float"}) and math.isfinite(_range(n)[1])
    ]


def _model_accepts(name: str, value: float) -> bool:
    try:
        MeshOptions.model_validate({name: value})
    except ValidationError:
        return False
    return True


def _fit_accepts(name: str, value: float) -> bool:
    try:
        check_fit_arguments(
            MeshOptions, {**DEFAULTS, "pitch_m": None, name: value, "kernel": reference_kernel("dog", 7)}
        )
    except InputError:
        return False
    return True


@pytest.mark.parametrize("name", _numeric())
def test_the_options_model_and_the_fit_accept_the_same_range(name):
    lo, hi = _range(name)
    integer = view(MeshOptions, name).kinds == {"int"}
    probes = [lo, hi, lo - 1 if integer else lo - max(abs(lo), 1e-300) * 1e-6, hi + 1 if integer else hi * (1 + 1e-6)]
    for v in probes:
        v = int(v) if integer else v
        assert _model_accepts(name, v) == _fit_accepts(name, v), (name, v)


def test_the_numeric_options_are_probed():
    assert {"tol", "max_iter", "n_init", "mismatch_sigma", "node_capacitance_f"} <= set(_numeric())
    assert _range("mismatch_sigma") == (0.0, 0.5) and _range("tol") == (1e-16, 1e-2)


def test_the_public_gain_modes_are_the_options_choices():
    from fsdvs_hw.realise.mesh import GAIN_MODES

    assert view(MeshOptions, "gain").choices == GAIN_MODES


def test_a_tolerance_the_fit_refuses_is_refused_when_the_design_is_loaded():
    with pytest.raises(DesignError, match=r"realisations\.mesh\.tol.*0\.1"):
        parse_design({"realisations": {"include": ["learned", "mesh"], "mesh": {"tol": 0.1}}})
    assert parse_design({"realisations": {"include": ["mesh"], "mesh": {"tol": 1e-2}}}).spec is not None
