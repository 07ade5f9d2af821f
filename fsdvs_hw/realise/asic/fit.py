"""Quantised ASIC taps: the best integer kernel for a bit budget, its cost and its hardware.

A digital FS-DVS filter applies integer taps ``q`` to digitised pixels; the realised kernel is
``s * q`` with one scale ``s`` per kernel, either a power of two (a wire shift) or free (folded
into the event comparator's threshold). :func:`fit_asic_taps` finds ``(s, q)``:

1. **Symmetry.** The target is projected (least squares) onto the chosen symmetric subspace
   (``none``: k² free taps, ``quadrant``: (r+1)², ``8-fold``: (r+1)(r+2)/2 — 49, 16, 10 for 7×7).
2. **Scale (continuous).** For a free scale, nlopt's DIRECT-L global search over ``log2 s``
   minimises the objective of the best integer taps at that scale (step 3); the result is polished
   by alternating the least-squares scale of the taps with step 3 until the taps stop changing.
   A power-of-two scale is searched over every useful exponent.
3. **Taps (integer).** At a fixed scale the objective

   .. math:: J(q) = \\frac{\\lVert s\\,q - K\\rVert_2^2}{\\lVert K\\rVert_2^2} + \\lambda\\,A(q)

   (squared relative kernel error plus ``adder_weight`` λ times the adder count :math:`A`, with
   symmetric pre-adds when ``pre_add``) is a sum over symmetry classes, so it is minimised exactly
   class by class. For each class the optimum is among the nearest integers (above and below
   ``K_c / s``) that have at most ``d`` canonical-signed-digit (CSD) digits, for every ``d``:
   a handful of candidates instead of ``2**bits``. Ties go to fewer adders.
   With ``objective="csf"`` the error term is the CSF-weighted error of the 2-D frequency
   response — a quadratic form that couples the classes — and exact one-class moves are repeated
   until none improves (a coordinate-wise optimum).

The result, :class:`AsicDesign`, satisfies the realisation protocol (:mod:`fsdvs_hw.realise.base`):
``kernel()`` is ``s * q``; ``cost()`` gives adders, CSD digits, accumulator width and, after
:meth:`AsicDesign.synthesise`, yosys cells and area. :meth:`AsicDesign.apply` is the bit-exact
integer model (:func:`~fsdvs_hw.realise.asic.arith.integer_correlate`), and
:meth:`AsicDesign.verilog` / :meth:`AsicDesign.simulate` / :meth:`AsicDesign.synthesise` generate,
simulate (Icarus Verilog) and synthesise (yosys) the streaming RTL (:mod:`fsdvs_hw.realise.asic.rtl`).

References
----------
.. [J15] S. G. Johnson, The NLopt nonlinear-optimization package (DIRECT-L: J. M. Gablonsky and
   C. T. Kelley, "A locally-biased form of the DIRECT algorithm", J. Global Optim. 21 (2001) 27-37).
.. [H96] R. I. Hartley, "Subexpression sharing in filters using canonic signed digit
   multipliers", IEEE Trans. Circuits Syst. II 43 (1996) 677-688.
"""

from __future__ import annotations

import math
import time
from collections.abc import Mapping
from dataclasses import dataclass, field, replace
from functools import lru_cache
from typing import Any

import numpy as np

from ...errors import InputError
from ...kernels import Kernel, as_kernel
from ...validation import check_fit_arguments
from ..base import CostItem, kernel_error
from .arith import (
    SYMMETRIES,
    SymmetryClasses,
    accumulator_bits,
    adder_count,
    csd_weight,
    integer_correlate,
    output_bits,
    resolve_symmetry,
    symmetry_classes,
    tap_range,
)
from .options import AsicOptions

__all__ = ["OBJECTIVES", "SCALE_MODES", "AsicDesign", "exhaustive_asic_taps", "fit_asic_taps"]

#: Scale options: ``"free"`` (any positive real, folded into the comparator threshold) or
#: ``"pow2"`` (2**-e, a wire shift). A positive float fixes the scale (e.g. one LSB of the threshold).
SCALE_MODES: tuple[str, ...] = ("free", "pow2")

#: What the integer search minimises (besides λ · adders): the kernel error, or the CSF-weighted
#: frequency-response error.
OBJECTIVES: tuple[str, ...] = ("kernel", "csf")

_CSF_NFFT = 64
_DIRECT_MAXEVAL = 400


