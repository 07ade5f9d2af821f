"""Property-based checks (hypothesis) of the design schema and the public fit functions.

* Every generated bad value of every design key and every fit option is refused with the
  project's :class:`InputError` naming the key (design files) or the argument (Python calls) —
  never another exception — and the fit functions refuse it before any work.
* The design check and the fit functions agree on every value, good or bad.
* Whatever a design names (its name, its kernel path), nothing is written or read outside its
  folder / the output folder.

Examples are bounded (``max_examples``) so the module runs in seconds; the fit functions are only
run up to their validation (a good option is followed by a bad kernel, which stops them).
"""

from __future__ import annotations

import math
import os
from pathlib import Path

import pytest

hypothesis = pytest.importorskip("hypothesis")
from _schema_view import FieldView, view  # noqa: E402
from hypothesis import HealthCheck, given, settings  # noqa: E402
from hypothesis import strategies as st  # noqa: E402

from fsdvs_hw.design import parse_design  # noqa: E402
from fsdvs_hw.design import sections as design_sections  # noqa: E402
from fsdvs_hw.errors import InputError  # noqa: E402
from fsdvs_hw.paths import confined_path, safe_name  # noqa: E402
from fsdvs_hw.realise.registry import REALISATIONS, realisation_names  # noqa: E402

#: hardware realisation → option → its view (kinds, bounds, choices from the model's JSON Schema)
FIT_OPTIONS = {
    n: {k: view(REALISATIONS[n].options, k) for k in REALISATIONS[n].options.model_fields}
    for n in realisation_names("hardware")
}

FAST = settings(
    max_examples=60, deadline=None, suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture]
)

# any JSON/TOML-like value, of every type a design file or a caller could give
ANY = st.one_of(
    st.none(),
    st.booleans(),
    st.integers(-(2**70), 2**70),
    st.floats(),
    st.text(max_size=12),
    st.lists(st.integers(-3, 3), max_size=3),
    st.dictionaries(st.text(max_size=4), st.integers(), max_size=2),
)


def _fit(name):
    return REALISATIONS[name].fit


# ---------------------------------------------------------------------- bad values, built from the schema
def _out_of_range_numbers(lo, hi, lo_open, hi_open, integer):
    """Numbers outside [lo, hi] (respecting open ends), and NaN/±inf for real-valued keys."""
    cands = []
    if lo is not None:
        below = st.floats(
            max_value=lo, exclude_max=not lo_open, allow_nan=False, allow_infinity=False, min_value=lo - 1e6 - abs(lo)
        )
        cands.append(below.map(math.floor).filter(lambda v: v < lo or (lo_open and v <= lo)) if integer else below)
    if hi is not None:
        above = st.floats(
            min_value=hi, exclude_min=not hi_open, allow_nan=False, allow_infinity=False, max_value=hi + 1e6 + abs(hi)
        )
        cands.append(above.map(math.ceil).filter(lambda v: v > hi or (hi_open and v >= hi)) if integer else above)
    if not integer:
        cands.append(st.sampled_from([math.nan, math.inf, -math.inf]))
    return st.one_of(cands) if cands else st.nothing()


def _wrong_types(
    accepts_int, accepts_float, accepts_str, accepts_bool, accepts_none, accepts_list=False, accepts_dict=False
):
    cands = []
    if not accepts_bool:
        cands.append(st.booleans())
    if not accepts_none:
        cands.append(st.none())
    if not accepts_str:
        cands.append(st.text(max_size=8))
    if not (accepts_int or accepts_float):
        cands.append(st.integers(-5, 5))
    if accepts_int and not accepts_float:
        cands.append(st.floats(allow_nan=True).filter(lambda v: not (math.isfinite(v) and v == int(v))))
    if not accepts_float and not accepts_int:
        cands.append(st.floats())
    if not accepts_list:
        cands.append(st.lists(st.integers(), max_size=2))
    if not accepts_dict:
        cands.append(st.dictionaries(st.sampled_from(["a", "b"]), st.integers(), max_size=2))
    return st.one_of(cands)


