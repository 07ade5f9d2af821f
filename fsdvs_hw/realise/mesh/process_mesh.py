"""The dual mesh built in a real process (``mesh_process``): fitted ideal mesh → biased sky130 transistors.

:func:`fit_process_mesh` fits the ideal dual mesh (:func:`~fsdvs_hw.realise.mesh.fit_resistive_mesh`,
default options), realises its four conductances as subthreshold pass transistors biased by a fit
against the PDK's models at the nominal condition (:func:`fsdvs_hw.process.mesh_devices.fit_mesh_bias`),
and evaluates the transistor mesh at every corner × temperature with the biases held
(:mod:`fsdvs_hw.process.corners`) and under Monte Carlo mismatch. The record's kernel — what the
scorer pushes through the event simulator and the task evaluators — is the kernel of the condition
``scored`` names: ``"worst"`` (the condition with the largest kernel error against the target, e.g.
"sky130 ss 85 °C") or ``"nominal"`` (the first corner at the first temperature).

Its cost carries, each with its source ("sky130 ss 85 °C, ngspice 39"): the kernel error per
condition, the mismatch kernel error's mean and 95 % interval, the area per pixel
(:mod:`fsdvs_hw.process.mesh_area`), whether it fits the pixel, the smallest pitch and the sharing
factor that make it fit with the kernel error sharing costs, and the power per pixel.
"""

from __future__ import annotations

import time
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Annotated, Any, Literal

import numpy as np
from pydantic import Field

from ...errors import InputError
from ...kernels import Kernel
from ...schema import StrictModel
from ...schema import field as option
from ...validation import check_fit_arguments
from ..base import CostItem, kernel_error
from .fit import MeshDesign, fit_resistive_mesh

__all__ = ["ProcessMeshDesign", "ProcessMeshOptions", "fit_process_mesh"]


class ProcessMeshOptions(StrictModel):
    """Options of :func:`fit_process_mesh` (``[realisations.mesh_process]``).

    Attributes
    ----------
    pdk : str
        A registered process (:func:`fsdvs_hw.process.process_names`).
    corners : list of str
        Global corners evaluated (the first is the nominal, where the biases are fitted).
    temperatures_c : list of float
        Temperatures (°C), the first the nominal.
    scored : {"worst", "nominal"}
        Which condition's kernel the scorer uses.
    mismatch_samples : int
        Monte Carlo mismatch samples at the nominal corner (0: none).
    reference_v : float
        Rest voltage of the mesh nodes (V).
    supply_v : float or None
        Core supply (V) of the power figure; None: the PDK's nominal.
    device_w_m, device_l_m : float
        Size of every mesh transistor (m).
    pitch_m : float or None
        Pixel pitch (m; default the kernel's).
    seed : int
        Seed of the Monte Carlo draw (ngspice ``.option seed`` is seed + 1).
    """

    pdk: str = option("sky130", "", "registered process (PDK)")
    corners: list[Literal["tt", "ff", "ss", "sf", "fs"]] | None = option(
        None, "", "global corners, the first nominal (default tt, ff, ss)"
    )
    temperatures_c: list[Annotated[float, Field(ge=-55, le=150)]] | None = option(
        None, "", "temperatures in °C, the first nominal (default 27, 85)"
    )
    scored: Literal["worst", "nominal"] = option("worst", "", "condition whose kernel is scored")
    mismatch_samples: int = option(30, "", "Monte Carlo mismatch samples (0: none)", ge=0, le=1000)
    reference_v: float = option(0.5, "V", "rest voltage of the mesh nodes", ge=0.1, le=1.2)
    supply_v: float | None = option(None, "V", "core supply (default: the PDK's nominal)", ge=0.5, le=5.0)
    device_w_m: float = option(1e-6, "m", "mesh transistor width", ge=0.42e-6, le=100e-6)
    device_l_m: float = option(2e-6, "m", "mesh transistor length", ge=0.15e-6, le=100e-6)
    pitch_m: float | None = option(None, "m", "pixel pitch (default: the kernel's)")
    seed: int = option(0, "", "seed of the Monte Carlo draw", ge=0, le=2**31 - 2)


