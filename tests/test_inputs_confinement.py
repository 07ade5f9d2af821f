"""Issue 23: inputs stay in their place. ``--set`` keys and scheduler addresses are checked before
any work, damaged stores are refused by name, nothing is written through a symbolic link, checkpoint
globs stay in the design's folder with a bounded walk, a report is never redrawn with another
design, integer flags have documented limits, and no design input raises anything but InputError."""

from __future__ import annotations

import os
import sqlite3
from pathlib import Path

import pytest
from conftest import cheap_design

from fsdvs_hw.cli import main
from fsdvs_hw.design import DesignError, check_key, load_design, parse_design
from fsdvs_hw.design import checkpoints as design_checkpoints
from fsdvs_hw.design import sections as design_sections
from fsdvs_hw.errors import InputError
from fsdvs_hw.explore.store import ResultsStore
from fsdvs_hw.explore.sweep import check_scheduler_address
from fsdvs_hw.limits import MAX_SEED, MAX_WORKERS, check_count
from fsdvs_hw.paths import write_output

hypothesis = pytest.importorskip("hypothesis")
from hypothesis import HealthCheck, given, settings  # noqa: E402
from hypothesis import strategies as st  # noqa: E402


def _one_clear_line(err: str) -> str:
    lines = [ln for ln in err.strip().splitlines() if not ln.startswith("[")]
    assert "Traceback" not in err
    assert len(lines) == 1 and ": error: " in lines[0], err
    return lines[0]


def _cli(argv: list[str], capsys) -> tuple[int, str]:
    try:
        code = main(argv)
    except SystemExit as exc:  # a flag refused while parsing (argparse exits 2 after one line)
        code = int(exc.code or 0)
    return code, capsys.readouterr().err


@pytest.fixture
def cheap(tmp_path) -> Path:
    p = tmp_path / "d.toml"
    p.write_text(cheap_design())
    return p


# ---------------------------------------------------------------------- --set keys
@pytest.mark.parametrize(
    "item,named",
    [
        ("foo.bar=1", "unknown section 'foo'"),
        ("sensor..x=1", "empty part"),
        ("sensor=3", "names a whole section"),
        ("sensor.nope=1", "sensor.pitch_m"),  # the allowed keys of [sensor] are listed
        ("sensor.resolution.x=1", "single value"),
        ("design.name.x=1", "single value"),
        ("asic.nope=2", "bits"),
        ("realisations.nope=1", "include"),
    ],
)
def test_malformed_set_key_is_one_line_before_any_work(cheap, tmp_path, capsys, item, named):
    out = tmp_path / "out"
    code, err = _cli(["explore", str(cheap), "--out", str(out), "--no-progress", "--set", item], capsys)
    line = _one_clear_line(err)
    assert code == 2 and "--set" in line and named in line and repr(item.partition("=")[0]) in line
    assert not out.exists()  # refused before the output folder was made


def test_check_key_suggests_close_keys_and_canonicalises():
    with pytest.raises(DesignError, match=r"did you mean sensor\.pitch_m"):
        check_key("sensr.pitch_m")
    assert check_key("asic.bits") == "realisations.asic.bits"
    assert check_key("kernel.params.sigma_centre_px") == "kernel.params.sigma_centre_px"


def test_table_valued_override_replaces_a_number(cheap):
    d = load_design(cheap).with_overrides({"tasks.n_test.detection": 4})
    assert d.data["tasks"]["n_test"] == {"detection": 4}


def test_a_bad_sweep_axis_key_is_a_design_error_not_a_crash(tmp_path):
    (tmp_path / "d.toml").write_text(cheap_design() + '[sweep]\naxes = { "sensor.resolution.x" = [1, 2] }\n')
    with pytest.raises(DesignError, match=r"sweep\.axes\.sensor\.resolution\.x"):
        load_design(tmp_path / "d.toml")


# ---------------------------------------------------------------------- scheduler addresses
@pytest.mark.parametrize(
    "address,named",
    [
        ("nonsense", "expected an address"),
        ("tcp://host:notaport", "bad port"),
        ("tls://:99999", "bad port"),
        ("ftp://a:1", "unknown scheme"),
        ("tcp://host", "no port"),
        ("tcp://:8786", "no host"),
        ("tcp://h:0", "port 0"),
    ],
)
def test_malformed_scheduler_is_one_line_exit_2(cheap, capsys, address, named):
    code, err = _cli(["sweep", str(cheap), "--no-progress", "--scheduler", address], capsys)
    line = _one_clear_line(err)
    assert code == 2 and "--scheduler" in line and named in line and address[:12] in line