def _bad_for_option(opt: FieldView, *, in_design: bool):
    k = set(opt.kinds)
    numeric = bool(k & {"int", "float"})
    cands = [
        _wrong_types(
            "int" in k,
            "float" in k,
            "str" in k,
            "bool" in k,
            opt.nullable or in_design,
            accepts_dict="object" in k and not in_design,
            accepts_list="object" in k,
        )
    ]
    if numeric:
        cands.append(_out_of_range_numbers(opt.lo, opt.hi, opt.lo_open, opt.hi_open, "float" not in k))
        if opt.odd:
            cands.append(st.integers(-50, 50).map(lambda v: 2 * v))
    if "str" in k and opt.choices is not None:
        cands.append(st.text(max_size=10).filter(lambda s: s not in opt.choices))
    return st.one_of(cands)


OPTION_KEYS = sorted(
    (r, o) for r, opts in FIT_OPTIONS.items() for o, spec in opts.items() if set(spec.kinds) != {"object"}
)


@st.composite
def bad_fit_option(draw):
    name, key = draw(st.sampled_from(OPTION_KEYS))
    return name, key, draw(_bad_for_option(FIT_OPTIONS[name][key], in_design=False))


@st.composite
def bad_design_option(draw):
    name, key = draw(st.sampled_from(OPTION_KEYS))
    return name, key, draw(_bad_for_option(FIT_OPTIONS[name][key], in_design=True))


def _bad_for_field(f: FieldView):
    types = set(f.kinds)
    cands = []
    accepts_int = "int" in types
    accepts_float = "float" in types
    cands.append(
        _wrong_types(
            accepts_int,
            accepts_float,
            "str" in types,
            "bool" in types,
            True,
            accepts_list="list" in types,
            accepts_dict="dict" in types,
        )
    )
    if accepts_int or accepts_float:
        cands.append(_out_of_range_numbers(f.lo, f.hi, f.lo_open, f.hi_open, not accepts_float))
    if "str" in types and f.choices is not None:
        cands.append(st.text(max_size=10).filter(lambda s: s not in f.choices))
    if f.item is not None:
        if f.length is not None:
            cands.append(st.lists(st.integers(16, 64), min_size=0, max_size=4).filter(lambda v: len(v) != f.length))
        if f.item.choices is not None:
            cands.append(
                st.lists(st.text(max_size=6).filter(lambda s: s not in f.item.choices), min_size=1, max_size=2)
            )
        if f.item.lo is not None:
            cands.append(st.integers(-1000, int(f.item.lo) - 1).map(lambda v: [v] * (f.length or 1)))
    return st.one_of(cands)


#: section → its model (the design file's model, built from the registry)
SECTIONS = {s: info.annotation for s, info in design_sections.design_model().model_fields.items()}
DESIGN_KEYS = sorted(
    (s, k)
    for s, model in SECTIONS.items()
    for k in model.model_fields
    if not (s == "realisations" and k in FIT_OPTIONS)
)


@st.composite
def bad_design_field(draw):
    section, key = draw(st.sampled_from(DESIGN_KEYS))
    return section, key, draw(_bad_for_field(view(SECTIONS[section], key)))


# ---------------------------------------------------------------------- properties
@FAST
@given(case=bad_design_field())
def test_every_bad_design_value_is_an_input_error_naming_its_key(case, tmp_path_factory):
    section, key, value = case
    base = tmp_path_factory.mktemp("d")
    with pytest.raises(InputError) as info:
        parse_design({section: {key: value}}, base_dir=base)
    assert f"{section}.{key}" in str(info.value)
    assert list(base.iterdir()) == []  # validation writes nothing


@FAST
@given(case=bad_design_option())
def test_every_bad_fit_option_in_a_design_is_an_input_error_naming_its_key(case):
    name, key, value = case
    with pytest.raises(InputError) as info:
        parse_design({"realisations": {name: {key: value}}})
    assert f"realisations.{name}.{key}" in str(info.value)