# ---------------------------------------------------------------------------- the design
@dataclass(frozen=True, eq=False)
class AsicDesign:
    """Integer taps and one scale: a kernel built as a shift-add digital filter.

    Parameters
    ----------
    target : Kernel
        The kernel that was fitted.
    taps : ndarray of int64, shape (k, k)
        Signed integer taps, ``-2**(bits-1) ≤ q ≤ 2**(bits-1) - 1`` (two's complement), constant on each symmetry class.
    scale : float
        Realised kernel = ``scale * taps`` (dimensionless gain per pixel per integer step).
    scale_mode : {"free", "pow2", "fixed"}
        How the scale was chosen; ``pow2`` means ``scale == 2**-scale_exponent``.
    bits : int
        Tap width, sign included (2…24).
    symmetry : {"none", "quadrant", "8-fold"}
        Symmetry imposed on the taps (the RTL pre-adds each class when ``pre_add``).
    input_bits : int
        Unsigned pixel width the accumulator is sized for (1…32).
    pre_add : bool
        Whether pixels of one symmetry class are summed before the constant multiplication.
    adder_weight : float
        λ used in the fit (price of one adder in squared relative kernel error).
    fit_info : dict
        Diagnostics of the fit (continuous scale, evaluations, run time, naive-scale error).
    synthesis : dict, optional
        yosys results from :meth:`synthesise` (cells, area, image width, run time).
    process : dict, optional
        The taps built in a real process by :meth:`build_in_process` (sky130: cells, area, the
        highest clock from static timing, energy per pixel from gate-level toggles, each with its
        source; :class:`~fsdvs_hw.realise.asic.sky130_flow.TapsInProcess`).

    Examples
    --------
    >>> import numpy as np
    >>> from fsdvs_hw import fit_asic_taps
    >>> d = fit_asic_taps(np.array([[-0.1, -0.1, -0.1], [-0.1, 1.0, -0.1], [-0.1, -0.1, -0.1]]), bits=6)
    >>> d.kernel().size, list(d.cost())[:2]
    (3, ['adders', 'adders_per_tap'])
    """

    target: Kernel
    taps: np.ndarray
    scale: float
    scale_mode: str
    bits: int
    symmetry: str
    input_bits: int = 8
    pre_add: bool = True
    adder_weight: float = 0.0
    fit_info: Mapping[str, Any] = field(default_factory=dict)
    synthesis: Mapping[str, Any] | None = None
    process: Mapping[str, Any] | None = None
    kind: str = field(default="asic", init=False)

    def __post_init__(self) -> None:
        q = np.asarray(self.taps)
        if q.shape != self.target.taps.shape or not np.issubdtype(q.dtype, np.integer):
            raise InputError(
                f"taps: must be an integer array of shape {self.target.taps.shape}, got {q.dtype} {q.shape}"
            )
        q = q.astype(np.int64).copy()
        q.setflags(write=False)
        object.__setattr__(self, "taps", q)
        lo, hi = tap_range(self.bits)
        if q.min() < lo or q.max() > hi:
            raise InputError(
                f"taps: {lo} ≤ q ≤ {hi} for bits={self.bits} (two's complement), got {int(q.min())}..{int(q.max())}"
            )
        if not np.any(q):
            raise InputError("taps: all integer taps are zero; the design would pass nothing")
        if not (math.isfinite(self.scale) and self.scale > 0):
            raise InputError(f"scale: must be a positive finite number, got {self.scale!r}")
        if self.symmetry not in SYMMETRIES:
            raise InputError(f"symmetry: {self.symmetry!r} unknown; allowed: {', '.join(SYMMETRIES)}")
        cls = symmetry_classes(q.shape[0], self.symmetry)
        if not np.array_equal(cls.expand(q[tuple(np.array(cls.representatives).T)]), q):
            raise InputError(f"taps: not {self.symmetry}-symmetric")
        accumulator_bits(q, self.input_bits)  # validates input_bits and the int64 range

    # ------------------------------------------------------------------ protocol
    def kernel(self) -> Kernel:
        """The kernel really applied: ``scale * taps`` at the target's pixel pitch."""
        return self.target.with_taps(
            self.scale * self.taps.astype(np.float64),
            name=f"{self.target.name} asic{self.bits}b",
            realisation="asic",
            bits=int(self.bits),
        )

    @property
    def classes(self) -> SymmetryClasses:
        """Symmetry classes of the taps."""
        return symmetry_classes(self.taps.shape[0], self.symmetry)

    @property
    def error(self) -> float:
        """Relative L2 error of the realised kernel against the target (absolute scale)."""
        return kernel_error(self.kernel(), self.target)

    @property
    def shape_error(self) -> float:
        """Relative L2 error after the least-squares gain (shape only; the gain is free in the threshold)."""
        return kernel_error(self.kernel(), self.target, fit_scale=True)

    @property
    def adders(self) -> int:
        """Adders of the realised architecture (symmetric pre-adds when ``pre_add``)."""
        return adder_count(self.taps, self.classes if self.pre_add else None)

    @property
    def adders_per_tap(self) -> int:
        """Adders with every tap multiplied separately (no pre-adds)."""
        return adder_count(self.taps)

    @property
    def accumulator_bits(self) -> int:
        """Signed accumulator width that cannot overflow for ``input_bits``-bit pixels."""
        return accumulator_bits(self.taps, self.input_bits)

    def output_bits(self, out_shift: int = 0) -> int:
        """Signed output width after a rounding right shift by ``out_shift``."""
        return output_bits(self.taps, self.input_bits, out_shift)

    def cost(self) -> dict[str, CostItem]:
        """Hardware cost: adders, CSD digits, taps, widths and (when synthesised) cells and area."""
        q = self.taps
        c: dict[str, CostItem] = {
            "adders": CostItem(
                self.adders,
                "count",
                "two-input adders/subtractors" + (" with symmetric pre-adds" if self.pre_add else ""),
            ),
            "adders_per_tap": CostItem(
                self.adders_per_tap, "count", "adders with every tap multiplied on its own (CSD)"
            ),
            "csd_digits": CostItem(int(csd_weight(q).sum()), "count", "non-zero CSD digits over all taps"),
            "nonzero_taps": CostItem(int(np.count_nonzero(q)), "count", "taps that are not zero"),
            "distinct_coefficients": CostItem(
                int(np.count_nonzero(q[tuple(np.array(self.classes.representatives).T)])),
                "count",
                "non-zero coefficients after symmetry",
            ),
            "tap_bits": CostItem(self.bits, "bit", "signed tap width"),
            "accumulator_bits": CostItem(
                self.accumulator_bits, "bit", f"signed accumulator for {self.input_bits}-bit unsigned pixels"
            ),
        }
        if self.synthesis:
            s = self.synthesis
            c["yosys_cells"] = CostItem(
                s["cells"], "count", f"yosys cells ({s['liberty']}, {s['image_width']}-pixel lines)"
            )
            c["flip_flops"] = CostItem(s["flip_flops"], "count", "flip-flops (line buffers, window, output)")
            c["area_m2"] = CostItem(
                s["area_m2"], "m^2", f"cell area from the liberty file ({s['liberty']}, area unit µm²)"
            )
            c["datapath_cells"] = CostItem(
                s["datapath_cells"], "count", "yosys cells of the arithmetic alone (no line buffers)"
            )
            c["datapath_area_m2"] = CostItem(s["datapath_area_m2"], "m^2", "cell area of the arithmetic alone")
        if self.process:
            c.update(_process_items(self.process))
        return c

    def describe(self) -> str:
        scale = f"2^-{self.fit_info.get('scale_exponent')}" if self.scale_mode == "pow2" else f"{self.scale:.6g}"
        lines = [
            f"asic: {self.bits}-bit integer taps ({self.symmetry} symmetry) for '{self.target.name}', scale {scale} ({self.scale_mode}), "
            f"objective {self.fit_info.get('objective_name', 'kernel')}, λ = {self.adder_weight:g}",
            f"  kernel error {self.error:.4g} (relative L2), shape error {self.shape_error:.4g} (gain fitted)",
            f"  adders {self.adders} ({'symmetric pre-adds' if self.pre_add else 'per tap'}; {self.adders_per_tap} per tap), "
            f"CSD digits {int(csd_weight(self.taps).sum())}, accumulator {self.accumulator_bits} bits for {self.input_bits}-bit pixels",
        ]
        if self.synthesis:
            s = self.synthesis
            lines.append(
                f"  yosys: {s['cells']} cells, {s['flip_flops']} flip-flops, area {s['area_m2'] * 1e12:.1f} µm² "
                f"({s['liberty']}, {s['image_width']}-pixel lines); arithmetic alone {s['datapath_cells']} cells, "
                f"{s['datapath_area_m2'] * 1e12:.1f} µm²"
            )
        if self.process:
            p = self.process
            lines.append(
                f"  {p['pdk']} {p['corner']} {p['temperature_c']:g} °C: {p['cells']} cells ({p['full_adders']} full adders), "
                f"{p['area_m2'] * 1e12:.0f} µm² for {p['frame'][0]}x{p['frame'][1]} frames, max clock "
                f"{p['max_clock_hz'] / 1e6:.1f} MHz (OpenSTA), {p['energy_per_pixel_j'] * 1e12:.3g} pJ/pixel (toggles)"
            )
        return "\n".join(lines)

    def to_dict(self) -> dict[str, Any]:
        return {
            "kind": self.kind,
            "target": self.target.to_dict(),
            "taps": self.taps.tolist(),
            "scale": float(self.scale),
            "scale_mode": self.scale_mode,
            "bits": int(self.bits),
            "symmetry": self.symmetry,
            "input_bits": int(self.input_bits),
            "pre_add": bool(self.pre_add),
            "adder_weight": float(self.adder_weight),
            "fit_info": dict(self.fit_info),
            "synthesis": None if self.synthesis is None else dict(self.synthesis),
        } | ({} if self.process is None else {"process": dict(self.process)})

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> AsicDesign:
        missing = [k for k in ("target", "taps", "scale", "scale_mode", "bits", "symmetry") if k not in data]
        if missing:
            raise InputError(f"asic design: missing field(s) {', '.join(missing)}")
        return cls(
            target=Kernel.from_dict(data["target"], source="asic design: field 'target'"),
            taps=np.asarray(data["taps"], dtype=np.int64),
            scale=float(data["scale"]),
            scale_mode=str(data["scale_mode"]),
            bits=int(data["bits"]),
            symmetry=str(data["symmetry"]),
            input_bits=int(data.get("input_bits", 8)),
            pre_add=bool(data.get("pre_add", True)),
            adder_weight=float(data.get("adder_weight", 0.0)),
            fit_info=dict(data.get("fit_info", {})),
            synthesis=data.get("synthesis"),
            process=data.get("process"),
        )

    # ------------------------------------------------------------------ hardware
    def apply(self, image: np.ndarray, *, out_shift: int = 0) -> np.ndarray:
        """The bit-exact integer model on ``input_bits``-bit pixels (see :func:`~fsdvs_hw.realise.asic.arith.integer_correlate`)."""
        return integer_correlate(image, self.taps, input_bits=self.input_bits, out_shift=out_shift)

    def verilog(
        self, *, image_width: int, image_height: int, out_shift: int = 0, module_name: str = "fsdvs_conv"
    ) -> str:
        """Synthesisable Verilog of the streaming filter (see :func:`~fsdvs_hw.realise.asic.rtl.generate_verilog`)."""
        from .rtl import generate_verilog

        return generate_verilog(
            self.taps,
            input_bits=self.input_bits,
            image_width=image_width,
            image_height=image_height,
            out_shift=out_shift,
            symmetry=self.symmetry if self.pre_add else "none",
            module_name=module_name,
        )

    def simulate(self, images: np.ndarray, *, out_shift: int = 0) -> np.ndarray:
        """Run the generated RTL in Icarus Verilog on ``images`` (N, H, W); returns the outputs."""
        from .rtl import simulate_rtl

        return simulate_rtl(
            self.taps,
            images,
            input_bits=self.input_bits,
            out_shift=out_shift,
            symmetry=self.symmetry if self.pre_add else "none",
        )

    def synthesise(self, *, image_width: int = 16, image_height: int = 16, out_shift: int = 0) -> AsicDesign:
        """Synthesise the RTL with yosys and the shipped liberty file; returns a copy with ``synthesis`` set."""
        from .rtl import generate_datapath_verilog, synthesise_verilog

        src = self.verilog(image_width=image_width, image_height=image_height, out_shift=out_shift)
        rep = synthesise_verilog(src, top="fsdvs_conv")
        dp = synthesise_verilog(
            generate_datapath_verilog(
                self.taps,
                input_bits=self.input_bits,
                out_shift=out_shift,
                symmetry=self.symmetry if self.pre_add else "none",
            ),
            top="fsdvs_datapath",
        )
        return replace(
            self,
            synthesis={
                **rep.to_dict(),
                "image_width": int(image_width),
                "image_height": int(image_height),
                "datapath_cells": dp.cells,
                "datapath_area_m2": dp.area_m2,
                "datapath_flip_flops": dp.flip_flops,
            },
        )

    def build_in_process(
        self, pdk: str = "sky130", *, frame: tuple[int, int] = (48, 64), corners: tuple[str, ...] = ("tt",)
    ) -> AsicDesign:
        """Build the taps in a real process; returns a copy with ``process`` set.

        sky130: synthesis onto sky130_fd_sc_hd, gate-level simulation checked bit-exactly against
        :meth:`apply` on real frames, OpenSTA's highest clock and the toggle energy
        (:func:`~fsdvs_hw.realise.asic.sky130_flow.build_taps_sky130`). The netlist and the timing
        report stay on the copy for the artifacts (:attr:`built`), not in :meth:`to_dict`.
        """
        if pdk != "sky130":
            raise InputError(f"pdk: {pdk!r} has no standard-cell flow; allowed: 'sky130'")
        from .sky130_flow import build_taps_sky130

        built = build_taps_sky130(self, frame=frame, corners=corners)
        out = replace(self, process=built.figures)
        object.__setattr__(out, "_built", built)
        return out

    @property
    def built(self) -> Any:
        """The :class:`~fsdvs_hw.realise.asic.sky130_flow.TapsInProcess` of :meth:`build_in_process` (None if not built here)."""
        return getattr(self, "_built", None)


