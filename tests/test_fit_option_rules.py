"""The rules of the fits' options models read the same from a design file and from a Python call.

Each realisation's options model (``fsdvs_hw/realise/<name>/options.py``) holds, besides every
option's range, the rules between options and the rules on the target kernel
(:mod:`fsdvs_hw.realise.fit_options`). A design file's ``[realisations.<name>]`` table and the fit
function's arguments are put to the same rules, so a broken rule is refused by both, before any
work, in the same words (the design file's line names the option under ``realisations.<name>.``).
"""

from __future__ import annotations

import numpy as np
import pytest

from fsdvs_hw.design import DesignError, parse_design
from fsdvs_hw.errors import InputError
from fsdvs_hw.kernels import Kernel
from fsdvs_hw.realise.registry import get_realisation

#: (realisation, options, the option the problem is reported on) — the design file's target is 7x7
BROKEN_RULES = [
    ("mesh", {"pixel_weight": 0.0}, "pixel_weight"),
    ("mesh", {"pixel_weight": 0.0, "gain": "fixed"}, None),
    ("mesh", {"fit_size": 5}, "fit_size"),
    ("mesh", {"model": "grid"}, "grid_half_width"),
    ("mesh", {"model": "grid", "grid_half_width": 2}, "grid_half_width"),
    ("mesh", {"model": "grid", "grid_half_width": 3}, None),
    ("mesh", {"g_lateral_s": 1e-5, "bounds": {"conductance_s": [1e-9, 2e-9]}}, "g_lateral_s"),
    ("mesh", {"g_lateral_s": 1e-9, "bounds": {"conductance_s": [9e-10, 1.1e-9]}}, "bounds"),
    ("asic", {"objective": "csf", "geometry": [1, 2]}, "geometry"),
    ("metalens", {"aperture_m": 1e-6}, "aperture_m"),
    ("metalens", {"focal_length_m": 2e-7}, "focal_length_m"),  # and the focusing NA (about 1)
    ("metalens", {"na_max": 0.01}, "na_max"),
]


def _design_problems(name, options):
    try:
        parse_design({"realisations": {"include": [name], name: options}}, source="rules")
    except DesignError as exc:
        return [line.strip() for line in str(exc).splitlines()[1:]]
    return []


def _fit_problems(name, options, target, *, run_the_fit):
    """The fit function's own refusal (``run_the_fit``), or for options it accepts, its entry check."""
    from fsdvs_hw.validation import check_fit_arguments

    spec = get_realisation(name)
    try:
        if run_the_fit:
            spec.fit(target, **options)
        else:
            check_fit_arguments(spec.options, {**options, "kernel": target})
    except InputError as exc:
        lines = str(exc).splitlines()
        return [line.strip() for line in (lines[1:] if len(lines) > 1 else lines)]
    return []


@pytest.mark.parametrize("name, options, key", BROKEN_RULES, ids=lambda v: str(v))
def test_a_broken_rule_is_refused_by_the_design_file_and_the_fit_in_the_same_words(name, options, key):
    target = parse_design({}, source="rules").target
    design = _design_problems(name, options)
    fit = _fit_problems(name, options, target, run_the_fit=key is not None)
    if key is None:
        assert design == [] and fit == []
        return
    assert any(line.startswith(f"key 'realisations.{name}.{key}' = ") for line in design), design
    assert [line.replace(f"'realisations.{name}.", "'", 1) for line in design] == fit


def test_the_fit_function_refuses_a_broken_rule_before_any_work():
    from fsdvs_hw import fit_asic_taps, fit_metalens, fit_resistive_mesh

    dog = parse_design({}, source="rules").target
    with pytest.raises(InputError, match=r"^key 'fit_size' = 5: must be None \(whole response\) or odd in 7\.\.63"):
        fit_resistive_mesh(dog, fit_size=5)
    with pytest.raises(InputError, match=r"^key 'pixel_weight' = 0\.0: with gain='free' the pixel path"):
        fit_resistive_mesh(dog, pixel_weight=0.0)
    odd = Kernel(np.array([[0.0, 1.0, 0.0], [-1.0, 0.0, 1.0], [0.0, -1.0, 0.0]]), name="odd")
    with pytest.raises(InputError, match=r"^key 'symmetry' = \"8-fold\": the 8-fold-symmetric part of kernel 'odd'"):
        fit_asic_taps(odd, symmetry="8-fold")
    positive = Kernel(np.full((3, 3), 1.0 / 9), name="box")
    with pytest.raises(InputError, match=r"^key 'strategy' = \"differential\": .* needs a kernel with negative taps"):
        fit_metalens(positive, strategy="differential", n_wavelengths=1)