def test_good_scheduler_addresses_pass_unchanged():
    for a in ("tls://10.0.0.5:8786", "tcp://localhost:8786", "tcp://[::1]:8786", "inproc://x/1"):
        assert check_scheduler_address(a) == a


# ---------------------------------------------------------------------- corrupt stores
def _stored(path: Path) -> None:
    with ResultsStore(path) as s:
        for i in range(40):
            s.add(
                f"k{i}",
                design="d",
                realisation="asic",
                params={"i": i},
                status="ok",
                result={"x": "y" * 200},
                wall_s=0.1,
            )


def test_a_store_with_a_damaged_page_is_refused_naming_the_file(tmp_path):
    path = tmp_path / "r.sqlite"
    _stored(path)
    db = sqlite3.connect(path)
    page_size = db.execute("PRAGMA page_size").fetchone()[0]
    root = db.execute("SELECT rootpage FROM sqlite_master WHERE name='points'").fetchone()[0]
    db.close()
    blob = bytearray(path.read_bytes())
    at = (root - 1) * page_size
    blob[at : at + 8] = b"\xff" * 8  # the b-tree page header of the points table
    path.write_bytes(bytes(blob))
    with pytest.raises(InputError, match="r.sqlite") as info:
        ResultsStore(path)
    assert "\n" not in str(info.value)


@pytest.mark.parametrize("how", ["truncated", "garbage", "other_meta"])
def test_a_corrupt_store_on_the_command_line_is_one_line(cheap, tmp_path, capsys, how):
    store = tmp_path / "bad.sqlite"
    if how == "truncated":
        good = tmp_path / "good.sqlite"
        _stored(good)
        store.write_bytes(good.read_bytes()[:5000])
    elif how == "garbage":
        store.write_bytes(os.urandom(3000))
    else:
        db = sqlite3.connect(store)
        db.execute("CREATE TABLE meta (a)")
        db.commit()
        db.close()
    before = store.read_bytes()
    code, err = _cli(["sweep", str(cheap), "--store", str(store), "--no-progress"], capsys)
    assert code == 2 and "bad.sqlite" in _one_clear_line(err)
    assert store.read_bytes() == before


# ---------------------------------------------------------------------- writes never follow links
def test_os_replace_replaces_a_link_and_leaves_its_target_alone(tmp_path):
    target = tmp_path / "outside.txt"
    target.write_bytes(b"precious")
    link = tmp_path / "out" / "report.html"
    link.parent.mkdir()
    link.symlink_to(target)
    tmp = link.parent / "tmp"
    tmp.write_bytes(b"new")
    os.replace(tmp, link)  # what write_output relies on
    assert not link.is_symlink() and link.read_bytes() == b"new" and target.read_bytes() == b"precious"


def test_write_output_refuses_a_link_and_writes_atomically(tmp_path):
    target = tmp_path / "outside.txt"
    target.write_bytes(b"precious")
    (tmp_path / "out").mkdir()
    (tmp_path / "out" / "a.json").symlink_to(target)
    with pytest.raises(InputError, match="symbolic link"):
        write_output(tmp_path / "out" / "a.json", "{}")
    assert target.read_bytes() == b"precious"
    p = write_output(tmp_path / "out" / "b.json", "x" * 10)
    write_output(p, "second")
    assert p.read_text() == "second" and sorted(f.name for f in p.parent.iterdir()) == ["a.json", "b.json"]


@pytest.fixture(scope="module")
def run_dir(tmp_path_factory) -> tuple[Path, Path]:
    d = tmp_path_factory.mktemp("run")
    (d / "d.toml").write_text(cheap_design())
    assert main(["explore", str(d / "d.toml"), "--out", str(d / "out"), "--no-progress"]) == 0
    return d / "d.toml", d / "out"


@pytest.mark.parametrize("name", ["report.html", "scores.json", "scores.csv"])
def test_report_never_writes_through_a_link_in_out(run_dir, tmp_path, capsys, name):
    design, out = run_dir
    outside = tmp_path / "outside.txt"
    outside.write_bytes(b"do not touch\n")
    victim = out / name
    saved = victim.read_bytes()
    victim.unlink()
    victim.symlink_to(outside)
    try:
        code, err = _cli(["report", str(design), "--out", str(out)], capsys)
        line = _one_clear_line(err)
    finally:
        victim.unlink()
        victim.write_bytes(saved)
    assert code == 2 and name in line and "symbolic link" in line
    assert outside.read_bytes() == b"do not touch\n"


