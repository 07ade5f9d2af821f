r"""Hard limits of a realisation, what would meet them, and where a cross-kind ranking flips.

A cost figure can break a **hard limit**: a mesh larger than the pixel it sits in, an event rate
the readout cannot carry, an added latency or an array power beyond a ``[costs]`` budget key
(:data:`HARD_LIMITS`). Such a realisation is never "build" (:mod:`fsdvs_hw.report.verdict`).
This module says what would make it fit, computed from the kind's own cost model
(:data:`fsdvs_hw.costs.physical.COST_MODELS`), never written by hand:

* :func:`assumption_at` — the value of one ``[costs]`` key (or a realisation's knob, such as the
  mesh's conductance :data:`MESH_CONDUCTANCE`) at which a cost figure reaches a target: a scan of
  the key's allowed range on a log grid, then Brent's method (:func:`scipy.optimize.brentq`) on
  :math:`\log(\text{figure}) - \log(\text{target})`;
* :func:`remedies` — for each broken limit: the pixel pitch at which the mesh fits
  (:math:`p = \sqrt{A}`), the assumption values that bring the figure within the limit, and, for
  an in-pixel mesh, one mesh node shared by k × k pixels with the kernel error that placement
  costs (:func:`shared_node_error`);
* :func:`cost_flips` — for two realisations and one cost, every key whose change within its
  range reverses which of the two is cheaper, and the value at which it does.

References
----------
.. [1] R. P. Brent, *Algorithms for Minimization without Derivatives*, Prentice-Hall 1973, ch. 4
   (the root finder).

Examples
--------
>>> from fsdvs_hw.costs.limits import HARD_LIMITS
>>> sorted(HARD_LIMITS)
['area_m2', 'event_rate_eps', 'latency_s', 'power_w']
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field, replace
from types import MappingProxyType
from typing import Any

import numpy as np

from ..errors import InputError
from ..records import Cost, Score
from .assumptions import CostAssumptions
from .physical import physical_cost
from .record import PhysicalCost

__all__ = [
    "FLIP_KEYS",
    "HARD_LIMITS",
    "IN_PIXEL_KINDS",
    "MESH_CONDUCTANCE",
    "Remedy",
    "assumption_at",
    "broken_limits",
    "cost_flips",
    "costed",
    "remedies",
    "shared_node_error",
]

#: Figure → (the limit it is held to, in words; the key or quantity that sets the limit). The area
#: limit holds for a filter inside the pixel (:data:`IN_PIXEL_KINDS`).
HARD_LIMITS: Mapping[str, tuple[str, str]] = MappingProxyType(
    {
        "area_m2": ("the pixel's area (pitch²)", "sensor.pitch_m"),
        "event_rate_eps": ("the readout limit", "costs.readout_limit_eps"),
        "latency_s": ("the latency budget", "costs.latency_budget_s"),
        "power_w": ("the power budget", "costs.power_budget_w"),
    }
)

#: A realisation's knob that the cost models see through its fitted items: the mesh's lateral
#: conductance (``realisations.mesh.g_lateral_s``, S). Every conductance of the fit scales with it
#: at a fixed kernel (the space constants are conductance ratios) and the settling time as 1/g.
MESH_CONDUCTANCE = "realisations.mesh.g_lateral_s"

#: Keys whose change can reorder kinds, per figure: the ``[costs]`` scalars each model reads, and the
#: mesh's conductance. Keys a figure does not depend on find no flip and cost nothing but a scan.
FLIP_KEYS: Mapping[str, tuple[str, ...]] = MappingProxyType(
    {
        "power_w": (
            "costs.sample_rate_hz",
            "costs.process_node_m",
            "costs.digital_supply_v",
            "costs.analog_supply_v",
            MESH_CONDUCTANCE,
        ),
        "area_m2": (
            "costs.process_node_m",
            "costs.transistor_area_f2",
            "costs.capacitor_density_f_m2",
            "costs.sram_cell_area_f2",
        ),
        "latency_s": ("costs.sample_rate_hz", "costs.clock_hz", MESH_CONDUCTANCE),
    }
)

#: Keys tried to meet each hard limit (besides the pitch and the shared node, for the area).
_REMEDY_KEYS: Mapping[str, tuple[str, ...]] = MappingProxyType(
    {
        "area_m2": ("costs.capacitor_density_f_m2", "costs.process_node_m", "costs.transistor_area_f2"),
        "latency_s": ("costs.sample_rate_hz", "costs.clock_hz", MESH_CONDUCTANCE),
        "power_w": ("costs.sample_rate_hz", "costs.process_node_m", "costs.digital_supply_v", MESH_CONDUCTANCE),
        "event_rate_eps": (),
    }
)

#: Kinds whose filter sits inside the pixel (its area competes with the photodiode's).
IN_PIXEL_KINDS = ("mesh",)

_MESH_CONDUCTANCE_RANGE = (1e-13, 1e-3)  # S: realisations.mesh.g_lateral_s's schema range
_SCAN = 49  # log-grid points over a key's range before the root is refined


@dataclass(frozen=True)
class Remedy:
    """One way to meet a broken limit (the report words it: :func:`fsdvs_hw.report.costs.remedy_text`).

    Attributes
    ----------
    key : str
        What changes: a ``[costs]`` key (``"costs.capacitor_density_f_m2"``), a realisation's knob
        (:data:`MESH_CONDUCTANCE`), ``"sensor.pitch_m"`` or ``"placement.shared_node"``.
    value : float
        The value at which the figure meets the limit (SI unit of the key; pixels per side for a
        shared node).
    now : float
        The key's present value (same unit).
    effects : mapping
        Other figures at that value, where the change moves them (``latency_s``, ``power_w``,
        ``area_m2``; SI units).
    kernel_error : float
        The relative kernel error the change costs (NaN: none; a shared node's placement error).
    """

    key: str
    value: float
    now: float
    effects: Mapping[str, float] = field(default_factory=dict)
    kernel_error: float = math.nan

    def to_dict(self) -> dict[str, Any]:
        out: dict[str, Any] = {"key": self.key, "value": self.value, "now": self.now, "effects": dict(self.effects)}
        if not math.isnan(self.kernel_error):
            out["kernel_error"] = self.kernel_error
        return out


def _cost_name(key: str) -> str:
    """The :class:`CostAssumptions` field a ``"costs.<name>"`` key names (a number; InputError otherwise)."""
    section, _, name = key.partition(".")
    info = CostAssumptions.model_fields.get(name) if section == "costs" else None
    if info is None or info.annotation is not float:
        scalars = ", ".join(n for n, f in CostAssumptions.model_fields.items() if f.annotation is float)
        raise InputError(
            f"key {key!r}: not a number of the [costs] section; allowed: {MESH_CONDUCTANCE!r} or costs.<name>, "
            f"name one of {scalars}"
        )
    return name


def _key_range(key: str) -> tuple[float, float]:
    if key == MESH_CONDUCTANCE:
        return _MESH_CONDUCTANCE_RANGE
    field = CostAssumptions.model_fields[_cost_name(key)]
    lo, hi = -math.inf, math.inf
    for m in field.metadata:  # annotated_types Ge / Gt / Le / Lt (a bound of 0 is a bound)
        for name in ("ge", "gt"):
            if getattr(m, name, None) is not None:
                lo = max(lo, float(getattr(m, name)))
        for name in ("le", "lt"):
            if getattr(m, name, None) is not None:
                hi = min(hi, float(getattr(m, name)))
    return lo, hi


def _key_now(score: Score, a: CostAssumptions, key: str) -> float:
    if key == MESH_CONDUCTANCE:
        items = {k: score.cost.value(k) for k in score.cost.items}
        return float(items.get("g_lateral_narrow", math.nan))
    return float(getattr(a, _cost_name(key)))


def _with_key(score: Score, a: CostAssumptions, key: str, value: float) -> tuple[Score, CostAssumptions]:
    """``score`` and ``a`` with ``key`` set to ``value`` (the mesh's conductances scaled together)."""
    if key != MESH_CONDUCTANCE:
        return score, a.model_copy(update={_cost_name(key): value})
    items = {k: score.cost.value(k) for k in score.cost.items}
    g0 = items.get("g_lateral_narrow", math.nan)
    if not (math.isfinite(g0) and g0 > 0):
        return score, a
    s = value / g0
    d = score.cost.to_dict()
    for name, item in d.items():
        if isinstance(item, dict) and "value" in item:
            if name.startswith("g_"):
                d[name] = {**item, "value": item["value"] * s}
            elif name.startswith("tau_"):
                d[name] = {**item, "value": item["value"] / s}
    return score.with_(cost=Cost.from_dict(d)), a


def _figure(score: Score, a: CostAssumptions, figure: str) -> float:
    return physical_cost(score, a).value(figure)


def _solve(f: Callable[[float], float], lo: float, hi: float) -> list[float]:
    """Roots of ``f`` (a log ratio) over ``[lo, hi]`` (log-spaced scan, then Brent's method)."""
    from scipy.optimize import brentq

    if not (lo > 0 and hi > lo):
        return []
    xs = np.geomspace(lo, hi, _SCAN)
    ys = np.array([f(float(x)) for x in xs])
    roots = []
    for i in range(len(xs) - 1):
        y0, y1 = ys[i], ys[i + 1]
        if not (np.isfinite(y0) and np.isfinite(y1)):
            continue
        if y0 == 0.0:
            roots.append(float(xs[i]))
        elif y0 * y1 < 0:
            u = brentq(lambda t: f(math.exp(t)), math.log(xs[i]), math.log(xs[i + 1]), xtol=1e-10, rtol=1e-10)
            roots.append(math.exp(u))
    return roots


def assumption_at(score: Score, a: CostAssumptions, key: str, figure: str, target: float) -> list[float]:
    """Values of ``key`` within its allowed range at which ``figure`` equals ``target``.

    Parameters
    ----------
    score : Score
        A scored realisation (its fitted cost items, kernel, event rates).
    a : CostAssumptions
        The ``[costs]`` section the other keys keep.
    key : str
        ``"costs.<name>"`` (a scalar :class:`CostAssumptions` key) or :data:`MESH_CONDUCTANCE`.
    figure : str
        A :class:`~fsdvs_hw.costs.record.PhysicalCost` figure (``"power_w"``, ``"area_m2"``, ...).
    target : float
        The figure's target value (its SI unit), > 0.

    Returns
    -------
    list of float
        Every crossing, ascending (empty: the figure never reaches ``target`` in the key's range).

    Raises
    ------
    InputError
        ``key`` is neither a number of the ``[costs]`` section nor :data:`MESH_CONDUCTANCE`.

    Examples
    --------
    The ASIC's array power is linear in its sample rate: 11.4 mW at 1 kHz reaches 22.8 mW at 2 kHz.

    >>> from fsdvs_hw.costs import CostAssumptions, physical_cost
    >>> from fsdvs_hw.costs.limits import assumption_at
    >>> from fsdvs_hw.kernels import reference_kernel
    >>> from fsdvs_hw.records import Cost, Score
    >>> cost = Cost.from_dict({"adders": {"value": 64, "unit": "count"},
    ...                        "accumulator_bits": {"value": 17, "unit": "bit"}})
    >>> s = Score(kind="asic", label="asic", describe="", kernel=reference_kernel("dog", 7), kernel_error=0.0,
    ...           kernel_error_gain_free=0.0, dc_gain=1.0, asymmetry=0.0, cost=cost)
    >>> p = physical_cost(s, CostAssumptions()).value("power_w")
    >>> [round(v) for v in assumption_at(s, CostAssumptions(), "costs.sample_rate_hz", "power_w", 2 * p)]
    [2000]
    """
    if not (target > 0 and math.isfinite(target)):
        return []
    lo, hi = _key_range(key)

    def f(v: float) -> float:
        s, aa = _with_key(score, a, key, v)
        x = _figure(s, aa, figure)
        return math.log(x / target) if x > 0 and math.isfinite(x) else math.nan

    return _solve(f, lo, hi)


def costed(score: Score, a: CostAssumptions) -> PhysicalCost:
    """:func:`fsdvs_hw.costs.physical_cost` with its hard limits checked: every limit broken
    (:func:`broken_limits`) in ``limits`` with its :func:`remedies`, and the budgets' flags.

    Parameters
    ----------
    score : Score
    a : CostAssumptions

    Returns
    -------
    PhysicalCost
        Its ``fits`` is False when a limit is broken.
    """
    pc = physical_cost(score, a)
    figs = pc.figures
    flags = list(pc.flags)
    broken = []
    for lim in broken_limits(score, a, {k: f.value for k, f in figs.items()}):
        if lim["figure"] in ("latency_s", "power_w"):  # the area and readout models flag their own
            unit = figs[lim["figure"]].unit
            flags.append(
                f"{lim['figure'].split('_')[0]} {lim['value']:.3g} {unit} exceeds {lim['words']} "
                f"{lim['limit']:.3g} {unit} ({lim['key']})"
            )
        broken.append({**lim, "remedies": [r.to_dict() for r in remedies(score, a, lim)]})
    return replace(pc, flags=tuple(flags), limits=tuple(broken))


def broken_limits(score: Score, a: CostAssumptions, figures: Mapping[str, float]) -> list[dict[str, Any]]:
    """The hard limits ``figures`` break (:data:`HARD_LIMITS`), each ``{figure, value, limit, key, words}``.

    ``figures`` are a :class:`~fsdvs_hw.costs.record.PhysicalCost`'s values; the area limit (the
    kernel's pitch squared, m²) holds for the kinds whose filter sits inside the pixel
    (:data:`IN_PIXEL_KINDS`).
    """
    out = []
    pitch = float(score.kernel.pitch_m)
    limits = {
        "area_m2": pitch**2 if score.kind in IN_PIXEL_KINDS else math.inf,
        "event_rate_eps": a.readout_limit_eps,
        "latency_s": a.latency_budget_s,
        "power_w": a.power_budget_w,
    }
    for name, limit in limits.items():
        v = figures.get(name, math.nan)
        if math.isfinite(v) and v > limit:
            words, key = HARD_LIMITS[name]
            out.append({"figure": name, "value": float(v), "limit": float(limit), "key": key, "words": words})
    return out


def shared_node_error(kernel: np.ndarray, k: int) -> float:
    """Relative kernel error of the best filter whose nodes are each shared by ``k`` × ``k`` pixels.

    Every k × k block of pixels sums its photocurrents into one node, the nodes filter on their own
    (block) lattice with any kernel ``M``, and each pixel reads its block's node. The operator is
    not shift-invariant; averaged over a pixel's place in its block, its kernel is
    :math:`\\bar K = k^{-2}\\, B_k * (U_k M) * B_k` (:math:`B_k`: the k × k box, :math:`U_k`: zeros
    inserted between the nodes). The error is :math:`\\min_M \\lVert \\bar K - T\\rVert / \\lVert T\\rVert`
    (linear least squares over ``M``): a lower bound for a mesh, whose ``M`` is further constrained.

    Parameters
    ----------
    kernel : array, shape (n, n)
        The target kernel T (any normalisation).
    k : int
        Pixels per node side, ≥ 1 (1: no sharing, error 0).

    Returns
    -------
    float
        Relative L2 error, in [0, 1].

    Examples
    --------
    >>> import numpy as np
    >>> from fsdvs_hw.costs.limits import shared_node_error
    >>> t = np.zeros((7, 7)); t[3, 3] = 1.0
    >>> shared_node_error(t, 1) < 1e-12, round(shared_node_error(t, 3), 3)
    (True, 0.853)
    """
    from scipy.signal import convolve2d

    t = np.asarray(kernel, dtype=np.float64)
    if k <= 1:
        return 0.0
    n = t.shape[0]
    m = math.ceil(n / k) + 1  # node offsets reaching past the target's support
    half = m // 2
    size = (2 * half) * k + 2 * k - 1  # support of the placed kernel
    box = np.ones((k, k))
    cols = []
    for i in range(-half, half + 1):
        for j in range(-half, half + 1):
            u = np.zeros((size, size))
            c = size // 2
            u[c + i * k, c + j * k] = 1.0
            kb = convolve2d(convolve2d(u, box, mode="same"), box, mode="same") / k**2
            cols.append(kb.ravel())
    a_mat = np.stack(cols, axis=1)
    tt = np.zeros((size, size))
    c0 = size // 2 - n // 2
    if c0 < 0:
        return math.nan
    tt[c0 : c0 + n, c0 : c0 + n] = t
    coef, *_ = np.linalg.lstsq(a_mat, tt.ravel(), rcond=None)
    norm = float(np.linalg.norm(t))
    return float(np.linalg.norm(a_mat @ coef - tt.ravel()) / norm) if norm > 0 else math.nan


def remedies(score: Score, a: CostAssumptions, limit: Mapping[str, Any]) -> list[Remedy]:
    """What would bring one broken limit (:func:`broken_limits`) within it, from the cost model.

    Parameters
    ----------
    score : Score
        The realisation.
    a : CostAssumptions
        The ``[costs]`` section it was costed under.
    limit : mapping
        One entry of :func:`broken_limits`.

    Returns
    -------
    list of Remedy
        For the area: the pitch at which it fits, the key values at which it fits, the smallest
        shared node (k × k pixels) that fits with its placement error; for the others, the key
        values at which the figure meets the limit (in the key's allowed range). Empty when
        nothing in reach helps (an event rate: a faster readout is the remedy, said by the
        limit itself).
    """
    figure, target = str(limit["figure"]), float(limit["limit"])
    out: list[Remedy] = []
    if figure == "area_m2":
        area = float(limit["value"])
        pitch = float(score.kernel.pitch_m)
        out.append(Remedy("sensor.pitch_m", math.sqrt(area), pitch))
        k = math.ceil(math.sqrt(area / pitch**2))
        if k >= 2:
            out.append(
                Remedy(
                    "placement.shared_node",
                    float(k),
                    1.0,
                    effects={"area_m2": area / k**2},
                    kernel_error=shared_node_error(score.kernel.taps, k),
                )
            )
    for key in _REMEDY_KEYS.get(figure, ()):
        now = _key_now(score, a, key)
        if not math.isfinite(now):
            continue
        roots = assumption_at(score, a, key, figure, target)
        if not roots:
            continue
        v = min(roots, key=lambda r: abs(math.log(r / now)))  # the nearest crossing
        s, aa = _with_key(score, a, key, v)
        effects = {f: _figure(s, aa, f) for f in ("latency_s", "power_w") if f != figure}
        out.append(Remedy(key, v, now, effects={f: x for f, x in effects.items() if math.isfinite(x)}))
    return out


def cost_flips(
    a_score: Score, b_score: Score, a: CostAssumptions, figure: str, keys: Sequence[str] | None = None
) -> list[dict[str, Any]]:
    """Where the cheaper of two realisations in ``figure`` changes, one key at a time.

    Parameters
    ----------
    a_score, b_score : Score
        Two realisations (usually of different kinds).
    a : CostAssumptions
        The ``[costs]`` values both are costed under.
    figure : str
        ``"power_w"``, ``"area_m2"`` or ``"latency_s"`` (:data:`FLIP_KEYS`).
    keys : sequence of str, optional
        The keys to vary (default :data:`FLIP_KEYS` of ``figure``).

    Returns
    -------
    list of dict
        ``{"key", "value", "now", "cheaper_now"}`` (``cheaper_now``: 0 for ``a_score``, 1 for
        ``b_score``) per key whose value ``value`` within its range makes both equal (the crossing
        nearest the present value ``now``).
    """
    out = []
    for key in keys if keys is not None else FLIP_KEYS.get(figure, ()):
        na, nb = _key_now(a_score, a, key), _key_now(b_score, a, key)
        now = na if math.isfinite(na) else nb
        if not math.isfinite(now):
            continue
        lo, hi = _key_range(key)

        def f(v: float, key: str = key) -> float:
            sa, aa = _with_key(a_score, a, key, v)
            sb, ab = _with_key(b_score, a, key, v)
            x, y = _figure(sa, aa, figure), _figure(sb, ab, figure)
            return math.log(x / y) if x > 0 and y > 0 and math.isfinite(x) and math.isfinite(y) else math.nan

        f_now = f(now)
        if not math.isfinite(f_now) or f_now == 0.0:
            continue
        roots = _solve(f, lo, hi)
        if not roots:
            continue
        v = min(roots, key=lambda r: abs(math.log(r / now)))
        out.append({"key": key, "value": v, "now": now, "cheaper_now": 0 if f_now < 0 else 1})
    return out