@dataclass(frozen=True, eq=False)
class ProcessMeshDesign:
    """A dual mesh realised in a process: the scored condition's mesh, and every condition's result.

    Attributes
    ----------
    mesh : MeshDesign
        The scored condition's effective mesh (its conductances are the devices' there).
    ideal : MeshDesign
        The ideal mesh that was realised.
    bias : dict
        :meth:`fsdvs_hw.process.mesh_devices.MeshBias.to_dict`.
    conditions : list of dict
        :meth:`fsdvs_hw.process.corners.ConditionResult.to_dict` per corner × temperature.
    mismatch : dict or None
        :meth:`fsdvs_hw.process.corners.MismatchSummary.to_dict`.
    scored_label : str
        ``"ss 85 °C"``: the condition of :attr:`mesh`.
    area : dict
        Area per pixel, pixel fit, smallest pitch, sharing factor and its kernel error.
    power_w : float
        Power per pixel (W).
    settling_s : dict
        ``{"narrow", "wide"}``: 63 % settling of each mesh's centre output after a current step
        (ngspice transient at the nominal condition, 5×5 patch, device capacitances included).
    pdk, tool : str
        ``"sky130"``, ``"ngspice 39"``.
    wall_s : float
        Wall time of the fit and every simulation (s).
    """

    mesh: MeshDesign
    ideal: MeshDesign
    bias: dict[str, Any]
    conditions: list[dict[str, Any]]
    mismatch: dict[str, Any] | None
    scored_label: str
    area: dict[str, Any]
    power_w: float
    settling_s: dict[str, float] = field(default_factory=dict)
    pdk: str = "sky130"
    tool: str = "ngspice"
    wall_s: float = 0.0
    kind: str = field(default="mesh_process", init=False)

    @property
    def target(self) -> Kernel | None:
        """The kernel the ideal mesh was fitted to."""
        return self.ideal.target

    def kernel(self, size: int | None = None) -> Kernel:
        """The scored condition's kernel (whole response, or a ``size`` crop)."""
        k = self.mesh.kernel(size)
        prov = {**k.provenance, "realisation": "mesh_process", "process": f"{self.pdk} {self.scored_label}"}
        return Kernel(k.taps, pitch_m=k.pitch_m, name=f"mesh {self.pdk} {self.scored_label}", provenance=prov)

    def kernel_error(self, target: Kernel | np.ndarray | None = None, *, fit_scale: bool = False) -> float:
        """The scored condition's whole-response kernel error (:meth:`MeshDesign.kernel_error`)."""
        return self.mesh.kernel_error(target, fit_scale=fit_scale)

    def _source(self, label: str, samples: int | None = None) -> str:
        extra = f", {samples} samples" if samples else ""
        return f"{self.pdk} {label}, {self.tool}{extra}"

    def cost(self) -> dict[str, CostItem]:
        """The scored mesh's cost plus the process figures, each naming its source."""
        c = dict(self.mesh.cost())
        nominal = self.conditions[0]
        nom_label = f"{nominal['corner']} {nominal['temperature_c']:g} °C"
        for cond in self.conditions:
            key = f"kernel_error_{cond['corner']}_{cond['temperature_c']:g}C"
            label = f"{cond['corner']} {cond['temperature_c']:g} °C"
            c[key] = CostItem(cond["kernel_error"], "1", f"kernel error vs target ({self._source(label)})")
        worst = max(self.conditions, key=lambda d: d["kernel_error"])
        worst_label = f"{worst['corner']} {worst['temperature_c']:g} °C"
        c["kernel_error_worst_corner"] = CostItem(
            worst["kernel_error"], "1", f"largest kernel error over corners ({self._source(worst_label)})"
        )
        if self.mismatch:
            mm, n = self.mismatch, self.mismatch["samples"]
            src = self._source(f"{mm['corner']}_mm {mm['temperature_c']:g} °C", n)
            for name in ("error_vs_nominal", "error_vs_target"):
                mean, lo, hi = mm["ci"][name]
                c[f"mismatch_{name}"] = CostItem(
                    mean, "1", f"mean kernel {name.replace('_', ' ')} under mismatch ({src})"
                )
                c[f"mismatch_{name}_ci_low"] = CostItem(lo, "1", f"95 % CI low ({src})")
                c[f"mismatch_{name}_ci_high"] = CostItem(hi, "1", f"95 % CI high ({src})")
        a = self.area
        src = self._source(nom_label) + ", stated layout rules (fsdvs_hw.process.mesh_area)"
        c["mesh_area_m2"] = CostItem(a["total_m2"], "m^2", f"mesh area per pixel ({src})")
        c["mesh_device_area_m2"] = CostItem(
            a["devices_m2"], "m^2", f"six transistors with contacts and routing ({src})"
        )
        c["mesh_capacitor_area_m2"] = CostItem(a["capacitor_m2"], "m^2", f"two MIM node capacitors ({src})")
        c["fits_pixel"] = CostItem(float(a["fits_pixel"]), "1", f"1 if the mesh fits the pixel pitch ({src})")
        c["min_pitch_m"] = CostItem(a["min_pitch_m"], "m", f"smallest pixel pitch the mesh fits ({src})")
        c["sharing_k"] = CostItem(a["sharing_k"], "count", f"one mesh node per k×k pixels to fit the pitch ({src})")
        c["sharing_kernel_error"] = CostItem(
            a["sharing_kernel_error"], "1", f"window kernel error vs target (gain fitted) with that sharing ({src})"
        )
        if "unshared_kernel_error" in a:
            c["unshared_kernel_error"] = CostItem(
                a["unshared_kernel_error"], "1", f"the same error without sharing ({src})"
            )
        c["power_w"] = CostItem(self.power_w, "W", f"mesh power per pixel at full signal ({self._source(nom_label)})")
        if self.settling_s:
            c["settling_s"] = CostItem(
                max(self.settling_s.values()),
                "s",
                f"63 % settling of the slower mesh's centre output after a step ({self._source(nom_label)} transient)",
            )
        return c

    def describe(self) -> str:
        lines = [f"dual mesh in {self.pdk} transistors, scored at {self.scored_label}:"]
        lines += [
            f"  {d['corner']} {d['temperature_c']:g} °C: kernel error {d['kernel_error']:.3g}, vs ideal {d['error_vs_ideal']:.3g},"
            f" lambda {d['lambda_narrow_px']:.3g}/{d['lambda_wide_px']:.3g} px"
            for d in self.conditions
        ]
        if self.mismatch:
            m, lo, hi = self.mismatch["ci"]["error_vs_nominal"]
            lines.append(
                f"  mismatch ({self.mismatch['samples']} samples): kernel error vs nominal {m:.3g} [{lo:.3g}, {hi:.3g}]"
            )
        a = self.area
        lines.append(
            f"  area {a['total_m2'] * 1e12:.3g} µm² per pixel ({'fits' if a['fits_pixel'] else 'does not fit'}"
            f" the {a['pitch_m'] * 1e6:.3g} µm pixel;"
            f" smallest pitch {a['min_pitch_m'] * 1e6:.3g} µm;"
            f" sharing k = {a['sharing_k']}: window kernel error {a['sharing_kernel_error']:.3g}"
            f" against {a.get('unshared_kernel_error', float('nan')):.3g} unshared)"
        )
        return "\n".join(lines)

    def to_dict(self) -> dict[str, Any]:
        return {
            "kind": self.kind,
            "mesh": self.mesh.to_dict(),
            "ideal": self.ideal.to_dict(),
            "bias": self.bias,
            "conditions": self.conditions,
            "mismatch": self.mismatch,
            "scored_label": self.scored_label,
            "area": self.area,
            "power_w": self.power_w,
            "settling_s": self.settling_s,
            "pdk": self.pdk,
            "tool": self.tool,
            "wall_s": self.wall_s,
        }

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> ProcessMeshDesign:
        if not isinstance(data, Mapping) or data.get("kind") != "mesh_process":
            raise InputError("ProcessMeshDesign.from_dict: expected a dict with kind 'mesh_process'")
        d = {k: v for k, v in data.items() if k != "kind"}
        d["mesh"] = MeshDesign.from_dict(d["mesh"])
        d["ideal"] = MeshDesign.from_dict(d["ideal"])
        return cls(**d)


