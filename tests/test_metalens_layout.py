"""The metalens layout: lattice, nearest complex transmission, the layout PSF against the ideal lens, GDSII, DRC.

The PSF tests use synthetic libraries (no RCWA): a lossless library of N levels evenly covering 2π
is what scalar diffraction theory calls an N-level phase grating, whose first-order efficiency is
sinc²(1/N) (Swanson, MIT Lincoln Laboratory Technical Report 854, 1989): 0.811 for 4 levels,
0.9992 for 64. So 64 levels must reproduce the ideal-phase PSF (measured: 0.34 % relative L2 on a
square lattice, 0.59 % hexagonal; tolerance 1.5 %), and 4 levels must not (measured 19 %), losing
about 19 % of the light.
"""

from __future__ import annotations

import json

import numpy as np
import pytest

from fsdvs_hw import reference_kernel
from fsdvs_hw.errors import InputError
from fsdvs_hw.realise.metalens import fit_metalens
from fsdvs_hw.realise.metalens.drc import drc_available, run_drc
from fsdvs_hw.realise.metalens.layout import assign_levels, lattice_sites, read_gds_pillars, write_gds
from fsdvs_hw.realise.metalens.layout_design import build_layout, step_psfs
from fsdvs_hw.realise.metalens.layout_psf import pixel_overlaps
from fsdvs_hw.realise.metalens.meta_atoms import MetaAtomLibrary, MetaAtomSpec

pytest.importorskip("gdstk")

#: Largest relative L2 difference between the layout PSF of a 64-level lossless library and the ideal PSF.
FINE_TOL = 0.015
#: Smallest relative L2 difference of a 4-level library (it must visibly fail).
COARSE_MIN = 0.10

OPTIONS = {"period_m": 300e-9, "lattice": "square", "transmission_min": 0.5, "phase_tolerance_rad": 0.1}


@pytest.fixture(scope="module")
def ideal():
    """A small ideal-phase lens: 20 µm aperture, f = 60 µm, DoG 3×3 at 2 µm pitch, one wavelength."""
    return fit_metalens(
        reference_kernel("dog", 3, pitch_m=2e-6),
        aperture_m=20e-6,
        focal_length_m=60e-6,
        illuminant=555e-9,
        n_wavelengths=1,
        n_terms=1,
        max_iter=5,
        n_starts=1,
        progress=False,
    )


def lossless(n_levels: int) -> MetaAtomLibrary:
    spec = MetaAtomSpec(
        radii_m=tuple(np.linspace(40e-9, 125e-9, n_levels)), wavelengths_m=(555e-9,), fourier_orders=2, check_orders=1
    )
    t = np.exp(2j * np.pi * np.arange(n_levels) / n_levels)[None]
    return MetaAtomLibrary(spec, t, t.copy())


def _psfs(ideal, library, lattice="square"):
    opts = {**OPTIONS, "lattice": lattice}
    lenses = build_layout(ideal, opts, library)
    lib_psfs, lay_psfs, _ = step_psfs(ideal, lenses, library, opts)
    return lib_psfs[0], lay_psfs[0]


@pytest.mark.parametrize("lattice", ["square", "hexagonal"])
def test_a_fine_lossless_library_reproduces_the_ideal_psf_and_a_coarse_one_does_not(ideal, lattice):
    p_ideal = ideal.psfs[0]

    def err(p):
        return float(np.linalg.norm(p - p_ideal) / np.linalg.norm(p_ideal))

    (lib_fine, _), (lay_fine, _) = _psfs(ideal, lossless(64), lattice)
    assert err(lib_fine) < FINE_TOL and err(lay_fine) < FINE_TOL
    (lib_coarse, _), (lay_coarse, _) = _psfs(ideal, lossless(4), lattice)
    assert err(lib_coarse) > COARSE_MIN and err(lay_coarse) > COARSE_MIN
    # the 4-level grating sends sinc²(1/4) = 0.811 of the light into the lens's focus
    assert lay_coarse.sum() / p_ideal.sum() == pytest.approx(np.sinc(0.25) ** 2, abs=0.03)


def test_the_nearest_complex_transmission_wins_over_the_nearest_phase():
    # entry 0: the exact phase but nearly opaque (a resonance); entry 1: 0.3 rad off, fully transmitting
    t = np.array([0.1 * np.exp(1j * 1.0), np.exp(1j * 1.3), np.exp(1j * 4.0)])
    levels, _ = assign_levels(np.array([1.0]), t, theta=0.0)
    assert levels.tolist() == [1]
    # the free global phase is chosen well: a lossless 8-level library reaches every phase within π/8
    t8 = np.exp(2j * np.pi * np.arange(8) / 8)
    phase = np.linspace(0, 2 * np.pi, 1000, endpoint=False)
    levels, theta = assign_levels(phase, t8)
    miss = np.angle(t8[levels] * np.exp(-1j * (phase + theta)))
    assert np.abs(miss).max() <= np.pi / 8 + 1e-9
    with pytest.raises(InputError, match="no usable radius"):
        assign_levels(phase, np.array([], dtype=complex))


