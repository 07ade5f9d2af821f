"""One table of every hardware-fit option: its type, unit, allowed range and default.

The design loader (:mod:`fsdvs_hw.explore.design`) and the public fit functions
(:func:`~fsdvs_hw.realise.mesh.fit_resistive_mesh`, :func:`~fsdvs_hw.realise.asic.fit_asic_taps`,
:func:`~fsdvs_hw.realise.metalens.fit_metalens`) check their options against the same
:data:`FIT_OPTIONS`, so a value a design file refuses is refused by the Python call too, and the
other way round, with the same words: the option, the value and what is allowed. Both check before
any work starts (a bad value never costs a fit).

Rules shared by every option: a boolean is never a number; numbers must be finite (NaN and ±inf
are refused even where no range is given); an integer option refuses floats (``7.0`` is refused,
so a typo never truncates silently); ``None`` is accepted only where the option says so.

Options whose value is a structured object (``mesh.bounds``, ``asic.geometry``,
``metalens.illuminant``/``response``) are typed here and range-checked by their own class or
function, which raises the same :class:`~fsdvs_hw.errors.InputError`.

The limits mirror the fit functions' documented ranges; ``tests/test_validation.py`` checks that
every parameter of every fit function is listed here with the function's own default.
"""

from __future__ import annotations

import math
import numbers
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

from .errors import InputError
from .kernels import Kernel, check_tap_magnitude

__all__ = ["Option", "FIT_OPTIONS", "FIT_FUNCTIONS", "check_option", "check_fit_options", "check_fit_arguments"]

#: Realisation name → the public fit function (``module:function``) whose options are listed.
FIT_FUNCTIONS: dict[str, str] = {
    "mesh": "fsdvs_hw.realise.mesh:fit_resistive_mesh",
    "asic": "fsdvs_hw.realise.asic:fit_asic_taps",
    "metalens": "fsdvs_hw.realise.metalens:fit_metalens",
}

_KINDS = ("int", "float", "str", "bool", "object")


