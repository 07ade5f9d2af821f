"""How the report writes things for people: realisation names, colours and markers, numbers with SI prefixes.

One place decides how a realisation looks (its registry ``title``, ``colour`` and ``marker``,
:class:`fsdvs_hw.realise.registry.RealisationSpec`), so a colour names the same realisation in
every figure and table, and one place writes numbers: SI prefixes for physical units
(``100 µm``, not ``0.0001 m``), never e-notation (``3.2 × 10⁻⁵``, not ``3.2e-05``).

References
----------
BIPM, *The International System of Units (SI)*, 9th ed., 2019, §3 (SI prefixes) and §5.4.3
(a space between number and unit; the prefix binds to the unit before any power: µm² = (µm)²).
"""

from __future__ import annotations

import json
import math
import re
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

from ..realise.registry import REALISATIONS

__all__ = [
    "PREFIXED_UNITS",
    "Style",
    "cost_label",
    "number",
    "params_text",
    "plain",
    "point_title",
    "si",
    "style",
    "title",
]

#: Units that take an SI prefix (``"m^2"`` takes it squared).
PREFIXED_UNITS: frozenset[str] = frozenset({"m", "m^2", "s", "S", "F", "W", "J", "A", "V", "Hz"})

_PREFIXES: tuple[tuple[int, str], ...] = (
    (-15, "f"),
    (-12, "p"),
    (-9, "n"),
    (-6, "µ"),
    (-3, "m"),
    (0, ""),
    (3, "k"),
    (6, "M"),
    (9, "G"),
    (12, "T"),
)
_SUPERSCRIPT = str.maketrans("-0123456789", "⁻⁰¹²³⁴⁵⁶⁷⁸⁹")
#: Markers handed to realisations that do not declare one (hollow-friendly shapes, in this order).
_SPARE_MARKERS: tuple[str, ...] = ("o", "s", "D", "^", "v", "P", "X", "<", ">", "p", "h", "*")
#: Colours for realisations that do not declare one (matplotlib's tab10, in order).
_SPARE_COLOURS: tuple[str, ...] = (
    "#1f77b4",
    "#ff7f0e",
    "#2ca02c",
    "#d62728",
    "#9467bd",
    "#8c564b",
    "#e377c2",
    "#7f7f7f",
    "#bcbd22",
    "#17becf",
)


@dataclass(frozen=True)
class Style:
    """How one realisation looks in the report.

    Attributes
    ----------
    title : str
        Its name for people (``"resistive mesh"``).
    colour : str
        Matplotlib colour of its points and lines, the same in every figure.
    marker : str
        Matplotlib marker of its points; distinct between registered realisations.
    """

    title: str
    colour: str
    marker: str


def style(name: str) -> Style:
    """The :class:`Style` of realisation ``name`` (registry ``title``, ``colour`` and ``marker``).

    A realisation that declares no colour or marker gets the first one no registered realisation
    declares, picked in registration order, so two realisations never share a colour or a marker
    (up to ten colours and twelve markers); an unregistered name gets the colour and marker of
    its hash, stable across runs.
    """
    names = list(REALISATIONS)
    used_colours = {s.colour for s in REALISATIONS.values() if s.colour}
    used_markers = {s.marker for s in REALISATIONS.values() if s.marker}
    free_colours = [c for c in _SPARE_COLOURS if c not in used_colours] or list(_SPARE_COLOURS)
    free_markers = [m for m in _SPARE_MARKERS if m not in used_markers] or list(_SPARE_MARKERS)
    spec = REALISATIONS.get(name)
    if spec is not None:
        undeclared_c = [n for n in names if not REALISATIONS[n].colour]
        undeclared_m = [n for n in names if not REALISATIONS[n].marker]
        colour = spec.colour or free_colours[undeclared_c.index(name) % len(free_colours)]
        marker = spec.marker or free_markers[undeclared_m.index(name) % len(free_markers)]
        return Style(spec.title or name, colour, marker)
    h = sum(ord(c) * 31**i for i, c in enumerate(name))  # not hash(): that changes per process
    return Style(name, free_colours[h % len(free_colours)], free_markers[h % len(free_markers)])


def title(name: str) -> str:
    """Realisation ``name`` for people (its registry ``title``; the name itself when it has none)."""
    return style(name).title


def point_title(realisation: str, params: Mapping[str, Any] | str | None = None) -> str:
    """A design point for people: ``"ASIC taps (bits 4)"``.

    Parameters
    ----------
    realisation : str
        Registry name.
    params : mapping or JSON text, optional
        The point's swept values (``{"asic.bits": 4}``); only the option name after the last dot
        is shown, with underscores as spaces.
    """
    name = title(realisation)
    shown = params_text(params)
    return f"{name} ({shown})" if shown else name


def params_text(params: Mapping[str, Any] | str | None) -> str:
    """A point's swept values for people, ``"bits 4, g max 1 µS"`` style (``""`` for none)."""
    if isinstance(params, str):
        params = json.loads(params) if params.strip() else {}
    return ", ".join(f"{k.split('.')[-1].replace('_', ' ')} {_param(v)}" for k, v in (params or {}).items())


def _param(v: Any) -> str:
    return number(v) if isinstance(v, (int, float)) and not isinstance(v, bool) else str(v)


