"""Option schemas: an option's type, unit, allowed range, default and meaning, and the checks.

Every realisation declares its fit options as a mapping of :class:`Option` in its registry entry
(:class:`fsdvs_hw.realise.registry.RealisationSpec`). The design loader
(:mod:`fsdvs_hw.explore.design`) checks a ``[realisations.<name>]`` table against that schema, and
the fit function checks its own arguments against the same schema at its first line
(:func:`check_fit_arguments`), so a value a design file refuses is refused by the Python call too,
and the other way round, with the same words: the option, the value and what is allowed. Both
check before any work starts (a bad value never costs a fit).

Rules shared by every option: a boolean is never a number; numbers must be finite (NaN and ±inf
are refused even where no range is given); an integer option refuses floats (``7.0`` is refused,
so a typo never truncates silently); ``None`` is accepted only where the option says so.

Options whose value is a structured object (``mesh.bounds``, ``asic.geometry``,
``metalens.illuminant``/``response``) are typed here and range-checked by their own class or
function (``Option.factory`` builds a table given in a design file before any fit), which raises
the same :class:`~fsdvs_hw.errors.InputError`.

The second half of the module holds the argument checks of the Python API
(:func:`check_int`, :func:`check_real`, :func:`check_bool`, :func:`check_instance`,
:func:`check_increasing_times`): the public functions of :mod:`fsdvs_hw.sensor`,
:mod:`fsdvs_hw.scenes` and :mod:`fsdvs_hw.tasks` call them before any work, so a wrong type or value
is one :class:`~fsdvs_hw.errors.InputError` line (``name=value: why; allowed: ...``), never a
traceback from inside torch or numpy (``tests/test_api_inputs.py``).

``tests/test_realisation_contract.py`` checks, for every registered realisation, that every
parameter of its fit function is in its schema with the function's own default.
"""

from __future__ import annotations

import math
import numbers
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

from .errors import InputError
from .kernels import Kernel, check_tap_magnitude

__all__ = ["Option", "option", "PITCH_RANGE_M", "check_option", "check_options", "check_fit_arguments",
           "check_int", "check_real", "check_bool", "check_instance", "check_increasing_times"]

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
    factory : callable, optional
        For an ``"object"`` option: builds the object from a table (``factory(**table)``), so a
        design file's table is checked by the class before any work starts.
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
    factory: Callable[..., Any] | None = None

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
    s = " ".join(repr(value).split())  # one line (numpy arrays print on several)
    return s if len(s) <= 60 else s[:57] + "..."


#: Allowed pixel pitch in metres (the same range as :mod:`fsdvs_hw.kernels`; did you pass µm?).
PITCH_RANGE_M: tuple[float, float] = (1e-7, 1e-3)


def option(kinds: str, default: Any, unit: str, doc: str, **kw: Any) -> Option:
    """Shorthand for :class:`Option`: ``option("int|str", 24, "", "samples, or 'auto'", lo=1, choices=("auto",))``."""
    return Option(tuple(kinds.split("|")), default, unit, doc, **kw)


def check_option(options: Mapping[str, Option], name: str, value: Any, *, prefix: str = "",
                 owner: str = "the fit function") -> Any:
    """Check one option against a schema; return the normalised value.

    Parameters
    ----------
    options : mapping of str to Option
        The schema (a realisation's :attr:`~fsdvs_hw.realise.registry.RealisationSpec.options`).
    name : str
        Option (keyword) name.
    value : Any
    prefix : str
        Prepended to the option name in messages (``"realisations.asic."`` for design keys).
    owner : str
        What the options belong to, for the unknown-option message (``"fit_asic_taps"``).

    Raises
    ------
    InputError
        Unknown option, wrong type, out of range; the message names ``prefix + name``, the value
        and what is allowed.
    """
    if name not in options:
        raise InputError(f"{prefix}{name}: unknown option of {owner}; allowed: {', '.join(sorted(options))}")
    return options[name].check(value, name=prefix + name)


def check_options(options: Mapping[str, Option], values: Mapping[str, Any], *, prefix: str = "",
                  owner: str = "the fit function") -> dict[str, Any]:
    """Check a mapping of options (e.g. a ``[realisations.asic]`` table); return them normalised.

    Raises :class:`InputError` for the first bad option (see :func:`check_option`).
    """
    if not isinstance(values, Mapping):
        raise InputError(f"{prefix.rstrip('.') or owner}: options must be a table, got {type(values).__name__}")
    return {k: check_option(options, k, v, prefix=prefix, owner=owner) for k, v in values.items()}


def check_fit_arguments(options: Mapping[str, Option], arguments: Mapping[str, Any]) -> None:
    """Check a fit function's arguments at its first line (``check_fit_arguments(OPTIONS, locals())``).

    Every argument listed in ``options`` is checked, and the target kernel's largest tap must lie
    in :data:`fsdvs_hw.kernels.TAP_MAGNITUDE_RANGE` (design files check the same); other names
    (arguments added later) are left to the function.
    """
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