@dataclass(frozen=True)
class Option:
    """Schema of one fit option.

    Parameters
    ----------
    kinds : tuple of str
        Allowed kinds, any of ``"int"``, ``"float"`` (ints accepted), ``"str"``, ``"bool"``,
        ``"object"`` (checked by the fit function's own class). Numbers are range-checked.
    default : Any
        The fit function's default.
    unit : str
        Physical unit of a number (``"m"``, ``"S"``, ``"F"``, ``"px"``, ``"bit"``; ``""`` =
        dimensionless).
    doc : str
        A few words of meaning.
    lo, hi : float, optional
        Allowed numeric range (inclusive unless ``lo_open`` / ``hi_open``).
    choices : tuple of str, optional
        Allowed strings.
    nullable : bool
        ``None`` allowed (means "the function's automatic choice").
    odd : bool
        Integer must be odd.
    """

    kinds: tuple[str, ...]
    default: Any
    unit: str
    doc: str
    lo: float | None = None
    hi: float | None = None
    lo_open: bool = False
    hi_open: bool = False
    choices: tuple[str, ...] | None = None
    nullable: bool = False
    odd: bool = False

    def __post_init__(self) -> None:
        unknown = set(self.kinds) - set(_KINDS)
        if unknown:  # pragma: no cover - programming error in the table below
            raise ValueError(f"Option kinds {unknown} unknown")

    def allowed(self) -> str:
        """Human-readable description of what is allowed."""
        parts: list[str] = []
        if "int" in self.kinds or "float" in self.kinds:
            word = "integer" if "float" not in self.kinds else "number"
            rng = ""
            if self.lo is not None or self.hi is not None:
                lo = "-inf" if self.lo is None else f"{self.lo:g}"
                hi = "inf" if self.hi is None else f"{self.hi:g}"
                rng = f" in {'(' if self.lo_open else '['}{lo}, {hi}{')' if self.hi_open else ']'}"
            unit = f" {self.unit}" if self.unit else ""
            parts.append(f"{'an odd ' if self.odd else 'a finite '}{word}{rng}{unit}")
        if "str" in self.kinds:
            parts.append("one of " + ", ".join(repr(c) for c in self.choices) if self.choices else "a string")
        if "bool" in self.kinds:
            parts.append("a boolean (true or false)")
        if "object" in self.kinds:
            parts.append("a table / object of the documented fields")
        if self.nullable:
            parts.append("None (automatic)")
        return " or ".join(parts) + f" ({self.doc})"

    def check(self, value: Any, *, name: str) -> Any:
        """Return ``value`` (numbers normalised: int or float) or raise :class:`InputError`.

        The message names ``name``, the value and :meth:`allowed`.
        """
        why = self.problem(value)
        if why is not None:
            raise InputError(f"{name}={_show(value)}: {why}")
        if isinstance(value, numbers.Integral) and not isinstance(value, (bool, np.bool_)):
            return int(value) if "int" in self.kinds else float(value)
        if isinstance(value, numbers.Real) and not isinstance(value, (bool, np.bool_)):
            return float(value)
        if isinstance(value, np.bool_):
            return bool(value)
        return value

    def problem(self, value: Any) -> str | None:
        """What is wrong with ``value`` (``"<why>; allowed: <what>"``), or None when it is allowed."""
        why = self._why(value)
        return None if why is None else f"{why}; allowed: {self.allowed()}"

    def _why(self, value: Any) -> str | None:
        if value is None:
            return None if self.nullable else "None is not allowed"
        if isinstance(value, (bool, np.bool_)):
            return None if "bool" in self.kinds else "wrong type boolean"
        if isinstance(value, numbers.Integral) and ("int" in self.kinds or "float" in self.kinds):
            return self._range(float(value)) if abs(int(value)) < 2**63 else "out of range"
        if isinstance(value, numbers.Real) and "float" in self.kinds:
            v = float(value)
            return "not a finite number" if not math.isfinite(v) else self._range(v)
        if isinstance(value, str) and "str" in self.kinds:
            if self.choices is not None and value not in self.choices:
                return "not one of the allowed words"
            return None
        if "object" in self.kinds and not isinstance(value, (str, numbers.Number)):
            return None
        return f"wrong type {_TYPE_WORDS.get(type(value).__name__, type(value).__name__)}"

    def _range(self, v: float) -> str | None:
        if self.lo is not None and (v <= self.lo if self.lo_open else v < self.lo):
            return "out of range"
        if self.hi is not None and (v >= self.hi if self.hi_open else v > self.hi):
            return "out of range"
        if self.odd and int(v) % 2 == 0:
            return "must be odd"
        return None


_TYPE_WORDS = {"str": "string", "float": "number", "int": "integer", "bool": "boolean", "dict": "table",
               "list": "list"}


def _show(value: Any) -> str:
    s = repr(value)
    return s if len(s) <= 60 else s[:57] + "..."


def _o(kinds: str, default: Any, unit: str, doc: str, **kw: Any) -> Option:
    return Option(tuple(kinds.split("|")), default, unit, doc, **kw)


_PITCH = dict(lo=1e-7, hi=1e-3)  # metres; the same range as fsdvs_hw.kernels (did you pass µm?)