@pytest.mark.parametrize("lattice,cell", [("square", 1.0), ("hexagonal", np.sqrt(3) / 2)])
def test_lattice_sites_fill_the_aperture_at_the_lattice_density(lattice, cell):
    a, p = 20e-6, 300e-9
    sites = lattice_sites(a, p, lattice)
    assert np.hypot(sites[:, 0], sites[:, 1]).max() <= a
    assert len(sites) == pytest.approx(np.pi * a * a / (cell * p * p), rel=0.01)
    d = np.sort(np.hypot(*(sites[1:] - sites[0]).T))
    assert d[0] == pytest.approx(p)  # nearest neighbour at one period
    with pytest.raises(InputError, match="lattice 'triangular' unknown"):
        lattice_sites(a, p, "triangular")


def test_pixel_overlaps_integrate_exactly():
    x = (np.arange(-50, 51)) * 0.3e-6
    w = pixel_overlaps(x, 0.3e-6, 5, 4.86e-6)
    assert w.sum(axis=0) == pytest.approx(np.full(5, 4.86 / 0.3))  # each pixel holds pitch/dx samples
    assert np.all(w.sum(axis=1) <= 1 + 1e-12)


def test_gds_reads_back_with_its_pillar_count_and_passes_drc_only_at_rules_it_meets(tmp_path, ideal):
    library = lossless(16)
    [lens] = build_layout(ideal, OPTIONS, library)
    gds = write_gds(tmp_path / "lens.gds", [(lens.sites, lens.levels)], library.radii_m, layer=7, datatype=3)
    back = read_gds_pillars(gds.path)
    assert back.pillars == len(lens.sites) == gds.pillars
    assert back.per_level == gds.per_level and back.levels == len(np.unique(lens.levels))
    import gdstk

    lib = gdstk.read_gds(str(gds.path))
    shapes = [p for c in lib.cells if c.name.startswith("PILLAR") for p in c.polygons]
    assert {(p.layer, p.datatype) for p in shapes} == {(7, 3)}
    if not drc_available():
        pytest.skip("the klayout package is not installed")
    # radii 40–125 nm at a 300 nm period: widths ≥ 80 nm, gaps ≥ 50 nm
    ok = run_drc(gds.path, layer=7, datatype=3, min_width_m=70e-9, min_space_m=40e-9)
    assert ok.ran and ok.passed and ok.shapes == back.pillars
    bad = run_drc(gds.path, layer=7, datatype=3, min_width_m=90e-9, min_space_m=60e-9)
    assert bad.ran and not bad.passed and bad.width_violations > 0 and bad.space_violations > 0
    wrong_layer = run_drc(gds.path, layer=1, datatype=0, min_width_m=70e-9, min_space_m=40e-9)
    assert wrong_layer.shapes == 0


def test_options_refuse_rules_the_layout_would_break():
    from fsdvs_hw.realise.metalens.layout_design import fit_metalens_layout

    k = reference_kernel("dog", 3, pitch_m=2e-6)
    with pytest.raises(InputError, match="min_width_m"):
        fit_metalens_layout(k, min_radius_m=30e-9, min_width_m=70e-9)
    with pytest.raises(InputError, match="min_space_m"):
        fit_metalens_layout(k, max_radius_m=140e-9, min_space_m=40e-9)
    with pytest.raises(InputError, match="diffracts into the substrate"):
        fit_metalens_layout(k, period_m=400e-9, max_radius_m=150e-9)


def test_drc_without_klayout_says_so(monkeypatch, tmp_path):
    import sys

    from fsdvs_hw.realise.metalens import drc

    monkeypatch.setattr(drc, "_SCRIPT", "import klayout_not_installed_here\n")
    res = drc.run_drc(tmp_path / "none.gds", layer=1, datatype=0, min_width_m=1e-7, min_space_m=1e-7)
    assert not res.ran and not res.passed and "DRC failed" in res.message
    monkeypatch.setattr(drc, "_SCRIPT", "raise ModuleNotFoundError(\"No module named 'klayout'\")\n")
    res = drc.run_drc(tmp_path / "none.gds", layer=1, datatype=0, min_width_m=1e-7, min_space_m=1e-7)
    assert not res.ran and "not installed" in res.message
    assert json.loads(json.dumps(res.to_dict()))["ran"] is False and sys.executable


def test_a_design_file_names_the_key_of_an_unknown_material():
    from fsdvs_hw.design import parse_design

    table = {"realisations": {"include": ["metalens_layout"], "metalens_layout": {"substrate": "glass"}}}
    with pytest.raises(InputError, match=r"realisations\.metalens_layout\.substrate.*'glass' unknown"):
        parse_design(table, source="t")