@FAST
@given(case=bad_fit_option())
def test_every_bad_fit_argument_is_an_input_error_naming_it_before_any_work(case, monkeypatch, tmp_path):
    name, key, value = case
    import fsdvs_hw.realise.asic.fit as asic
    import fsdvs_hw.realise.mesh.fit as mesh
    import fsdvs_hw.realise.metalens.fit as metalens
    from fsdvs_hw.kernels import reference_kernel

    def work_started(*a, **k):
        raise AssertionError(f"{name}: work started before {key}={value!r} was refused")

    # the expensive parts of each fit: reaching any of them means validation came too late
    for module, attr in (
        (mesh, "_mesh_solver"),
        (mesh, "_numpy_orbit_response"),
        (asic, "_TapProblem"),
        (metalens, "RadialKernelModel"),
        (metalens, "sampled_spectrum"),
    ):
        monkeypatch.setattr(module, attr, work_started)  # raises if renamed: the guard would watch nothing
    monkeypatch.chdir(tmp_path)
    target = reference_kernel("dog", 5)
    with pytest.raises(InputError) as info:
        _fit(name)(target, **{key: value})
    assert str(info.value).startswith(f"key '{key}' = ")
    assert list(tmp_path.iterdir()) == []


@FAST
@given(name_key=st.sampled_from(OPTION_KEYS), value=ANY)
def test_design_check_and_fit_function_agree_on_every_value(name_key, value):
    """Design accepts a value ⇔ the fit function's own check accepts it, for the design's target."""
    name, key = name_key
    try:
        parse_design({"realisations": {name: {key: value}}})
        design_ok = True
    except InputError as exc:
        assert f"realisations.{name}.{key}" in str(exc)
        design_ok = False
    fit_ok, said = _fit_entry_accepts(name, key, value)
    if isinstance(value, dict):  # a Python object is fine in a call, never in a design file
        assert not design_ok
        return
    assert design_ok == fit_ok, said


class _Validated(Exception):
    pass


def _fit_entry_accepts(name, key, value):
    """Whether the fit function's entry check accepts ``key=value`` for a design file's target (a rule
    may depend on the target kernel), and what it said; the fit is stopped right after that check."""
    import sys

    fit = _fit(name)
    module = sys.modules[fit.__module__]
    entry = module.check_fit_arguments

    def stop_after_the_check(options, arguments):
        entry(options, arguments)
        raise _Validated

    module.check_fit_arguments = stop_after_the_check
    try:
        fit(_DESIGN_TARGET, **{key: value})
    except _Validated:
        return True, "accepted"
    except InputError as exc:
        return not str(exc).startswith(f"key '{key}' = "), str(exc)
    finally:
        module.check_fit_arguments = entry
    raise AssertionError(f"{name}: the fit did not stop at its entry check")


_DESIGN_TARGET = parse_design({}, source="property").target


@FAST
@given(
    taps=st.one_of(
        st.none(),
        st.text(max_size=5),
        st.integers(),
        st.lists(st.lists(st.floats(), min_size=1, max_size=3), min_size=1, max_size=3),
        st.lists(
            st.lists(st.one_of(st.text(max_size=2), st.none(), st.booleans()), min_size=3, max_size=3),
            min_size=3,
            max_size=3,
        ),
    )
)
def test_bad_kernels_are_input_errors_for_every_fit_function(taps):
    import numpy as np

    from fsdvs_hw.kernels import Kernel

    def kernel_ok():
        try:
            Kernel(taps)
            return True
        except InputError:
            return False

    ok = kernel_ok()
    for name in ("mesh", "asic", "metalens"):
        if ok:
            continue  # every fitter takes a valid array kernel (issue 17): it would start a fit
        with pytest.raises(InputError):
            _fit(name)(taps)


# ---------------------------------------------------------------------- nothing outside its folder
NAMES = st.one_of(
    st.text(max_size=40),
    st.lists(st.sampled_from(["..", ".", "/", "a", "\\", "~", "etc", "\x00", " ", "é"]), max_size=8).map("".join),
)


@settings(max_examples=300, deadline=None)
@given(name=NAMES)
def test_a_sanitised_name_never_leaves_its_folder(name, tmp_path_factory):
    base = tmp_path_factory.getbasetemp() / "stores"
    slug = safe_name(name)
    assert slug and slug not in (".", "..") and "/" not in slug and "\\" not in slug and "\x00" not in slug
    assert (base / f"{slug}.sqlite").resolve().parent == base.resolve()
    if name != slug:
        assert safe_name(name + "x") != slug  # different names never share a file


