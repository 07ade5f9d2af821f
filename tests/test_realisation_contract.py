"""The wiring contract every registered realisation keeps, and a fourth realisation from one file.

Parametrised over every realisation in the registry plus the test plugin
``tests/plugins/toy_realisation.py`` (a box filter registered from outside the package): the
fitted kernel is an odd square on the target's pitch, every cost item has a unit and the declared
ones keep theirs, the JSON record rebuilds the realisation, every declared option reaches the fit
function from a design file and from Python, and a score carries every field the store, the tables
and the report read. Then ``explore`` runs end to end on a design that includes the plugin.

What each test catches (the issue's wiring mutations): a cost unit changed in ``cost()`` or in the
declaration (units test); an option dropped or renamed between the design loader, the scorer and the
fit function (options tests); a record field lost in ``to_dict``/``from_dict`` (round trip); a
score or table field renamed or swapped (score fields test); a per-realisation list left somewhere
outside the registry (the plugin end-to-end test fails with "unknown realisation" or a missing cost
axis).
"""

from __future__ import annotations

import csv
import dataclasses
import importlib
import inspect
import json
import math
import re
import sys
from pathlib import Path

import numpy as np
import pytest
from _schema_view import view

from fsdvs_hw.kernels import Kernel, reference_kernel
from fsdvs_hw.realise import registry
from fsdvs_hw.realise.registry import (
    COST_UNITS,
    get_realisation,
    realisation_from_dict,
    realisation_names,
    register_realisation,
    unregister_realisation,
)
from fsdvs_hw.records import Score, ScoredPoint

PLUGINS = Path(__file__).resolve().parent / "plugins"
NAMES = [*realisation_names(), "box"]
PITCH_M = 3.0e-6  # not the default pitch: a realisation must carry the target's own

#: Small settings so that each fit takes a second or less (any realisation not listed: its defaults).
CHEAP = {
    "mesh": {"n_init": 4, "n_starts": 1, "max_iter": 40},
    "asic": {"bits": 6},
    "metalens": {"n_wavelengths": 1, "n_starts": 1, "max_iter": 5, "n_terms": 1},
    "metalens_layout": {"n_wavelengths": 1, "n_starts": 1, "max_iter": 5, "n_terms": 1, "drc": False},
    "box": {"width": 3},
    "mesh_process": {"corners": ["tt"], "temperatures_c": [27.0], "mismatch_samples": 0},  # two ngspice runs
}

#: Non-default values of options a generic rule cannot make up (structured tables; a range that
#: depends on the target: the fit window holds the 7x7 target of a design file).
SAMPLES = {
    ("mesh", "bounds"): {"lambda_px": [0.2, 15.0]},
    ("mesh", "fit_size"): 9,
    ("metalens", "illuminant"): 600e-9,  # one visible wavelength: the default lens's NA stays below 1
    ("metalens_layout", "illuminant"): 600e-9,
    ("metalens_layout", "period_m"): 310e-9,  # below λ_min / n(substrate): no diffraction into the glass
    ("metalens_layout", "max_radius_m"): 120e-9,
    ("metalens_layout", "check_orders"): 4,
    ("metalens_layout", "min_width_m"): 60e-9,
    ("metalens_layout", "min_space_m"): 30e-9,
}

#: Options a design must set with a sample so that the fit's rules between options accept it.
COMPANIONS = {("mesh", "model"): {"grid_half_width": 5}}


@pytest.fixture(scope="module", autouse=True)
def toy_plugin():
    """Import the plugin file (it registers ``box``); unregister it afterwards."""
    sys.path.insert(0, str(PLUGINS))
    try:
        module = importlib.import_module("toy_realisation")
        register_realisation(module.SPEC, replace=True)  # again, if an earlier module run unregistered it
        yield module
    finally:
        unregister_realisation("box")
        sys.path.remove(str(PLUGINS))


@pytest.fixture(scope="module")
def target():
    return reference_kernel("dog", 5, pitch_m=PITCH_M)


_FITTED: dict[str, object] = {}


def _fitted(name, target):
    if name not in _FITTED:
        _FITTED[name] = registry.fit_realisation(name, target, CHEAP.get(name, {}))
    return _FITTED[name]