# ---------------------------------------------------------------------------- Python API arguments
# Checks the public functions of fsdvs_hw.sensor, fsdvs_hw.scenes and fsdvs_hw.tasks run on their
# arguments before any work, so a wrong type or value costs one line naming the argument, the value
# and what is allowed, never a traceback from inside torch or numpy.

def _allowed_range(lo: float | None, hi: float | None, lo_open: bool, hi_open: bool) -> str:
    a = "-inf" if lo is None else f"{lo:g}"
    b = "inf" if hi is None else f"{hi:g}"
    return f"{'(' if lo_open else '['}{a}, {b}{')' if hi_open else ']'}"


def check_int(name: str, value: Any, lo: int | None = None, hi: int | None = None) -> int:
    """``value`` as a Python int in ``[lo, hi]`` (numpy integers accepted; bools and floats refused).

    Raises
    ------
    InputError
        ``"<name>=<value>: <why>; allowed: an integer in [lo, hi]"``.
    """
    allowed = f"an integer in {_allowed_range(lo, hi, False, False)}"
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, numbers.Integral):
        raise InputError(f"{name}={_show(value)}: wrong type {type(value).__name__}; allowed: {allowed}")
    v = int(value)
    if (lo is not None and v < lo) or (hi is not None and v > hi):
        raise InputError(f"{name}={_show(value)}: out of range; allowed: {allowed}")
    return v


def check_real(name: str, value: Any, lo: float | None = None, hi: float | None = None, *,
               lo_open: bool = False, hi_open: bool = False, unit: str = "") -> float:
    """``value`` as a finite float in the range (ints and numpy numbers accepted; bools refused).

    Raises
    ------
    InputError
        ``"<name>=<value>: <why>; allowed: a finite number in [lo, hi] <unit>"``.
    """
    allowed = f"a finite number in {_allowed_range(lo, hi, lo_open, hi_open)}{' ' + unit if unit else ''}"
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, numbers.Real):
        raise InputError(f"{name}={_show(value)}: wrong type {type(value).__name__}; allowed: {allowed}")
    v = float(value)
    if not math.isfinite(v):
        raise InputError(f"{name}={_show(value)}: not a finite number; allowed: {allowed}")
    if (lo is not None and (v <= lo if lo_open else v < lo)) or (hi is not None and (v >= hi if hi_open else v > hi)):
        raise InputError(f"{name}={_show(value)}: out of range; allowed: {allowed}")
    return v


def check_bool(name: str, value: Any, *, nullable: bool = False) -> bool | None:
    """``value`` as a bool (``True``/``False``, numpy bools; ``None`` only if ``nullable``)."""
    if value is None and nullable:
        return None
    if not isinstance(value, (bool, np.bool_)):
        raise InputError(f"{name}={_show(value)}: wrong type {type(value).__name__}; allowed: True or False"
                         + (" or None" if nullable else ""))
    return bool(value)


def check_instance(name: str, value: Any, types: type | tuple[type, ...], what: str, *,
                   nullable: bool = False) -> Any:
    """``value`` itself if it is an instance of ``types`` (or ``None`` when ``nullable``).

    ``what`` says what is allowed in words (``"a SensorConfig"``).
    """
    if (value is None and nullable) or isinstance(value, types):
        return value
    raise InputError(f"{name}={_show(value)}: wrong type {type(value).__name__}; allowed: {what}"
                     + (" or None" if nullable else ""))


def check_increasing_times(name: str, times: Any) -> np.ndarray:
    """Frame times in seconds as a 1-D float64 array: numeric, finite, at least 2, strictly increasing.

    Accepts any array-like (lists, numpy arrays, CPU or GPU tensors).
    """
    if isinstance(times, (str, bytes)) or times is None:
        raise InputError(f"{name}={_show(times)}: wrong type {type(times).__name__}; allowed: a 1-D array of "
                         "frame times in seconds, finite and strictly increasing")
    try:
        if hasattr(times, "detach"):
            times = times.detach().cpu().numpy()
        ts = np.asarray(times, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise InputError(f"{name}: must be a numeric array of frame times in seconds ({exc})") from None
    ts = ts.reshape(-1) if ts.ndim == 1 or (ts.ndim == 2 and ts.shape[0] == 1) else ts
    if ts.ndim != 1 or ts.size < 2:
        raise InputError(f"{name}: shape {ts.shape}; allowed: a 1-D array of at least 2 frame times in seconds")
    if not np.isfinite(ts).all():
        raise InputError(f"{name}: contains NaN or inf; allowed: finite frame times in seconds")
    steps = np.diff(ts)
    if not (steps > 0).all():
        bad = int(np.nonzero(steps <= 0)[0][0]) + 1
        raise InputError(f"{name}: must be strictly increasing; time {bad} ({ts[bad]:g} s) is not later than "
                         f"time {bad - 1} ({ts[bad - 1]:g} s)")
    return ts