#: realisation → option → schema. The ranges are the fit functions' own (see their docstrings).
FIT_OPTIONS: dict[str, dict[str, Option]] = {
    "mesh": {
        "bounds": _o("object", None, "", "MeshBounds fields: lambda_px, gain, min_lambda_ratio, conductance_s",
                     nullable=True),
        "pitch_m": _o("float", None, "m", "pixel pitch (default: the kernel's)", nullable=True, **_PITCH),
        "pixel_weight": _o("float|str", "free", "", "fixed weight of the pixel's own signal, or 'free'",
                           lo=0.0, hi=1e3, choices=("free",), nullable=True),
        "gain": _o("str", "free", "", "overall gain: 'free' (folds into the event threshold) or 'fixed'",
                   choices=("free", "fixed")),
        "nonnegative_dc": _o("bool", True, "", "constrain the whole-circuit DC gain w_p + a − b ≥ 0"),
        "mismatch_sigma": _o("float", 0.01, "", "relative die-level mismatch σ", lo=0.0, hi=0.5),
        "max_mismatch_error": _o("float", 0.05, "", "largest first-order kernel error at mismatch σ (None: off)",
                                 lo=1e-6, hi=10.0, nullable=True),
        "g_lateral_s": _o("float", 1e-8, "S", "lateral conductance of both meshes (within bounds.conductance_s)",
                          lo=1e-13, hi=1e-3),
        "node_capacitance_f": _o("float", 100e-15, "F", "node capacitance of both meshes", lo=1e-18, hi=1e-6),
        "model": _o("str", "lattice", "", "single-mesh model", choices=("lattice", "grid")),
        "grid_half_width": _o("int", None, "px", "half-width of the finite grid (model 'grid'; ≥ kernel radius)",
                              lo=0, hi=60, nullable=True),
        "fit_size": _o("int", None, "px", "odd window the error is minimised on (≥ kernel size; None: the "
                       "whole response)", lo=1, hi=63, odd=True, nullable=True),
        "n_init": _o("int", 16, "", "λ values per mesh in the initialisation grid", lo=2, hi=40),
        "n_starts": _o("int", 3, "", "IPOPT runs from the best distinct grid points", lo=1, hi=10),
        "max_iter": _o("int", 200, "", "IPOPT iteration limit", lo=1, hi=10000),
        "tol": _o("float", 1e-14, "", "IPOPT tolerance", lo=0.0, hi=1.0, lo_open=True),
    },
    "asic": {
        "bits": _o("int", 8, "bit", "signed tap width including the sign", lo=2, hi=24),
        "symmetry": _o("str", "auto", "", "symmetry imposed on the taps",
                       choices=("auto", "none", "quadrant", "8-fold")),
        "scale": _o("float|str", "free", "", "tap scale: 'free', 'pow2' or a fixed positive number",
                    lo=0.0, lo_open=True, choices=("free", "pow2")),
        "adder_weight": _o("float", 0.0, "", "price of one adder in squared relative error", lo=0.0),
        "input_bits": _o("int", 8, "bit", "unsigned pixel width the accumulator is sized for", lo=1, hi=32),
        "pre_add": _o("bool", True, "", "count and build symmetric pre-adds"),
        "objective": _o("str", "kernel", "", "what the error term measures", choices=("kernel", "csf")),
        "csf_method": _o("str", "mannos_sakrison_1974", "", "CSF model for objective 'csf'",
                         choices=("mannos_sakrison_1974", "barten_1999", "daly_1993", "watson_ahumada_2005")),
        "geometry": _o("object", None, "", "fsdvs_hw.csf.Geometry (pixels per degree) for objective 'csf'",
                       nullable=True),
    },
    "metalens": {
        "pitch_m": _o("float", None, "m", "pixel pitch (default: the kernel's)", nullable=True, **_PITCH),
        "illuminant": _o("str|float|object", "D65", "m", "colour illuminant name, a spectral distribution, or "
                         "one wavelength in metres", lo=1e-7, hi=2e-5),
        "response": _o("str|object", None, "", "sensor spectral response (default photopic V(λ))", nullable=True),
        "strategy": _o("str", "pedestal", "", "signed-kernel strategy", choices=("pedestal", "differential")),
        "aperture_m": _o("float", 100e-6, "m", "lens aperture diameter", lo=1e-7, hi=1e-1, lo_open=True,
                         nullable=True),
        "focal_length_m": _o("float", 200e-6, "m", "lens focal length", lo=1e-7, hi=1.0, nullable=True),
        "design_wavelength_m": _o("float", 555e-9, "m", "design wavelength", lo=1e-7, hi=2e-5),
        "dispersion": _o("str", "diffractive", "", "dispersion model", choices=("diffractive", "achromatic")),
        "n_terms": _o("int", 4, "", "polynomial phase terms", lo=0, hi=12),
        "n_wavelengths": _o("int|str", 24, "", "spectral samples, or 'auto'", lo=1, hi=200, choices=("auto",)),
        "guard_px": _o("int", 2, "px", "ring of pixels where spilled light counts as error", lo=0, hi=8),
        "max_iter": _o("int", 150, "", "L-BFGS iterations of the final refinement", lo=1, hi=100000),
        "n_starts": _o("int", 6, "", "defocus starting points", lo=1, hi=1000),
        "n_sub": _o("int", None, "", "pixel-integration nodes per axis (None: from the PSF's bandwidth)",
                    lo=1, hi=4096, nullable=True),
        "window_pad": _o("float", 2.0, "", "radial-model window padding factor", lo=1.0, hi=16.0),
        "na_max": _o("float", None, "", "largest local numerical aperture of the phase", lo=0.0, hi=1.0,
                     lo_open=True, hi_open=True, nullable=True),
    },
}


