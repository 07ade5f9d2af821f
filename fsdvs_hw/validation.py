"""Argument checks: fit functions against their option model, and the Python API's arguments.

Every realisation declares its fit options as a pydantic model (:mod:`fsdvs_hw.schema`) in its
registry entry (:attr:`fsdvs_hw.realise.registry.RealisationSpec.options`). The design loader
(:mod:`fsdvs_hw.design`) checks a ``[realisations.<name>]`` table against that model, and
the fit function checks its own arguments against the same model at its first line
(:func:`check_fit_arguments`, which returns the validated options object the fit then reads), so a
value a design file refuses is refused by the Python call too, and the other way round, with the
same words: the option, the value and what is allowed; the rules between options and on the target
kernel included (:mod:`fsdvs_hw.realise.fit_options`). Both check before any work starts (a bad
value never costs a fit). The rules (no boolean as a number,
finite numbers, no float for an integer, ``None`` only where allowed) are those of
:class:`fsdvs_hw.schema.StrictModel`.

The second half of the module holds the argument checks of the Python API
(:func:`check_int`, :func:`check_real`, :func:`check_bool`, :func:`check_instance`,
:func:`check_increasing_times`): the public functions of :mod:`fsdvs_hw.sensor`,
:mod:`fsdvs_hw.scenes` and :mod:`fsdvs_hw.tasks` call them before any work, so a wrong type or value
is one :class:`~fsdvs_hw.errors.InputError` line (``name=value: why; allowed: ...``), never a
traceback from inside torch or numpy (``tests/test_api_inputs.py``).

``tests/test_realisation_contract.py`` checks, for every registered realisation, that every
parameter of its fit function is in its model with the function's own default.
"""

from __future__ import annotations

import math
import numbers
from collections.abc import Mapping
from typing import TYPE_CHECKING, Any, Literal, TypeVar, overload

import numpy as np

from .errors import InputError
from .kernels import PITCH_RANGE_M, Kernel, check_tap_magnitude  # PITCH_RANGE_M: re-exported

if TYPE_CHECKING:  # pydantic loads on the first fit-argument check, not with the simulator's checks
    from pydantic import BaseModel

ModelT = TypeVar("ModelT", bound="BaseModel")

__all__ = [
    "PITCH_RANGE_M",
    "check_bool",
    "check_fit_arguments",
    "check_increasing_times",
    "check_instance",
    "check_int",
    "check_real",
]


def _show(value: Any) -> str:
    s = " ".join(repr(value).split())  # one line (numpy arrays print on several)
    return s if len(s) <= 60 else s[:57] + "..."


def check_fit_arguments(options: type[ModelT], arguments: Mapping[str, Any]) -> ModelT:
    """Check a fit function's arguments at its first line (``o = check_fit_arguments(AsicOptions, locals())``).

    Every argument that is a field of the model ``options`` is validated against it (all problems
    in one :class:`~fsdvs_hw.errors.InputError`, each naming the argument, the value and what is
    allowed), and the target kernel's largest tap must lie in
    :data:`fsdvs_hw.kernels.TAP_MAGNITUDE_RANGE` (design files check the same); other names
    (arguments added later) are left to the function. A model with a ``with_target`` method
    (:class:`fsdvs_hw.realise.fit_options.FitOptions`) then coerces the ``kernel`` argument and
    checks its rules on the target kernel.

    Returns
    -------
    pydantic.BaseModel
        The validated options object (holding the target kernel when the model checks one).
    """
    from .schema import validate

    checked = validate(options, {name: arguments[name] for name in options.model_fields if name in arguments})
    assert isinstance(checked, options)
    kernel = arguments.get("kernel")
    if isinstance(kernel, Kernel):
        check_tap_magnitude(kernel, source=f"kernel '{kernel.name}'")
    elif kernel is not None and not isinstance(kernel, (str, bytes)):  # taps as an array (mesh accepts them)
        try:
            taps = np.asarray(kernel, dtype=np.float64)
        except (TypeError, ValueError):
            taps = None  # not numeric: the coercion of the target names the problem
        if taps is not None and taps.size and np.isfinite(taps).all() and np.any(taps != 0):
            check_tap_magnitude(taps, source="kernel")
    with_target = getattr(checked, "with_target", None)
    return with_target(kernel) if callable(with_target) else checked


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


def check_real(
    name: str,
    value: Any,
    lo: float | None = None,
    hi: float | None = None,
    *,
    lo_open: bool = False,
    hi_open: bool = False,
    unit: str = "",
) -> float:
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


@overload
def check_bool(name: str, value: Any, *, nullable: Literal[False] = False) -> bool: ...


@overload
def check_bool(name: str, value: Any, *, nullable: bool) -> bool | None: ...


def check_bool(name: str, value: Any, *, nullable: bool = False) -> bool | None:
    """``value`` as a bool (``True``/``False``, numpy bools; ``None`` only if ``nullable``)."""
    if value is None and nullable:
        return None
    if not isinstance(value, (bool, np.bool_)):
        raise InputError(
            f"{name}={_show(value)}: wrong type {type(value).__name__}; allowed: True or False"
            + (" or None" if nullable else "")
        )
    return bool(value)


def check_instance(name: str, value: Any, types: type | tuple[type, ...], what: str, *, nullable: bool = False) -> Any:
    """``value`` itself if it is an instance of ``types`` (or ``None`` when ``nullable``).

    ``what`` says what is allowed in words (``"a SensorConfig"``).
    """
    if (value is None and nullable) or isinstance(value, types):
        return value
    raise InputError(
        f"{name}={_show(value)}: wrong type {type(value).__name__}; allowed: {what}" + (" or None" if nullable else "")
    )


def check_increasing_times(name: str, times: Any) -> np.ndarray:
    """Frame times in seconds as a 1-D float64 array: numeric, finite, at least 2, strictly increasing.

    Accepts any array-like (lists, numpy arrays, CPU or GPU tensors).
    """
    if isinstance(times, (str, bytes)) or times is None:
        raise InputError(
            f"{name}={_show(times)}: wrong type {type(times).__name__}; allowed: a 1-D array of "
            "frame times in seconds, finite and strictly increasing"
        )
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
        raise InputError(
            f"{name}: must be strictly increasing; time {bad} ({ts[bad]:g} s) is not later than "
            f"time {bad - 1} ({ts[bad - 1]:g} s)"
        )
    return ts