def _area(ideal: MeshDesign, spec: Any, w: float, l_um: float) -> dict[str, Any]:
    from ...process.mesh_area import mesh_area_per_pixel, shared_kernel, sharing_factor

    a = mesh_area_per_pixel(w, l_um, ideal.node_capacitance_f, spec.capacitor_f_per_m2)
    k = sharing_factor(a["total_m2"], ideal.pitch_m)
    shared = shared_kernel(ideal, min(k, 16))

    def err(taps: np.ndarray) -> float:
        return kernel_error(taps, ideal.target, fit_scale=True) if ideal.target is not None else float("nan")

    return {
        **a,
        "pitch_m": ideal.pitch_m,
        "fits_pixel": bool(a["total_m2"] <= ideal.pitch_m**2),
        "min_pitch_m": float(np.sqrt(a["total_m2"])),
        "sharing_k": k,
        "sharing_kernel_error": err(shared),
        "unshared_kernel_error": err(shared_kernel(ideal, 1)),
    }


def fit_process_mesh(
    target: Kernel,
    *,
    pdk: str = "sky130",
    corners: list[str] | None = None,
    temperatures_c: list[float] | None = None,
    scored: str = "worst",
    mismatch_samples: int = 30,
    reference_v: float = 0.5,
    supply_v: float | None = None,
    device_w_m: float = 1e-6,
    device_l_m: float = 2e-6,
    pitch_m: float | None = None,
    seed: int = 0,
) -> ProcessMeshDesign:
    """Fit the ideal mesh, bias it in transistors, and evaluate it at every corner, temperature and under mismatch.

    Parameters are those of :class:`ProcessMeshOptions` (``corners`` default ``["tt", "ff", "ss"]``,
    ``temperatures_c`` default ``[27.0, 85.0]``).

    Examples
    --------
    >>> from fsdvs_hw import reference_kernel
    >>> d = fit_process_mesh(reference_kernel("dog", 5), mismatch_samples=0, corners=["tt"], temperatures_c=[27])  # doctest: +SKIP
    >>> d.scored_label  # doctest: +SKIP
    'tt 27 °C'
    """
    opts = check_fit_arguments(ProcessMeshOptions, locals())
    from ...process import get_process
    from ...process.corners import ConditionResult, condition_conductances, condition_design, mismatch_kernels
    from ...process.mesh_area import mesh_power_w
    from ...process.mesh_deck import settling_time_transient
    from ...process.mesh_devices import DeviceSize, fit_mesh_bias
    from ...process.ngspice import ngspice_version

    t0 = time.perf_counter()
    spec = get_process(opts.pdk)
    corner_list = list(opts.corners or ["tt", "ff", "ss"])
    temp_list = [float(t) for t in (opts.temperatures_c or [27.0, 85.0])]
    if not corner_list or not temp_list:
        raise InputError("[realisations.mesh_process] corners and temperatures_c: at least one each")
    ideal = fit_resistive_mesh(target, pitch_m=opts.pitch_m) if opts.pitch_m else fit_resistive_mesh(target)
    size = DeviceSize(opts.device_w_m * 1e6, opts.device_l_m * 1e6)
    corner0, temp0 = corner_list[0], temp_list[0]
    bias = fit_mesh_bias(
        ideal, pdk=opts.pdk, corner=corner0, temperature_c=temp0, reference_v=opts.reference_v, size=size
    )
    window = ideal.kernel_taps(ideal.size)
    conditions, designs = [], []
    for corner in corner_list:
        for temp in temp_list:
            g = condition_conductances(bias, corner, float(temp))
            d = condition_design(ideal, g)
            conditions.append(
                ConditionResult(
                    corner,
                    float(temp),
                    g,
                    d.kernel_error(),
                    kernel_error(d.kernel_taps(ideal.size), window),
                    d.lambda_narrow_px,
                    d.lambda_wide_px,
                    d.tau_wide_s,
                ).to_dict()
            )
            designs.append(d)
    i = int(np.argmax([c["kernel_error"] for c in conditions])) if opts.scored == "worst" else 0
    mm = None
    if opts.mismatch_samples:
        mm = mismatch_kernels(
            ideal, bias, samples=opts.mismatch_samples, corner=corner0, temperature_c=temp0, seed=opts.seed + 1
        ).to_dict()
    g0 = conditions[0]["conductances_s"]
    settling = (
        settling_time_transient(bias, node_capacitance_f=ideal.node_capacitance_f, corner=corner0, temperature_c=temp0)
        if ideal.node_capacitance_f > 0
        else {}
    )
    return ProcessMeshDesign(
        mesh=designs[i],
        ideal=ideal,
        bias=bias.to_dict(),
        conditions=conditions,
        mismatch=mm,
        scored_label=f"{conditions[i]['corner']} {conditions[i]['temperature_c']:g} °C",
        area=_area(ideal, spec, size.w_um, size.l_um),
        settling_s=settling,
        power_w=mesh_power_w(g0["vertical_narrow"], g0["vertical_wide"], opts.supply_v or spec.supply_v, temp0),
        pdk=opts.pdk,
        tool=ngspice_version(),
        wall_s=time.perf_counter() - t0,
    )