def test_report_with_another_design_is_refused_naming_both(run_dir, tmp_path, capsys):
    design, out = run_dir
    other = tmp_path / "other.toml"
    other.write_text(cheap_design() + "[sensor]\nthreshold_on = 0.3\n")
    before = (out / "report.html").read_bytes()
    code, err = _cli(["report", str(other), "--out", str(out)], capsys)
    line = _one_clear_line(err)
    assert code == 2 and "other.toml" in line and "scores.json" in line and "sensor.threshold_on" in line
    assert (out / "report.html").read_bytes() == before
    code, err = _cli(["report", str(design), "--out", str(out)], capsys)
    assert code == 0, err
    # the --set options the run did not use make another design too
    code, err = _cli(["report", str(design), "--out", str(out), "--set", "sensor.threshold_on=0.3"], capsys)
    assert code == 2 and "does not match" in _one_clear_line(err)


# ---------------------------------------------------------------------- checkpoint globs
def _ckpt_design(folder: Path, pattern: str) -> Path:
    p = folder / "d.toml"
    p.write_text(cheap_design() + f"[tasks]\ncheckpoints = {{ detection = {pattern!r} }}\n")
    return p


@pytest.mark.parametrize("pattern", ["../*", "../../*/*.safetensors", "/**/*.safetensors", "/etc/*"])
def test_a_glob_out_of_the_design_folder_is_refused_and_lists_nothing(tmp_path, pattern):
    (tmp_path / "secret_net.safetensors").write_bytes(b"x")
    folder = tmp_path / "designs"
    folder.mkdir()
    with pytest.raises(DesignError) as info:
        load_design(_ckpt_design(folder, pattern))
    msg = str(info.value)
    assert "inside the design's folder" in msg and "secret_net" not in msg and "passwd" not in msg


def test_a_glob_through_a_link_out_of_the_folder_does_not_echo_the_files(tmp_path):
    outside = tmp_path / "outside"
    outside.mkdir()
    (outside / "secret_net.safetensors").write_bytes(b"x")
    folder = tmp_path / "designs"
    folder.mkdir()
    (folder / "link").symlink_to(outside)
    with pytest.raises(DesignError) as info:
        load_design(_ckpt_design(folder, "link/*.safetensors"))
    assert "matches no file" in str(info.value) and "secret_net" not in str(info.value)


def test_a_wide_glob_is_refused_after_a_bounded_walk(tmp_path, monkeypatch):
    folder = tmp_path / "designs"
    (folder / "nets").mkdir(parents=True)
    for i in range(30):
        (folder / "nets" / f"f{i}.txt").write_bytes(b"")
    monkeypatch.setattr(design_checkpoints, "MAX_GLOB_ENTRIES", 10)
    with pytest.raises(DesignError, match="more than 10 files and folders"):
        load_design(_ckpt_design(folder, "*/*.safetensors"))
    walked = design_checkpoints.bounded_glob(folder, ["nets", "f1*.txt"], limit=100)
    assert sorted(p.name for p in walked) == ["f1.txt"] + [f"f{i}.txt" for i in range(10, 20)]


# ---------------------------------------------------------------------- limits of integer flags
@pytest.mark.parametrize(
    "argv,flag",
    [
        (["sweep", "{d}", "--workers", "0"], "--workers"),
        (["explore", "{d}", "--workers", str(MAX_WORKERS + 1)], "--workers"),
        (["sweep", "{d}", "--max-points", "0"], "--max-points"),
        (["learn", "detection", "--seed", "-1"], "--seed"),
        (["learn", "detection", "--seed", str(MAX_SEED + 1)], "--seed"),
        (["learn", "detection", "--n-train", "0"], "--n-train"),
        (["ablation", "--seeds", "0", str(2**40)], "--seeds"),
        (["ablation", "--sizes", "100000"], "--sizes"),
        (["sizing", "{d}", "--pilot", "0"], "--pilot"),
    ],
)
def test_integer_flags_outside_their_limits_are_one_line(cheap, capsys, argv, flag):
    code, err = _cli([a.format(d=cheap) for a in argv], capsys)
    line = _one_clear_line(err)
    assert code == 2 and flag in line and "allowed" in line


def test_check_count_names_the_range():
    assert check_count("--workers", 3, 1, 4) == 3
    for bad in (0, 5, True, 2.0, "3"):
        with pytest.raises(InputError, match=r"\[1, 4\]"):
            check_count("--workers", bad, 1, 4)