@settings(max_examples=200, deadline=None)
@given(rel=NAMES)
def test_a_confined_path_is_inside_its_folder_or_refused(rel, tmp_path_factory):
    base = tmp_path_factory.getbasetemp() / "designs"
    base.mkdir(exist_ok=True)
    try:
        p = confined_path(base, rel, what="kernel.path")
    except InputError as exc:
        assert "kernel.path" in str(exc)
        return
    assert p == base.resolve() or base.resolve() in p.parents


@settings(max_examples=8, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(name=NAMES.filter(lambda s: "\x00" not in s))
def test_a_sweep_run_writes_only_inside_its_output_folder(name, tmp_path_factory, capsys):
    import tomllib

    from fsdvs_hw.cli import main

    root = tmp_path_factory.mktemp("run")
    work = root / "work"
    work.mkdir()
    toml_name = '"' + name.replace("\\", "\\\\").replace('"', '\\"') + '"'
    text = (
        f'[design]\nname = {toml_name}\n[realisations]\ninclude = ["delta"]\n[analysis]\n'
        'csf_methods = ["mannos_sakrison_1974"]\n[emulation]\nenabled = false\n'
    )
    try:
        tomllib.loads(text)
    except tomllib.TOMLDecodeError:
        return  # control characters TOML cannot hold
    (work / "d.toml").write_text(text)
    cwd = os.getcwd()
    os.chdir(work)
    try:
        code = main(["sweep", "d.toml", "--no-progress"])
    finally:
        os.chdir(cwd)
    capsys.readouterr()
    assert code == 0
    written = [p.relative_to(root) for p in root.rglob("*") if p.is_file()]
    assert all(p == Path("work/d.toml") or p.parts[:3] == ("work", "out", "sweeps") for p in written), written


@settings(max_examples=60, deadline=None)
@given(
    on=st.floats(1e-4, 10.0),
    off=st.floats(1e-4, 10.0),
    sigma=st.floats(0.0, 1.0),
    placement=st.sampled_from(design_sections._PLACEMENTS),
    positivity=st.sampled_from(design_sections._POSITIVITY),
    seed=st.integers(0, 2**31 - 1),
)
def test_every_sensor_section_a_design_accepts_builds_a_simulator_config(on, off, sigma, placement, positivity, seed):
    """No design-valid [sensor] value may fail only later, inside a worker, when the simulator starts."""
    from fsdvs_hw.explore.emulation import _sensor_config

    d = parse_design(
        {
            "sensor": {
                "threshold_on": on,
                "threshold_off": off,
                "threshold_sigma": sigma,
                "placement": placement,
                "positivity": positivity,
            },
            "run": {"seed": seed},
        }
    )
    cfg = _sensor_config(d.data["sensor"], d.data["run"]["seed"], 25.0)
    assert cfg.threshold_on == on and cfg.positivity == positivity


@settings(max_examples=80, deadline=None)
@given(
    bits=st.integers(1, 16),
    gamma=st.floats(1.0, 4.0),
    peak=st.floats(1.0, 1e4),
    black=st.floats(0.0, 100.0),
    up=st.integers(1, 64),
    enabled=st.booleans(),
)
def test_an_emulation_section_is_accepted_only_if_its_display_can_be_built(bits, gamma, peak, black, up, enabled):
    """The design check and the emulation's DisplaySettings agree (black < peak is checked at load)."""
    from fsdvs_hw.design.display_settings import DisplaySettings

    section = {
        "enabled": enabled,
        "display_bits": bits,
        "display_gamma": gamma,
        "display_peak_nits": peak,
        "display_black_nits": black,
        "upsample_factor": up,
    }
    try:
        DisplaySettings.from_design(section)
        display_ok = True
    except InputError:
        display_ok = False
    try:
        parse_design({"emulation": section})
        design_ok = True
    except InputError as exc:
        assert "emulation." in str(exc)
        design_ok = False
    assert design_ok == (display_ok or not enabled)