def _views(spec):
    """Option → its :class:`FieldView` (kinds, bounds, choices from the model's JSON Schema)."""
    return {key: view(spec.options, key) for key in spec.options.model_fields}


def _non_default(opt, default):
    """A valid value different from the default (None when no generic rule finds one)."""
    kinds = set(opt.kinds)
    cands: list = []
    if "bool" in kinds:
        cands.append(not default)
    if "str" in kinds and opt.choices:
        cands += [c for c in opt.choices if c != default]
    if kinds & {"int", "float"}:
        lo, hi = opt.lo, opt.hi
        nums = []
        if isinstance(default, (int, float)) and not isinstance(default, bool):
            nums += [default + 2, default + 1, default * 2, default / 2, default - 1]
        if lo is not None and hi is not None:
            nums += [lo + (hi - lo) / 3, lo + 1, hi - 1]
        if lo is not None:
            nums += [lo + 1, lo * 2 if lo > 0 else lo + 0.5]
        nums += [1, 3, 0.5]
        for v in nums:
            if "float" not in kinds:
                if float(v) != int(v):
                    continue
                v = int(v)
            cands.append(v)
    for v in cands:
        if v != default and opt.ok(v):
            return v
    return None


def _option_values(name):
    spec = get_realisation(name)
    for key, opt in _views(spec).items():
        value = SAMPLES.get((name, key), _non_default(opt, opt.default))
        if value is not None:
            yield key, value


class _Landed(Exception):
    pass


def _spy(calls):
    def fit(target, **options):
        calls.append(options)
        raise _Landed("options recorded")

    return fit


# --------------------------------------------------------------------------------- the contract
@pytest.mark.parametrize("name", NAMES)
def test_spec_is_complete_and_the_fit_signature_matches_the_schema(name):
    spec = get_realisation(name)
    params = list(inspect.signature(spec.fit).parameters.values())
    declared = {p.name: p.default for p in params[1:]}
    assert set(declared) == set(spec.options.model_fields), "fit signature and option schema differ"
    for key, default in declared.items():
        opt = view(spec.options, key)
        assert opt.default == default, key
        assert opt.ok(default), f"{key}: the default itself is refused"
        assert opt.doc, f"{key}: no help text"
        if set(opt.kinds) & {"int", "float"} and opt.unit not in ("", "m", "S", "F", "px", "bit", "s", "V"):
            pytest.fail(f"{key}: unit {opt.unit!r} is not one the package uses")
    if spec.kind == "hardware":
        assert any(c.pareto for c in spec.costs), "a hardware realisation needs a Pareto cost axis"
        assert any(c.headline for c in spec.costs), "a hardware realisation needs a headline cost"
        assert spec.colour
    else:
        assert not spec.costs and not spec.options.model_fields


@pytest.mark.parametrize("name", NAMES)
def test_kernel_is_an_odd_square_on_the_targets_pitch(name, target):
    real = _fitted(name, target)
    k = real.kernel()
    assert isinstance(k, Kernel)
    assert k.taps.ndim == 2 and k.taps.shape[0] == k.taps.shape[1] and k.taps.shape[0] % 2 == 1
    assert k.pitch_m == pytest.approx(PITCH_M, rel=1e-12)
    assert np.isfinite(k.taps).all()
    assert real.kind == get_realisation(name).record_kind


@pytest.mark.parametrize("name", NAMES)
def test_cost_items_carry_units_and_keep_the_declared_ones(name, target):
    spec = get_realisation(name)
    cost = _fitted(name, target).cost()
    for item, c in cost.items():
        assert c.unit in COST_UNITS, f"{item}: unit {c.unit!r}"
        assert isinstance(c.value, (int, float, np.number)), item
    stored = {k: v.to_dict() for k, v in cost.items()}
    for c in spec.costs:
        if c.derive is not None:
            assert c.value(stored) is not None and math.isfinite(c.value(stored)), c.name
        elif not c.optional:
            assert c.name in cost, f"declared cost item {c.name} missing"
            assert cost[c.name].unit == c.unit, f"{c.name}: declared {c.unit!r}, cost() says {cost[c.name].unit!r}"
    if spec.kind == "hardware":
        label, value, unit = spec.cost_axis(stored)
        assert math.isfinite(value) and value > 0 and unit
    else:
        assert cost == {}


