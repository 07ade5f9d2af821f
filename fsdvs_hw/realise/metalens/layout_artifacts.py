"""Buildable artifacts of a metalens layout: the GDSII file, its DRC report, the library, the step PSFs.

:func:`write_layout_artifacts` writes, for a fitted
:class:`~fsdvs_hw.realise.metalens.layout_design.MetalensLayoutDesign`:

``metalens.gds``
    The layout (gdstk; µm units, 1 nm grid): top cell ``METALENS``, one cell per radius level
    (``PILLAR_<index>_R<radius>NM``, one circle on the design's layer/datatype), referenced once per
    lattice site; a differential pair's two lenses side by side, 10 µm apart.
``drc.json``
    KLayout's width (projection metrics) and space check at the design's rules, run in a separate
    process (:mod:`~fsdvs_hw.realise.metalens.drc`), and the pillar count gdstk reads back.
``meta_atoms.json``
    The meta-atom library used (complex transmission at both truncation orders, spec, provenance).
``layout_psf.npz``
    The PSFs and applied kernels of the three steps (``ideal_*``, ``library_*``, ``layout_*``),
    the per-level radii (m) and pillar counts.

Example
-------
>>> from fsdvs_hw.realise.metalens.layout_artifacts import GDS_NAME
>>> GDS_NAME
'metalens.gds'
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np

from ...errors import InputError
from ...paths import npz_bytes, write_output
from ..artifacts import Artifact
from .drc import run_drc
from .layout import read_gds_pillars, write_gds
from .layout_design import PAIR_GAP_M, MetalensLayoutDesign, build_layout
from .meta_atoms import load_library
from .options import MetalensLayoutOptions

__all__ = ["GDS_NAME", "write_layout_artifacts"]

GDS_NAME = "metalens.gds"


def _library_of(design: MetalensLayoutDesign) -> Any:
    """The design's library (from the cache; recomputed only if its fingerprint is no longer cached)."""
    opts = MetalensLayoutOptions.model_validate(
        {**design.options, "design_wavelength_m": design.ideal.geometry.design_wavelength_m}
    )
    library = load_library(opts.meta_atom_spec(), progress=False)
    if library.spec.fingerprint != design.layout_info.get("library_fingerprint"):
        raise InputError(
            f"metalens layout: its library {design.layout_info.get('library_fingerprint')} is not the one its options "
            f"give ({library.spec.fingerprint})"
        )
    return library


def write_layout_artifacts(
    design: MetalensLayoutDesign, out_dir: str | Path, *, resolution: tuple[int, int] | None = None
) -> tuple[Artifact, ...]:
    """Write the GDS, its DRC report, the library and the step PSFs into ``out_dir`` (module docstring).

    ``resolution`` is accepted for the writer protocol and not used.
    """
    if not isinstance(design, MetalensLayoutDesign):
        raise InputError(f"write_layout_artifacts: expected a MetalensLayoutDesign, got {type(design).__name__}")
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    o = design.options
    library = _library_of(design)
    lenses = build_layout(design.ideal, o, library)
    spacing = design.ideal.geometry.aperture_m + PAIR_GAP_M
    gds = write_gds(
        out / GDS_NAME,
        [(lens.sites, lens.levels) for lens in lenses],
        library.radii_m,
        layer=int(o["gds_layer"]),
        datatype=int(o["gds_datatype"]),
        spacing_m=spacing,
    )
    back = read_gds_pillars(gds.path)
    report: dict[str, Any] = {
        "pillars_written": gds.pillars,
        "pillars_read_back": back.pillars,
        "expected_pillars": int(design.layout_info["pillars"]),
        "radius_levels": gds.levels,
        "layer": int(o["gds_layer"]),
        "datatype": int(o["gds_datatype"]),
    }
    if o.get("drc", True):
        drc = run_drc(
            gds.path,
            layer=int(o["gds_layer"]),
            datatype=int(o["gds_datatype"]),
            min_width_m=float(o["min_width_m"]),
            min_space_m=float(o["min_space_m"]),
        )
        report["drc"] = drc.to_dict()
    else:
        report["drc"] = {"ran": False, "message": "DRC off (drc = false)"}
    write_output(out / "drc.json", json.dumps(report, indent=1) + "\n", flag="artifacts")
    write_output(out / "meta_atoms.json", json.dumps(library.to_dict(), indent=1) + "\n", flag="artifacts")
    steps = {"ideal": design.ideal, "library": design.library_step, "layout": design.layout}
    arrays: dict[str, Any] = {}
    for name, step in steps.items():
        arrays[f"{name}_psf"] = np.stack([np.asarray(p, dtype=float) for p in step.psfs])
        arrays[f"{name}_kernel"] = np.asarray(step.kernel().taps, dtype=float)
        arrays[f"{name}_kernel_error"] = float(step.error)
    levels = np.concatenate([lens.levels for lens in lenses])
    write_output(
        out / "layout_psf.npz",
        npz_bytes(
            **arrays,
            radii_m=library.radii_m,
            pillars_per_radius=np.bincount(levels, minlength=library.radii_m.size),
            pixel_pitch_m=design.target.pitch_m,
        ),
        flag="artifacts",
    )
    drc_words = report["drc"].get("message", "")
    return (
        Artifact(
            "gds",
            gds.path,
            f"GDSII layout: {gds.pillars} pillars, {gds.levels} radius cells, layer {o['gds_layer']}/{o['gds_datatype']} (µm, 1 nm grid)",
            'python -c "import gdstk; print(sum(max(1, r.repetition.size) for r in '
            f"gdstk.read_gds('{GDS_NAME}').top_level()[0].references))\" prints "
            f"{int(design.layout_info['pillars'])}; KLayout DRC (drc.json): {drc_words}",
        ),
        Artifact("drc", out / "drc.json", "pillar count read back by gdstk and KLayout's width/space check", ""),
        Artifact(
            "meta_atoms",
            out / "meta_atoms.json",
            "the meta-atom library used: complex t vs radius (m) and wavelength (m)",
            "",
        ),
        Artifact(
            "layout_psf",
            out / "layout_psf.npz",
            "PSFs (fractions of aperture power) and kernels of the steps ideal phase → library → layout",
            "",
        ),
    )