def check_option(realisation: str, name: str, value: Any, *, prefix: str = "") -> Any:
    """Check one option of one realisation; return the normalised value.

    Parameters
    ----------
    realisation : {"mesh", "asic", "metalens"}
    name : str
        Option (keyword) name.
    value : Any
    prefix : str
        Prepended to the option name in messages (``"realisations.asic."`` for design keys).

    Raises
    ------
    InputError
        Unknown realisation or option, wrong type, out of range; the message names
        ``prefix + name``, the value and what is allowed.
    """
    options = _options(realisation)
    if name not in options:
        raise InputError(f"{prefix}{name}: unknown option of {FIT_FUNCTIONS[realisation].split(':')[1]}; "
                         f"allowed: {', '.join(sorted(options))}")
    return options[name].check(value, name=prefix + name)


def check_fit_options(realisation: str, options: Mapping[str, Any], *, prefix: str = "") -> dict[str, Any]:
    """Check a mapping of options (e.g. a ``[realisations.asic]`` table); return them normalised.

    Raises :class:`InputError` for the first bad option (see :func:`check_option`).
    """
    if not isinstance(options, Mapping):
        raise InputError(f"{prefix.rstrip('.') or realisation}: fit options must be a table, "
                         f"got {type(options).__name__}")
    return {k: check_option(realisation, k, v, prefix=prefix) for k, v in options.items()}


def check_fit_arguments(realisation: str, arguments: Mapping[str, Any]) -> None:
    """Check a fit function's arguments at its first line (``check_fit_arguments("asic", locals())``).

    Every argument listed in :data:`FIT_OPTIONS` is checked, and the target kernel's largest tap
    must lie in :data:`fsdvs_hw.kernels.TAP_MAGNITUDE_RANGE` (design files check the same); other
    names (arguments added later) are left to the function.
    """
    options = _options(realisation)
    for name, opt in options.items():
        if name in arguments:
            opt.check(arguments[name], name=name)
    kernel = arguments.get("kernel")
    if isinstance(kernel, Kernel):
        check_tap_magnitude(kernel, source=f"kernel '{kernel.name}'")
    elif kernel is not None and not isinstance(kernel, (str, bytes)):  # taps as an array (mesh accepts them)
        try:
            taps = np.asarray(kernel, dtype=np.float64)
        except (TypeError, ValueError):
            return  # not numeric: the function's own check names the problem
        if taps.size and np.isfinite(taps).all() and np.any(taps != 0):
            check_tap_magnitude(taps, source="kernel")


def _options(realisation: str) -> dict[str, Option]:
    if realisation not in FIT_OPTIONS:
        raise InputError(f"realisation {realisation!r} unknown; allowed: {', '.join(FIT_OPTIONS)}")
    return FIT_OPTIONS[realisation]