def number(v: float | int | None, digits: int = 3) -> str:
    """``v`` with ``digits`` significant digits and no e-notation.

    Integers are written in full, grouped by thin spaces from five digits on (``29 696``); floats from
    0.001 to below 10⁶ in positional notation (``0.0423``, ``4220``); smaller or larger ones as
    ``m × 10ⁿ`` (``3.2 × 10⁻⁵``). NaN and None give ``"–"``.
    """
    if v is None or isinstance(v, bool):
        return "–" if v is None else ("yes" if v else "no")
    if isinstance(v, int) or (isinstance(v, float) and v.is_integer() and abs(v) < 1e15):
        if isinstance(v, float) and abs(v) < 1e-300:
            return "0"
        return _group(int(v))
    v = float(v)
    if math.isnan(v):
        return "–"
    if math.isinf(v):
        return "∞" if v > 0 else "−∞"
    a = abs(v)
    if 1e-3 <= a < 1e6:
        exp = math.floor(math.log10(a))
        decimals = max(digits - 1 - exp, 0)
        text = f"{v:.{decimals}f}"
        if "." in text:
            text = text.rstrip("0").rstrip(".")
        whole, _, frac = text.partition(".")
        sign = "-" if whole.startswith("-") else ""
        whole = _group(int(whole.lstrip("-")))
        return sign + whole + (f".{frac}" if frac else "")
    mant, _, exp_text = f"{v:.{digits - 1}e}".partition("e")  # Python rounds the mantissa and carries into exp
    m = mant.rstrip("0").rstrip(".") if "." in mant else mant
    return f"{m} × 10{str(int(exp_text)).translate(_SUPERSCRIPT)}"


def _group(n: int) -> str:
    """Digits of an integer, grouped in threes by thin spaces from five digits on (SI §5.4.4)."""
    return f"{n:,}".replace(",", "\u2009") if abs(n) >= 10_000 else str(n)


def si(value: float | None, unit: str, digits: int = 3) -> str:
    """``value`` in ``unit`` with an SI prefix chosen so the number lies in [1, 1000).

    Parameters
    ----------
    value : float
        In the unprefixed unit (metres, seconds, siemens, ...).
    unit : str
        A unit of :data:`PREFIXED_UNITS` (``"m^2"`` is written ``m²`` and takes its prefix
        squared); ``"1"`` (dimensionless) and ``"count"`` give the bare number; other units
        (``"bit"``, ``"px"``, already-prefixed display units such as ``"µm²"``) are written after
        the unprefixed number.
    digits : int
        Significant digits.

    Examples
    --------
    >>> si(0.0001, "m"), si(6.04e-06, "s"), si(2e-9, "m^2"), si(64, "count"), si(0.42, "1")
    ('100 µm', '6.04 µs', '2000 µm²', '64', '0.42')
    """
    if value is None or (isinstance(value, float) and math.isnan(value)):
        return "–"
    unit = unit or "1"
    if unit in ("1", "count", ""):
        return number(value, digits)
    if unit not in PREFIXED_UNITS or value == 0 or math.isinf(value):
        return f"{number(value, digits)} {unit.replace('^2', '²')}"
    power = 2 if unit == "m^2" else 1
    base = "m" if unit == "m^2" else unit
    exp3 = math.floor(math.log10(abs(value)) / (3 * power)) * 3
    exp3 = min(max(exp3, _PREFIXES[0][0]), _PREFIXES[-1][0])
    scaled = value / 10.0 ** (exp3 * power)
    # rounding may carry into the next prefix (999.7 µm -> 1.00 mm)
    if float(f"{abs(scaled):.{digits}g}") >= 1000**power and exp3 < _PREFIXES[-1][0]:
        exp3 += 3
        scaled = value / 10.0 ** (exp3 * power)
    prefix = dict(_PREFIXES)[exp3]
    text = number(float(f"{scaled:.{digits}g}") if abs(scaled) >= 1 else scaled, digits)
    return f"{text} {prefix}{base}{'²' if power == 2 else ''}"


_E_NUMBER = re.compile(r"(?<![\w.])[-+]?\d+(?:\.\d+)?[eE][-+]?\d+(?![\w.])")


def plain(text: str) -> str:
    """Free text (a warning, a cost item's description) with every e-notation number rewritten by
    :func:`number`: ``"all but 1e-6 of it"`` → ``"all but 1 × 10⁻⁶ of it"``.

    Examples
    --------
    >>> plain("g_l = 1e-08 S, tau = 2.68e-06 s; 7x7 kernel")
    'g_l = 1 × 10⁻⁸ S, tau = 2.68 × 10⁻⁶ s; 7x7 kernel'
    """
    return _E_NUMBER.sub(lambda m: number(float(m.group(0))), text)


def cost_label(realisation: str, item: str) -> str:
    """The label of cost item ``item`` of ``realisation``: its declared
    :class:`~fsdvs_hw.realise.registry.CostSpec` label, else the name with spaces."""
    spec = REALISATIONS.get(realisation)
    for c in spec.costs if spec is not None else ():
        if c.name == item and c.label:
            return c.label
    words = item.removesuffix("_m2").removesuffix("_m").removesuffix("_px").split("_")
    return " ".join(_GREEK.get(w, w) for w in words)


#: Symbol names in cost item names written as the symbols.
_GREEK = {"lambda": "λ", "tau": "τ", "sigma": "σ", "mu": "µ"}