def _process_items(p: Mapping[str, Any]) -> dict[str, CostItem]:
    """Cost items of a design built in a process (:meth:`AsicDesign.build_in_process`)."""
    src = p["sources"]
    frame = f"{p['frame'][0]}x{p['frame'][1]}"
    return {
        "yosys_cells": CostItem(p["cells"], "count", f"{p['pdk']} standard cells ({frame} frames)"),
        "flip_flops": CostItem(p["flip_flops"], "count", f"{p['pdk']} flip-flops (line buffers, window, output)"),
        "full_adders": CostItem(p["full_adders"], "count", f"{p['pdk']} full-adder cells (extract_fa)"),
        "area_m2": CostItem(p["area_m2"], "m^2", src["area_m2"]),
        "datapath_area_m2": CostItem(p["datapath_area_m2"], "m^2", src["datapath_area_m2"]),
        "flip_flop_area_m2": CostItem(p["flip_flop_area_m2"], "m^2", src["flip_flop_area_m2"]),
        "process_frame_width": CostItem(p["frame"][1], "px", f"{p['pdk']} build's line length (pixels)"),
        "max_clock_hz": CostItem(p["max_clock_hz"], "Hz", src["max_clock_hz"]),
        "energy_per_pixel_j": CostItem(p["energy_per_pixel_j"], "J", src["energy_per_pixel_j"]),
    }