# ---------------------------------------------------------------------- fuzz
_SCHEMA = {s: list(info.annotation.model_fields) for s, info in design_sections.design_model().model_fields.items()}
_GARBAGE = st.one_of(
    st.none(),
    st.booleans(),
    st.integers(-(2**70), 2**70),
    st.floats(allow_nan=True),
    st.text(max_size=12),
    st.lists(st.integers(-5, 5000), max_size=3),
    st.dictionaries(st.text(max_size=6), st.integers(-3, 3), max_size=2),
)
_VALUE = st.recursive(
    _GARBAGE,
    lambda inner: st.one_of(st.lists(inner, max_size=3), st.dictionaries(st.text(max_size=6), inner, max_size=3)),
    max_leaves=6,
)
_SECTION_KEYS = {s: sorted(f) + ["zz_unknown"] for s, f in _SCHEMA.items() if s != "tasks"}
FUZZ = settings(
    max_examples=60,
    deadline=None,
    derandomize=True,
    suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture],
)


@st.composite
def _design_dict(draw):
    sections = draw(st.lists(st.sampled_from([*_SECTION_KEYS, "bogus"]), max_size=4, unique=True))
    raw: dict = {}
    for s in sections:
        if s == "bogus" or draw(st.integers(0, 9)) == 0:
            raw[s] = draw(_VALUE)
            continue
        keys = draw(st.lists(st.sampled_from(_SECTION_KEYS[s]), max_size=3, unique=True))
        raw[s] = {k: draw(_VALUE) for k in keys}
    return raw


@FUZZ
@given(raw=_design_dict())
def test_fuzzed_design_tables_validate_or_raise_input_error(raw, tmp_path):
    try:
        d = parse_design(raw, source="fuzz", base_dir=tmp_path)
    except InputError:
        return
    # every section, except [costs] and [process], which a design holds only when it sets them (its fingerprint is unchanged)
    assert d.target is not None and set(d.data) == set(_SCHEMA) - ({"costs", "process"} - set(raw))


_KEY_PART = st.one_of(
    st.sampled_from([*_SCHEMA, "asic", "mesh", "bits", "resolution", "pitch_m", "params", ""]),
    st.text(alphabet="abcxyz._=[]{} ", max_size=6),
)


@FUZZ
@given(parts=st.lists(_KEY_PART, min_size=1, max_size=4), value=st.text(max_size=12))
def test_fuzzed_set_strings_validate_or_raise_input_error(parts, value, cheap):
    from fsdvs_hw.cli.explore import parse_overrides

    base = load_design(cheap)
    try:
        d = base.with_overrides(parse_overrides([".".join(parts) + "=" + value]))
    except InputError:
        return
    assert d.data["design"]["name"]


# ------------------------------------------------- every file for the user: whole, never through a link
@pytest.mark.parametrize("suffix", [".json", ".npy", ".csv", ".pt"])
def test_kernel_save_never_writes_through_a_link_and_replaces_whole(tmp_path, suffix):
    from fsdvs_hw.kernels import load_kernel, reference_kernel

    outside = tmp_path / "outside.txt"
    outside.write_bytes(b"precious")
    link = tmp_path / f"k{suffix}"
    link.symlink_to(outside)
    with pytest.raises(InputError, match="symbolic link"):
        reference_kernel("dog", 5).save(link)
    assert outside.read_bytes() == b"precious" and link.is_symlink()
    target = tmp_path / f"real{suffix}"
    reference_kernel("dog", 5).save(target)
    reference_kernel("dog", 7).save(target)  # replaced whole: the new kernel, no temp file left beside it
    assert load_kernel(target).size == 7
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted(["outside.txt", f"k{suffix}", f"real{suffix}"])


def test_asic_artifacts_and_their_index_refuse_a_link(tmp_path):
    from fsdvs_hw.kernels import reference_kernel
    from fsdvs_hw.realise.artifacts import write_index
    from fsdvs_hw.realise.asic import fit_asic_taps
    from fsdvs_hw.realise.asic.artifacts import write_asic_artifacts

    outside = tmp_path / "outside.v"
    outside.write_text("precious")
    out = tmp_path / "art"
    out.mkdir()
    (out / "fsdvs_conv.v").symlink_to(outside)
    with pytest.raises(InputError, match="symbolic link"):
        write_asic_artifacts(fit_asic_taps(reference_kernel("dog", 5), bits=6), out)
    assert outside.read_text() == "precious"
    (out / "index.json").symlink_to(outside)
    with pytest.raises(InputError, match="symbolic link"):
        write_index([], out / "index.json")
    assert outside.read_text() == "precious"


def test_codesign_tables_refuse_a_link(tmp_path):
    from fsdvs_hw.explore.codesign import write_codesign

    outside = tmp_path / "outside.csv"
    outside.write_text("precious")
    (tmp_path / "codesign.csv").symlink_to(outside)
    with pytest.raises(InputError, match="symbolic link"):
        write_codesign({"cells": []}, tmp_path)
    assert outside.read_text() == "precious"