@pytest.mark.parametrize("name", NAMES)
def test_json_round_trip_rebuilds_the_same_realisation(name, target):
    real = _fitted(name, target)
    back = realisation_from_dict(json.loads(json.dumps(real.to_dict())))
    assert type(back) is type(real) and back.kind == real.kind
    np.testing.assert_allclose(back.kernel().taps, real.kernel().taps, rtol=1e-12, atol=0)
    assert back.kernel().pitch_m == real.kernel().pitch_m
    assert {k: v.unit for k, v in back.cost().items()} == {k: v.unit for k, v in real.cost().items()}
    for k, v in real.cost().items():
        assert float(back.cost()[k].value) == pytest.approx(float(v.value), rel=1e-9, nan_ok=True), k


@pytest.mark.parametrize("name", NAMES)
def test_every_option_reaches_the_fit_function_from_a_design_file(name, monkeypatch):
    from fsdvs_hw.design import parse_design
    from fsdvs_hw.explore.sweep import evaluate_point, expand_points

    spec = get_realisation(name)
    calls: list[dict] = []
    monkeypatch.setitem(registry._REGISTRY, name, dataclasses.replace(spec, fit=_spy(calls)))
    tried = 0
    for key, value in _option_values(name):
        if view(spec.options, key).kinds == {"object"} and not view(spec.options, key).table:
            continue  # a Python object: cannot come from a design file (the next test passes it)
        table = {key: value, **COMPANIONS.get((name, key), {})}
        d = parse_design({"realisations": {"include": [name], name: table}}, source="contract")
        [point] = expand_points(d)
        res = evaluate_point(point)
        assert res["status"] == "error" and "options recorded" in res["result"]["reason"], res
        assert calls[-1][key] == value, f"{name}.{key}: set {value!r}, the fit got {calls[-1].get(key)!r}"
        tried += 1
    assert tried >= min(1, len(spec.options.model_fields))


@pytest.mark.parametrize("name", NAMES)
def test_every_option_reaches_the_fit_function_from_python(name, target, monkeypatch):
    from fsdvs_hw.explore.scoring import fit_realisation

    spec = get_realisation(name)
    calls: list[dict] = []
    monkeypatch.setitem(registry._REGISTRY, name, dataclasses.replace(spec, fit=_spy(calls)))
    for key, opt in _views(spec).items():
        value = object() if opt.kinds == {"object"} else SAMPLES.get((name, key), _non_default(opt, opt.default))
        if value is None:
            continue
        with pytest.raises(_Landed):
            fit_realisation(name, target, {key: value})
        assert calls[-1][key] is value or calls[-1][key] == value, key
        if "pitch_m" in spec.options.model_fields and key != "pitch_m":
            assert calls[-1]["pitch_m"] == PITCH_M  # the target's pitch is passed unless set


@pytest.mark.parametrize("name", NAMES)
def test_a_score_carries_every_field_the_tables_read(name, target):
    from fsdvs_hw.explore.scoring import score
    from fsdvs_hw.report.tables import score_rows

    spec = get_realisation(name)
    real = _fitted(name, target)
    typed = score(real, target=target, csf_methods=("mannos_sakrison_1974",), fit_wall_s=0.5)
    rec = typed.to_dict()
    # one serialisation: the record rebuilt from its dict writes the same dict
    assert Score.from_dict(json.loads(json.dumps(rec))).to_dict() == rec
    assert typed.wall.fit_s == 0.5 and typed.cost.to_dict() == rec["cost"]
    for key in (
        "kind",
        "label",
        "describe",
        "kernel",
        "kernel_error",
        "kernel_error_gain_free",
        "dc_gain",
        "spectral",
        "csf",
        "cost",
        "tasks",
        "emulation",
        "wall_s",
    ):
        assert key in rec, key
    assert set(rec["wall_s"]) == {"fit", "analysis", "tasks", "emulation"} and rec["wall_s"]["fit"] == 0.5
    assert rec["kind"] == spec.record_kind
    assert all(set(c) >= {"value", "unit"} and c["unit"] in COST_UNITS for c in rec["cost"].values())
    assert Kernel.from_dict(rec["kernel"]).pitch_m == pytest.approx(PITCH_M)
    [row] = score_rows([ScoredPoint("k", name, {}, "ok", score=Score.from_dict(rec))])
    assert row["kernel_error"] == pytest.approx(rec["kernel_error"])
    assert row["csf_agreement"] == pytest.approx(rec["csf"]["mannos_sakrison_1974"]["correlation"])
    assert row["fit_s"] == 0.5
    for item, c in rec["cost"].items():
        assert row[f"cost_{item}"] == pytest.approx(c["value"], nan_ok=True)
    if spec.kind == "hardware":
        label, value, unit = spec.cost_axis(rec["cost"])
        assert (row["kind_cost"], row["kind_cost_unit"]) == (label, unit)
        assert row["kind_cost_value"] == pytest.approx(value)
        assert row["headline_cost"] == spec.headline(rec["cost"])
        assert row["headline_cost_unit"] == rec["cost"][row["headline_cost"]]["unit"]
    else:
        assert row["kind_cost"] == "" and math.isnan(row["kind_cost_value"])