# ---------------------------------------------------------------------------- the fit
#: Up to this tap width the per-class candidates are exact (every integer with ≤ d CSD digits is
#: enumerated once); wider taps use truncated CSD expansions (see :meth:`_TapProblem.solve`).
_EXACT_BITS = 16


def _csd_truncations(n: np.ndarray, n_digits: int) -> np.ndarray:
    """For each integer in ``n``: its CSD expansion truncated to the top 0, 1, …, ``n_digits`` digits.

    Returns an array of shape ``n.shape + (n_digits + 1,)``.
    """
    v = np.asarray(n, dtype=np.int64).copy()
    planes = []
    while np.any(v != 0):  # non-adjacent form, least significant digit first
        d = np.where(v & 1, 2 - (v & 3), 0)
        planes.append(d)
        v = (v - d) >> 1
    if not planes:
        return np.zeros(v.shape + (n_digits + 1,), dtype=np.int64)
    D = np.stack(planes[::-1], axis=-1)  # most significant first
    w = 1 << np.arange(len(planes) - 1, -1, -1, dtype=np.int64)
    rank = np.cumsum(D != 0, axis=-1)
    return np.stack([(D * (rank <= k) * w).sum(axis=-1) for k in range(n_digits + 1)], axis=-1)


@lru_cache(maxsize=32)
def _candidate_sets(bits: int) -> tuple[np.ndarray, ...]:
    """For d = 0, 1, …: sorted integers in [-2**(bits-1), 2**(bits-1) - 1] with at most d CSD digits."""
    lo, hi = tap_range(bits)
    v = np.arange(lo, hi + 1, dtype=np.int64)
    w = csd_weight(v)
    return tuple(v[w <= d] for d in range(int(w.max()) + 1))