#: Half-width of the transistor deck a design point writes (a 9×9 patch per mesh: 450 transistors).
ARTIFACT_HALF_WIDTH = 4


def write_process_mesh_artifacts(
    design: ProcessMeshDesign, out_dir: Any, *, resolution: tuple[int, int] | None = None
) -> tuple[Any, ...]:
    """Write ``mesh_sky130.cir`` (the transistor deck at the nominal corner, with its ``.lib`` line) and
    ``process_corners.csv`` (per-condition conductances and kernel errors, and the mismatch summary).

    ``resolution`` is accepted for the writer protocol and not used.
    """
    from pathlib import Path

    from ...paths import csv_text, write_output
    from ...process.mesh_deck import transistor_mesh_deck
    from ...process.mesh_devices import MeshBias
    from ..artifacts import Artifact

    if not isinstance(design, ProcessMeshDesign):
        raise InputError(f"write_process_mesh_artifacts: expected a ProcessMeshDesign, got {type(design).__name__}")
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    bias = MeshBias.from_dict(design.bias)
    c0 = design.conditions[0]
    deck = transistor_mesh_deck(
        bias, half_width=ARTIFACT_HALF_WIDTH, corner=c0["corner"], temperature_c=c0["temperature_c"]
    )
    cmd = "ngspice -b mesh_sky130.cir -r mesh_sky130.raw"
    deck = (
        f"* run: {cmd}   (i(von*), i(vow*) / 1e-12 A: each node's normalised output; change the .lib section for another corner)\n"
        + deck
    )
    write_output(out / "mesh_sky130.cir", deck, flag="artifacts")
    rows: list[list[object]] = [
        [
            "corner",
            "temperature_c",
            "g_lateral_narrow_s",
            "g_vertical_narrow_s",
            "g_lateral_wide_s",
            "g_vertical_wide_s",
            "kernel_error",
            "error_vs_ideal",
        ]
    ]
    for c in design.conditions:
        g = c["conductances_s"]
        rows.append(
            [
                c["corner"],
                c["temperature_c"],
                *(repr(g[k]) for k in ("lateral_narrow", "vertical_narrow", "lateral_wide", "vertical_wide")),
                repr(c["kernel_error"]),
                repr(c["error_vs_ideal"]),
            ]
        )
    if design.mismatch:
        m = design.mismatch
        for name in ("error_vs_nominal", "error_vs_target"):
            mean, lo, hi = m["ci"][name]
            rows.append(
                [
                    f"{m['corner']}_mm",
                    m["temperature_c"],
                    f"{m['samples']} samples",
                    f"seed {m['seed']}",
                    f"mismatch {name}",
                    "mean [95% CI]",
                    repr(mean),
                    f"[{lo!r}, {hi!r}]",
                ]
            )
    write_output(out / "process_corners.csv", csv_text(rows), flag="artifacts")
    n = 2 * ARTIFACT_HALF_WIDTH + 1
    return (
        Artifact(
            "transistor_deck",
            out / "mesh_sky130.cir",
            f"ngspice deck: both meshes as {design.pdk} transistors on a {n}x{n} patch, AC impulse",
            f"{cmd}; runs at tt, ff and ss (tests/test_process_mesh.py)",
        ),
        Artifact(
            "process_corners",
            out / "process_corners.csv",
            "conductances (S) and kernel errors per corner × temperature, mismatch mean and 95 % CI",
            "",
        ),
    )