# --------------------------------------------------------------------------------- the plugin end to end
def test_registry_refuses_a_taken_name_and_a_unit_it_does_not_know(toy_plugin):
    from fsdvs_hw.errors import InputError
    from fsdvs_hw.realise.registry import CostSpec

    with pytest.raises(InputError, match="already registered"):
        register_realisation(dataclasses.replace(toy_plugin.SPEC))
    with pytest.raises(InputError, match="unit 'furlong' unknown"):
        CostSpec("x", "furlong")
    with pytest.raises(InputError, match="realisation 'nope' unknown; allowed: .*box"):
        get_realisation("nope")


def test_a_plugin_realisation_is_explored_end_to_end(tmp_path, capsys):
    """``box`` (registered by tests/plugins/toy_realisation.py, no edit to the package) in a design,
    with a sweep over its one option: it is fitted, scored, stored, tabled and reported, its cost on
    its own axis in its own unit (px)."""
    from fsdvs_hw.cli import main

    p = tmp_path / "box.toml"
    p.write_text(
        '[realisations]\ninclude = ["learned", "delta", "box"]\n[realisations.box]\nwidth = 3\n'
        '[sweep]\naxes = { "box.width" = [1, 3] }\n[analysis]\ncsf_methods = ["mannos_sakrison_1974"]\n'
        "[sensor]\nresolution = [24, 32]\n[emulation]\nenabled = false\n[run]\nworkers = 1\n"
    )
    out = tmp_path / "out"
    assert main(["explore", str(p), "--out", str(out), "--no-progress"]) == 0
    printed = capsys.readouterr().out
    assert re.search(r"^\| box width=1 \| .* \| box width 1 px \| ", printed, re.M), printed
    assert re.search(r"^\| box width=3 \| .* \| box width 3 px \| ", printed, re.M), printed
    rows = json.loads((out / "scores.json").read_text())["rows"]
    box = sorted((r for r in rows if r["realisation"] == "box"), key=lambda r: r["kind_cost_value"])
    assert [r["status"] for r in box] == ["ok", "ok"]
    assert [(r["kind_cost"], r["kind_cost_value"], r["kind_cost_unit"]) for r in box] == [
        ("box width", 1.0, "px"),
        ("box width", 3.0, "px"),
    ]
    assert all(r["headline_cost"] == "box_width" and r["headline_cost_unit"] == "px" for r in box)
    assert all(r["cost_adders"] == r["kind_cost_value"] ** 2 - 1 for r in box)
    with (out / "scores.csv").open() as fh:
        csv_box = [r for r in csv.DictReader(fh) if r["realisation"] == "box"]
    assert sorted(float(r["kind_cost_value"]) for r in csv_box) == [1.0, 3.0]
    assert {r["kind_cost_unit"] for r in csv_box} == {"px"}
    html = (out / "report.html").read_text()
    assert "box (width 3)" in html and "box width 3 px" in html  # the report labels swept points "name (option value)"
    from fsdvs_hw.realise.artifacts import read_index

    assert read_index(out / "artifacts" / "index.json") == []  # no writer declared: nothing written, no error
    assert "Buildable artifacts" not in html