class _TapProblem:
    """The integer problem in class space: J(q, s) = (s² qᵀMq − 2s qᵀb + c)/c + λ·adders(q).

    ``objective="kernel"``: ``M = diag(m_c)``, ``b = m_c K̄_c``, ``c = ‖K‖²`` (separable, solved
    exactly class by class). ``weights`` (a frequency weighting, e.g. a CSF) make ``M`` the
    weighted Gram matrix of the classes' spectra; the solve is then exact coordinate descent.
    """

    def __init__(
        self,
        target: np.ndarray,
        classes: SymmetryClasses,
        bits: int,
        adder_weight: float,
        pre_add: bool,
        weights: np.ndarray | None = None,
        n_fft: int = 0,
    ):
        self.t = target
        self.cls = classes
        self.m = classes.sizes.astype(np.float64)
        self.tbar = classes.class_means(target)
        self.norm2 = float((target * target).sum())
        # energy lost by the symmetric projection (a constant of the problem)
        self.proj2 = float(((target - classes.expand(self.tbar)) ** 2).sum())
        self.lo, self.hi = tap_range(bits)
        self.lim = self.hi  # largest positive tap
        self.bits = bits
        self.sets = _candidate_sets(bits) if bits <= _EXACT_BITS else None
        self.lam = float(adder_weight)
        self.pre_add = pre_add
        self.diagonal = weights is None
        if weights is None:
            self.M = np.diag(self.m)
            self.b = self.m * self.tbar
            self.c = self.norm2
        else:
            k = target.shape[0]
            r = k // 2
            f = np.fft.fftfreq(n_fft)
            pos = np.arange(-r, r + 1)
            F1 = np.exp(-2j * np.pi * np.outer(f, pos))  # (n_fft, k) one axis
            # spectrum of each pixel basis vector: F[fy, fx, y, x] = F1[fy, y] F1[fx, x]
            E = np.stack([(classes.labels == c) for c in range(classes.n_classes)], axis=-1).astype(np.float64)
            A = np.einsum("ay,bx,yxc->abc", F1, F1, E).reshape(n_fft * n_fft, -1)
            T = np.einsum("ay,bx,yx->ab", F1, F1, target).ravel()
            w2 = (np.asarray(weights, dtype=np.float64) ** 2).ravel()
            self.M = np.real(A.conj().T @ (w2[:, None] * A))
            self.b = np.real(A.conj().T @ (w2 * T))
            self.c = float(np.sum(w2 * np.abs(T) ** 2))

    def class_cost(self, q: np.ndarray) -> np.ndarray:
        """Adders attributable to each class value (classes on axis 0; the global −1 is a constant)."""
        w = csd_weight(q).astype(np.float64)
        m = self.m.reshape((-1,) + (1,) * (q.ndim - 1))
        if self.pre_add:
            return np.where(q != 0, m - 1.0 + w, 0.0)
        return m * w

    def error2(self, q: np.ndarray, s: float) -> float:
        """The (weighted) squared relative error of ``s q``."""
        if self.diagonal:  # direct form: no cancellation for tiny errors
            return (float((self.m * (s * q - self.tbar) ** 2).sum()) + self.proj2) / self.norm2
        qf = q.astype(np.float64)
        return max((s * s * float(qf @ self.M @ qf) - 2 * s * float(qf @ self.b) + self.c) / self.c, 0.0)

    def objective(self, q: np.ndarray, s: float) -> float:
        """J(q) at scale s (squared relative error + λ · adders)."""
        return self.error2(q, s) + self.lam * self.adders(q)

    def _candidates(self, u: np.ndarray) -> np.ndarray:
        """Per class (rows), the integers that can be optimal near the continuous value ``u``.

        Exact for ``bits ≤ 16``: for every digit count d the nearest integers above and below
        ``u`` with at most d CSD digits. Wider taps: the nearest integers and the truncations of
        their CSD expansions to 0, 1, 2, … digits (exact for λ = 0).
        """
        if self.sets is not None:
            cands = []
            for S in self.sets:
                i = np.searchsorted(S, u)
                cands.append(S[np.clip(i - 1, 0, S.size - 1)])
                cands.append(S[np.clip(i, 0, S.size - 1)])
            return np.stack(cands, axis=1)
        near = np.clip(np.stack([np.floor(u), np.ceil(u)], axis=1), self.lo, self.hi).astype(np.int64)
        return _csd_truncations(near, (self.bits + 2) // 2).reshape(near.shape[0], -1)

    def _pick(self, u: np.ndarray, w2: np.ndarray, cls_idx: np.ndarray) -> np.ndarray:
        """argmin over candidates of w2 (C − u)² + λ cost, ties to fewer adders."""
        C = self._candidates(u)
        cost = self.class_cost(C) if cls_idx.size == self.m.size else self._cost_rows(C, cls_idx)
        score = w2[:, None] * (C - u[:, None]) ** 2 + self.lam * cost
        best = score.min(axis=1, keepdims=True)
        tie = score <= best + 1e-12 * np.maximum(best, 1e-300)
        pick = np.argmin(np.where(tie, cost, np.inf), axis=1)
        return C[np.arange(C.shape[0]), pick]

    def _cost_rows(self, C: np.ndarray, cls_idx: np.ndarray) -> np.ndarray:
        w = csd_weight(C).astype(np.float64)
        m = self.m[cls_idx][:, None]
        return np.where(C != 0, m - 1.0 + w, 0.0) if self.pre_add else m * w

    def solve(self, s: float) -> np.ndarray:
        """Minimiser of J over integer class values at fixed scale ``s``.

        Kernel objective: exact, class by class (the problem is separable). Weighted objective:
        start from the rounded continuous optimum, then exact one-class moves (each class's
        sub-problem is a 1-D quadratic plus digits, solved over the same candidates) until none
        improves — a coordinate-wise optimum.
        """
        idx = np.arange(self.m.size)
        if self.diagonal:
            return self._pick(self.tbar / s, s * s * self.m / self.norm2, idx)
        try:
            u0 = np.linalg.solve(self.M, self.b) / s
        except np.linalg.LinAlgError:
            u0 = self.b / (s * np.diag(self.M))
        q = self._pick(np.clip(u0, self.lo, self.hi), s * s * np.diag(self.M) / self.c, idx)
        Md = np.diag(self.M)
        for _ in range(50):
            changed = False
            for c in idx:
                if Md[c] <= 0:
                    continue
                rest = float(self.M[c] @ q) - Md[c] * q[c]
                u = np.array([(self.b[c] / s - rest) / Md[c]])
                new = self._pick(u, np.array([s * s * Md[c] / self.c]), np.array([c]))[0]
                if new != q[c]:  # the 1-D pick is exact, so the move never increases J
                    q = q.copy()
                    q[c] = new
                    changed = True
            if not changed:
                break
        return q

    def adders(self, q: np.ndarray) -> float:
        return max(float(self.class_cost(q).sum()) - 1.0, 0.0)

    def better(self, J: float, q: np.ndarray, best: Mapping[str, Any]) -> bool:
        """True if (J, adders) beats ``best`` (ties in J, to 1e-12 relative, go to fewer adders)."""
        Jb = best.get("J", math.inf)
        if Jb - 1e-12 * abs(Jb) > J or not math.isfinite(Jb):
            return True
        return Jb + 1e-12 * abs(Jb) >= J and self.adders(q) < self.adders(best["q"])

    def ls_scale(self, q: np.ndarray) -> float | None:
        qf = q.astype(np.float64)
        den = float(qf @ self.M @ qf)
        if den <= 0:
            return None
        s = float(qf @ self.b) / den
        return s if s > 0 else None


def _csf_weights(kernel: Kernel, method: str, geometry: Any) -> tuple[np.ndarray, float]:
    """CSF weight on the 64×64 DFT grid (peak 1) and the pixels per degree used."""
    from ...csf import Geometry, contrast_sensitivity, csf_agreement

    if geometry is None:
        ppd = csf_agreement(kernel, method=method).pixels_per_degree
    elif isinstance(geometry, Geometry):
        ppd = geometry.pixels_per_degree
    else:
        raise InputError(f"geometry: expected a fsdvs_hw.csf.Geometry or None, got {type(geometry).__name__}")
    f = np.fft.fftfreq(_CSF_NFFT)
    fr = np.hypot(f[:, None], f[None, :])
    w = np.asarray(contrast_sensitivity(fr * ppd, method=method), dtype=np.float64)
    if not (np.all(np.isfinite(w)) and w.max() > 0):
        raise InputError(f"csf_method {method!r} gave no usable weights at {ppd:.3g} pixels/degree")
    return w / w.max(), float(ppd)


def _polish(p: _TapProblem, s: float, q: np.ndarray) -> tuple[float, np.ndarray]:
    """Alternate the least-squares scale of ``q`` and the integer solve at it (J never increases)."""
    for _ in range(50):
        s_ls = p.ls_scale(q)
        if s_ls is None:
            break
        q_new = p.solve(s_ls)
        if p.objective(q, s_ls) <= p.objective(q_new, s_ls):
            if p.objective(q, s_ls) <= p.objective(q, s):
                s = s_ls
            break
        s, q = s_ls, q_new
    return s, q


def _fit_free_scale(p: _TapProblem, amax: float, n_polish: int = 5) -> tuple[float, np.ndarray, dict[str, Any]]:
    import nlopt

    lo, hi = math.log2(amax / (2.0 * (p.hi + 1))), math.log2(2.0 * amax)
    seen: dict[bytes, tuple[float, float, np.ndarray]] = {}  # distinct taps -> (J, s, q)

    def f(x: np.ndarray, grad: np.ndarray) -> float:
        s = 2.0 ** float(x[0])
        q = p.solve(s)
        J = p.objective(q, s)
        key = q.tobytes()
        if key not in seen or seen[key][0] > J:
            seen[key] = (J, s, q)
        return J

    # seed: the naive scale (largest tap on the full two's-complement range), so the search never
    # ends worse than plain rounding
    naive = max(float(p.tbar.max()) / p.hi, -float(p.tbar.min()) / -p.lo)
    f(np.array([math.log2(naive)]), np.empty(0))
    opt = nlopt.opt(nlopt.GN_DIRECT_L, 1)
    opt.set_lower_bounds([lo])
    opt.set_upper_bounds([hi])
    opt.set_min_objective(f)
    opt.set_maxeval(_DIRECT_MAXEVAL if p.diagonal else _DIRECT_MAXEVAL // 4)
    opt.set_xtol_abs(1e-9)
    try:
        opt.optimize([0.5 * (lo + hi)])
    except nlopt.RoundoffLimited:  # the points evaluated so far are kept in `seen`
        pass
    evals = opt.get_numevals()
    # polish the best few distinct tap vectors (the polish is local) and keep the best result
    starts = sorted(seen.values(), key=lambda v: v[0])[:n_polish]
    best: dict[str, Any] = {"J": math.inf}
    for _J0, s0, q0 in starts:
        for s_c, q_c in ((s0, q0), _polish(p, s0, q0)):
            J = p.objective(q_c, s_c)
            if p.better(J, q_c, best):
                best.update(J=J, s=s_c, q=q_c)
    return (
        best["s"],
        best["q"],
        {"nlopt_algorithm": "GN_DIRECT_L", "nlopt_evaluations": int(evals), "scale_direct": float(starts[0][1])},
    )


def _divide_common_factor(
    p: _TapProblem, q: np.ndarray, s: float, *, powers_of_two_only: bool
) -> tuple[np.ndarray, float]:
    """Divide the taps by the common factor that leaves the fewest adders (same realised kernel)."""
    g = int(np.gcd.reduce(np.abs(q[q != 0])))
    if g <= 1:
        return q, s
    divs = {d for i in range(1, math.isqrt(g) + 1) if g % i == 0 for d in (i, g // i)}
    if powers_of_two_only:
        divs = {d for d in divs if d & (d - 1) == 0}
    best = min(sorted(divs, reverse=True), key=lambda d: p.adders(q // d))
    return q // best, s * best


def fit_asic_taps(
    kernel: Kernel | Any,
    bits: int = 8,
    *,
    pitch_m: float | None = None,
    symmetry: str = "auto",
    scale: str | float = "free",
    adder_weight: float = 0.0,
    input_bits: int = 8,
    pre_add: bool = True,
    objective: str = "kernel",
    csf_method: str = "mannos_sakrison_1974",
    geometry: Any = None,
    pdk: str | None = None,
    pdk_frame: tuple[int, int] = (48, 64),
    corners: tuple[str, ...] | list[str] = ("tt",),
) -> AsicDesign:
    """Fit integer taps and one scale to a kernel (see the module docstring for the method).

    The options are validated once, at entry, into an :class:`~fsdvs_hw.realise.asic.AsicOptions`
    (the same model and rules a design file's ``[realisations.asic]`` table is checked against)
    that the fit reads.

    Parameters
    ----------
    kernel : Kernel or array_like
        Target kernel: a :class:`~fsdvs_hw.kernels.Kernel`, a kernel file or odd k×k taps (see
        :func:`~fsdvs_hw.kernels.as_kernel`).
    bits, pitch_m, symmetry, scale, adder_weight, input_bits, pre_add, objective, csf_method, geometry, pdk, pdk_frame, corners
        The fit's options: each one's type, unit, range, default and meaning, and the rules between
        them, are those of :class:`~fsdvs_hw.realise.asic.AsicOptions`.

    Returns
    -------
    AsicDesign

    Raises
    ------
    InputError
        Bad arguments; a fixed scale or an adder weight at which every tap rounds to zero;
        an ``input_bits`` whose accumulator would exceed the exact 63-bit model.

    Examples
    --------
    >>> import numpy as np
    >>> from fsdvs_hw import fit_asic_taps
    >>> d = fit_asic_taps(np.array([[-0.1, -0.1, -0.1], [-0.1, 1.0, -0.1], [-0.1, -0.1, -0.1]]), bits=6)
    >>> d.taps, d.scale
    (array([[-1, -1, -1],
           [-1, 10, -1],
           [-1, -1, -1]]), 0.1)
    >>> d.apply(np.full((5, 5), 100)).tolist()     # the bit-exact integer model, valid-mode output
    [[200, 200, 200], [200, 200, 200], [200, 200, 200]]
    """
    o = check_fit_arguments(AsicOptions, locals())
    t0 = time.perf_counter()
    kernel = o.target
    lo_q, lim = tap_range(o.bits)
    sym = resolve_symmetry(kernel.taps, o.symmetry)
    cls = symmetry_classes(kernel.size, sym)
    weights, ppd = (None, None) if o.objective == "kernel" else _csf_weights(kernel, o.csf_method, o.geometry)
    p = _TapProblem(kernel.taps, cls, o.bits, o.adder_weight, o.pre_add, weights=weights, n_fft=_CSF_NFFT)
    amax = float(np.abs(p.tbar).max())
    # the naive scale uses the full two's-complement range: -2**(bits-1) for the most negative tap
    naive_s = max(float(p.tbar.max()) / lim, -float(p.tbar.min()) / -lo_q)
    naive_q = cls.expand(np.clip(np.round(p.tbar / naive_s), lo_q, lim))
    info: dict[str, Any] = {
        "naive_scale": naive_s,
        "naive_error": kernel_error(naive_s * naive_q, kernel),
        "objective_name": o.objective,
    }
    if ppd is not None:
        info.update(csf_method=o.csf_method, pixels_per_degree=ppd)
    s, q, mode = _fit_scale(p, o.scale, amax, lim, info)
    if not np.any(q):
        why = (
            f"at the fixed scale {s:.4g} (largest tap {amax:.4g} is below half a step)"
            if mode == "fixed"
            else f"with adder_weight={o.adder_weight:g} (an adder costs more than the whole kernel error)"
        )
        raise InputError(f"kernel '{kernel.name}' rounds to all-zero {o.bits}-bit taps {why}")
    info["fit_time_s"] = time.perf_counter() - t0
    info["objective"] = p.objective(q, s)
    design = AsicDesign(
        target=kernel,
        taps=cls.expand(q).astype(np.int64),
        scale=float(s),
        scale_mode=mode,
        bits=o.bits,
        symmetry=sym,
        input_bits=o.input_bits,
        pre_add=o.pre_add,
        adder_weight=o.adder_weight,
        fit_info=info,
    )
    if o.pdk is None:
        return design
    return design.build_in_process(o.pdk, frame=(int(o.pdk_frame[0]), int(o.pdk_frame[1])), corners=tuple(o.corners))


def _fit_scale(
    p: _TapProblem, scale: str | float, amax: float, lim: int, info: dict[str, Any]
) -> tuple[float, np.ndarray, str]:
    """The scale and class taps of one ``scale`` option (``"free"``, ``"pow2"`` or a fixed number);
    returns ``(s, q, mode)`` and records the search in ``info``. A free or power-of-two scale has
    the taps' common factor that leaves the fewest adders folded into it."""
    if scale == "free":
        s, q, extra = _fit_free_scale(p, amax)
        info.update(extra)
        mode = "free"
    elif scale == "pow2":
        e_lo = math.floor(-math.log2(2.0 * amax))
        e_hi = math.ceil(math.log2(2.0 * (lim + 1) / amax))
        best: dict[str, Any] = {"J": math.inf}
        for e in range(e_lo, e_hi + 1):
            qe = p.solve(2.0**-e)
            J = p.objective(qe, 2.0**-e)
            if p.better(J, qe, best):
                best.update(J=J, e=e, q=qe)
        e, q = best["e"], best["q"]
        s, mode = 2.0**-e, "pow2"
        info["scale_exponent"] = int(e)
    else:
        s = float(scale)
        q, mode = p.solve(s), "fixed"
    if mode != "fixed" and np.any(q):
        q, s = _divide_common_factor(p, q, s, powers_of_two_only=(mode == "pow2"))
        if mode == "pow2":
            info["scale_exponent"] = int(round(-math.log2(s)))
    return s, q, mode


def exhaustive_asic_taps(
    kernel: Kernel | Any,
    bits: int,
    *,
    symmetry: str,
    adder_weight: float = 0.0,
    pre_add: bool = True,
    objective: str = "kernel",
    geometry: Any = None,
    csf_method: str = "mannos_sakrison_1974",
    max_combinations: int = 2_000_000,
) -> tuple[np.ndarray, float, float]:
    """Brute-force optimum over every integer tap vector, each with its least-squares free scale.

    The test oracle of :func:`fit_asic_taps` (``scale="free"``) on tiny problems: enumerates all
    ``(2**bits) ** n_classes`` class values (the full two's-complement range).

    Returns
    -------
    (taps, scale, objective)
    """
    kernel = as_kernel(kernel)
    sym = resolve_symmetry(kernel.taps, symmetry)
    cls = symmetry_classes(kernel.size, sym)
    if objective not in OBJECTIVES:
        raise InputError(f"objective: {objective!r} unknown; allowed: {', '.join(OBJECTIVES)}")
    weights = None if objective == "kernel" else _csf_weights(kernel, csf_method, geometry)[0]
    p = _TapProblem(kernel.taps, cls, int(bits), float(adder_weight), bool(pre_add), weights=weights, n_fft=_CSF_NFFT)
    n = cls.n_classes
    vals = np.arange(p.lo, p.hi + 1, dtype=np.int64)
    if vals.size**n > max_combinations:
        raise InputError(
            f"exhaustive search over {vals.size}^{n} tap vectors exceeds max_combinations={max_combinations}"
        )
    Q = np.stack(np.meshgrid(*([vals] * n), indexing="ij"), axis=-1).reshape(-1, n)
    Q = Q[np.any(Q != 0, axis=1)]
    Qf = Q.astype(np.float64)
    num = Qf @ p.b
    den = np.einsum("ni,ij,nj->n", Qf, p.M, Qf)
    s = num / den
    ok = s > 0
    Q, Qf, s = Q[ok], Qf[ok], s[ok]
    if p.diagonal:
        err2 = ((p.m * (s[:, None] * Q - p.tbar) ** 2).sum(axis=1) + p.proj2) / p.norm2
    else:  # at the least-squares scale the weighted error is 1 - (qᵀb)² / (qᵀMq · c)
        err2 = np.maximum(1.0 - num[ok] ** 2 / (den[ok] * p.c), 0.0)
    cost = p.class_cost(Q.T).sum(axis=0)
    J = err2 + p.lam * np.maximum(cost - 1.0, 0.0)
    i = int(np.argmin(J))
    return cls.expand(Q[i]).astype(np.int64), float(s[i]), float(J[i])