@pytest.mark.slow
def test_spawned_workers_know_a_plugin_registered_in_the_parent(tmp_path):
    """``[run] workers = 2`` spawns processes: they import the plugin module named in
    ``FSDVS_HW_REALISATION_PLUGINS`` (set by register_realisation), so its points are scored, not
    refused as unknown."""
    import os

    from fsdvs_hw.design import parse_design
    from fsdvs_hw.explore.sweep import run_design

    assert "toy_realisation" in os.environ[registry.PLUGIN_ENV].split(os.pathsep)
    d = parse_design(
        {
            "realisations": {"include": ["box"]},
            "sweep": {"axes": {"box.width": [1, 3, 5]}},
            "analysis": {"csf_methods": ["mannos_sakrison_1974"]},
            "emulation": {"enabled": False},
        },
        source="spawned",
    )
    summary, rows = run_design(d, tmp_path / "store.sqlite", workers=2, progress=False)
    assert summary.executor.startswith("2 local processes")
    assert summary.statuses == {"ok": 3}, [r.reason for r in rows]
    assert sorted(r.score.cost.value("box_width") for r in rows if r.score is not None) == [1, 3, 5]


# --------------------------------------------------------------------------------- accepted ranges
def _bound_probes(opt) -> list:
    """Values at and just beyond each bound of an option (from its model's metadata), each of its
    choices and one value outside them, and both booleans: a new option is probed without an edit."""
    values: list = []
    kinds = set(opt.kinds)
    if kinds & {"int", "float"}:
        integer = "float" not in kinds
        for bound, side in ((opt.lo, -1), (opt.hi, 1)):
            if bound is None:
                continue
            if integer:
                values += [int(bound), int(bound) + side]
            else:
                values += [float(bound), float(bound) + side * max(abs(float(bound)), 1e-300) * 1e-6]
    if opt.choices:
        values += [*opt.choices, "no-such-choice"]
    if "bool" in kinds:
        values += [True, False]
    return values


def _design_accepts(name, key, value) -> bool:
    from fsdvs_hw.design import DesignError, parse_design

    try:
        parse_design({"realisations": {"include": [name], name: {key: value}}}, source="ranges")
    except DesignError as exc:
        assert f"'realisations.{name}." in str(exc), str(exc)  # refused for the option, not for something else
        return False
    return True


def _fit_accepts(spec, target, key, value, monkeypatch) -> bool:
    """The fit function's own validation: it is called with the value and stopped right after its
    entry check (every fit validates its whole options object there, before any work)."""
    from fsdvs_hw.errors import InputError

    module = sys.modules[spec.fit.__module__]
    entry = module.check_fit_arguments

    def validated_then_stop(options, arguments):
        entry(options, arguments)
        raise _Landed("validated")

    monkeypatch.setattr(module, "check_fit_arguments", validated_then_stop)
    try:
        spec.fit(target, **{key: value})
    except _Landed:
        return True
    except InputError:
        return False
    finally:
        monkeypatch.setattr(module, "check_fit_arguments", entry)
    raise AssertionError(f"{spec.name}: the fit did not stop at its entry check")


@pytest.mark.parametrize("name", [*realisation_names("hardware"), "box"])
def test_a_design_file_and_the_fit_accept_the_same_values_at_every_bound(name, monkeypatch):
    from fsdvs_hw.design import parse_design

    spec = get_realisation(name)
    target = parse_design({}, source="ranges").target  # the target a design file's fit gets
    differ = []
    for key in spec.options.model_fields:
        for value in _bound_probes(view(spec.options, key)):
            design = _design_accepts(name, key, value)
            if design != _fit_accepts(spec, target, key, value, monkeypatch):
                differ.append(
                    f"{key} = {value!r}: the design file {'accepts' if design else 'refuses'} it, the fit not"
                )
    assert not differ, "\n".join(differ)


def test_the_bounds_of_every_option_are_probed():
    probed = {
        (n, k): len(_bound_probes(view(get_realisation(n).options, k)))
        for n in realisation_names("hardware")
        for k in get_realisation(n).options.model_fields
    }
    assert probed[("mesh", "tol")] == 4 and probed[("asic", "bits")] == 4 and probed[("metalens", "strategy")] == 3
    assert sum(probed.values()) >= 100
