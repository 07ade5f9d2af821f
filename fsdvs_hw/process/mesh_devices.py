r"""The mesh's conductances as subthreshold pass transistors, biased by a fit against the process models.

Circuit (one mesh; the narrow and the wide mesh are two copies with their own biases). Every mesh
node sits at the reference voltage :math:`V_r` at rest. Each lateral conductance is an NMOS pass
transistor between neighbouring nodes, its gate at :math:`V_{g,l}`; each vertical conductance is an
NMOS pass transistor from the node to :math:`V_r`, gate at :math:`V_{g,v}`; bodies at ground. With
no signal every device has :math:`V_{ds} = 0` and carries no current, so the operating point is the
same in every node and each device is, for small signals, a conductance

.. math:: g(V_g) = \left.\frac{\partial I_d}{\partial V_d}\right|_{V_d = V_s = V_r}
          \approx \frac{I_0}{U_T}\, e^{(\kappa (V_g - V_{T0}) - V_r)/U_T}

in weak inversion (Mead 1989, ch. 5 and 7): one gate bias per conductance, the ratio of two
conductances :math:`e^{\kappa \Delta V_g / U_T}`. The injected signal (a photocurrent copied into the
node) is an ideal current source here, and each node's output is the current through its vertical
device (read by a current mirror, whose own mismatch is not modelled), so the mesh's normalised
response is :math:`H = i_v / i_{in}`, independent of the readout's gain. Linear for node swings well
below :math:`U_T` (26 mV at 27 °C).

:func:`characterise_conductance` measures :math:`g(V_g)` of one device size at a corner and
temperature with ngspice (an ``.ac`` analysis of one device per gate voltage, drain and source at
:math:`V_r`); :func:`fit_mesh_bias` inverts it (log-linear interpolation) for the four conductances
of a :class:`~fsdvs_hw.realise.mesh.MeshDesign` and checks each bias lies in weak inversion (the local
slope of :math:`\ln g` against :math:`V_g` at least :data:`SUBTHRESHOLD_SLOPE_FRACTION` of its
largest) and above the leakage floor.

References
----------
C. Mead, *Analog VLSI and Neural Systems*, Addison-Wesley 1989 (subthreshold MOS, ch. 3; resistive
networks, ch. 7). C. Mead, M. Mahowald, "A silicon model of early visual processing", Neural
Networks 1 (1988) 91-97.

Examples
--------
>>> from fsdvs_hw.process.mesh_devices import DeviceSize
>>> DeviceSize(1.0, 2.0).area_um2
2.0
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, field
from typing import Any

import numpy as np

from ..errors import InputError
from .ngspice import NGSPICE_OPTIONS, run_deck
from .registry import get_process

__all__ = [
    "CONDUCTANCE_NAMES",
    "GATE_GRID_V",
    "SUBTHRESHOLD_SLOPE_FRACTION",
    "ConductanceCurve",
    "DeviceSize",
    "MeshBias",
    "characterisation_deck",
    "characterise_conductance",
    "device_conductances",
    "fit_mesh_bias",
]

#: The four conductances of a dual mesh, in the order of the bias vector.
CONDUCTANCE_NAMES: tuple[str, ...] = ("lateral_narrow", "vertical_narrow", "lateral_wide", "vertical_wide")
#: Gate voltages of the characterisation (V): 0 … 1.8 V in 10 mV steps.
GATE_GRID_V = np.round(np.arange(0.0, 1.8001, 0.01), 6)
#: A bias is in weak inversion where d ln g / dV_g is at least this fraction of its largest value.
SUBTHRESHOLD_SLOPE_FRACTION = 0.8
#: A bias must give a conductance at least this many times the leakage floor (g at V_g = 0 V).
LEAKAGE_MARGIN = 100.0


@dataclass(frozen=True)
class DeviceSize:
    """Drawn width and length of a mesh transistor (µm; sky130 models take µm, ``scale=1u``).

    Attributes
    ----------
    w_um, l_um : float
        Width and length (µm); ≥ 0.42 and ≥ 0.15 (the nfet_01v8 minimums).
    """

    w_um: float = 1.0
    l_um: float = 2.0

    def __post_init__(self) -> None:
        if not (isinstance(self.w_um, (int, float)) and 0.42 <= self.w_um <= 100):
            raise InputError(f"device width w_um = {self.w_um!r}: allowed 0.42 … 100 µm")
        if not (isinstance(self.l_um, (int, float)) and 0.15 <= self.l_um <= 100):
            raise InputError(f"device length l_um = {self.l_um!r}: allowed 0.15 … 100 µm")

    @property
    def area_um2(self) -> float:
        """Gate area W·L (µm²)."""
        return float(self.w_um * self.l_um)


@dataclass(frozen=True)
class ConductanceCurve:
    """Small-signal conductance of one device size against its gate voltage at one condition.

    Attributes
    ----------
    gate_v : ndarray
        Gate voltages (V).
    conductance_s : ndarray
        :math:`\\partial I_d/\\partial V_d` at :math:`V_d = V_s = V_r` (S).
    pdk, corner : str
        Process and corner (``"sky130"``, ``"tt"``).
    temperature_c, reference_v : float
        Temperature (°C) and the source/drain voltage :math:`V_r` (V).
    size : DeviceSize
        The device measured.
    """

    gate_v: np.ndarray
    conductance_s: np.ndarray
    pdk: str
    corner: str
    temperature_c: float
    reference_v: float
    size: DeviceSize

    def subthreshold_range_s(self) -> tuple[float, float]:
        """The conductances (S) reachable in weak inversion: above the leakage floor × margin, and
        where the log-slope is ≥ :data:`SUBTHRESHOLD_SLOPE_FRACTION` of its largest."""
        lg = np.log(np.maximum(self.conductance_s, 1e-30))
        slope = np.gradient(lg, self.gate_v)
        peak = int(np.argmax(slope))
        ok = slope >= SUBTHRESHOLD_SLOPE_FRACTION * slope[peak]
        hi = peak
        while hi + 1 < len(ok) and ok[hi + 1]:
            hi += 1
        lo_g = max(float(self.conductance_s[0]) * LEAKAGE_MARGIN, float(self.conductance_s[: peak + 1].min()))
        return lo_g, float(self.conductance_s[hi])

    def gate_for(self, conductance_s: float) -> float:
        """Gate voltage (V) giving ``conductance_s`` (log-linear interpolation of the curve)."""
        lg = np.log(np.maximum(self.conductance_s, 1e-30))
        order = np.argsort(lg)
        return float(np.interp(math.log(conductance_s), lg[order], self.gate_v[order]))


def characterisation_deck(
    pdk: str, corner: str, temperature_c: float, reference_v: float, gates: np.ndarray, size: DeviceSize
) -> str:
    from . import sky130

    if pdk != "sky130":  # the deck's device names and .lib line are sky130's; another PDK brings its own
        raise InputError(f"[process] pdk = {pdk!r}: the transistor mesh is written for sky130 only")
    lines = [
        f"* fsdvs_hw: {sky130.NFET} W/L = {size.w_um}/{size.l_um} µm, g = dId/dVd at Vd = Vs = {reference_v} V",
        sky130.lib_line(corner),
        NGSPICE_OPTIONS,
        f".temp {float(temperature_c)!r}",
        f"VREF vref 0 DC {float(reference_v)!r}",
    ]
    for k, vg in enumerate(gates):
        lines += [
            f"VG{k} g{k} 0 DC {float(vg)!r}",
            f"VD{k} d{k} vref DC 0 AC 1",
            f"X{k} d{k} g{k} vref 0 {sky130.NFET} w={size.w_um!r} l={size.l_um!r}",
        ]
    lines += [".ac lin 1 1e-3 1e-3", ".options filetype=ascii", ".end", ""]
    return "\n".join(lines)


def device_conductances(
    gate_v: Any,
    *,
    pdk: str = "sky130",
    corner: str = "tt",
    temperature_c: float = 27.0,
    reference_v: float = 0.5,
    size: DeviceSize | None = None,
) -> np.ndarray:
    """Small-signal conductances (S) of one device per gate voltage in ``gate_v``, from ngspice."""
    size = size or DeviceSize()
    gates = np.atleast_1d(np.asarray(gate_v, dtype=float))
    spec = get_process(pdk)
    spec.corner_section(corner)
    if not (-55.0 <= float(temperature_c) <= 150.0):
        raise InputError(f"[process] temperature_c = {temperature_c!r}: allowed -55 … 150 °C")
    if not (0.0 <= float(reference_v) <= spec.supply_v):
        raise InputError(f"[process] reference_v = {reference_v!r}: allowed 0 … {spec.supply_v} V")
    out = run_deck(characterisation_deck(pdk, corner, temperature_c, reference_v, gates, size))
    return np.array([-out[f"i(vd{k})"][0].real for k in range(len(gates))])


def characterise_conductance(
    *,
    pdk: str = "sky130",
    corner: str = "tt",
    temperature_c: float = 27.0,
    reference_v: float = 0.5,
    size: DeviceSize | None = None,
) -> ConductanceCurve:
    """:math:`g(V_g)` of one device over :data:`GATE_GRID_V` at a corner and temperature (one ngspice run).

    Examples
    --------
    >>> curve = characterise_conductance()  # doctest: +SKIP
    >>> 1e-14 < curve.subthreshold_range_s()[0] < 1e-11  # doctest: +SKIP
    True
    """
    size = size or DeviceSize()
    g = device_conductances(
        GATE_GRID_V, pdk=pdk, corner=corner, temperature_c=temperature_c, reference_v=reference_v, size=size
    )
    return ConductanceCurve(GATE_GRID_V.copy(), g, pdk, corner, float(temperature_c), float(reference_v), size)


@dataclass(frozen=True)
class MeshBias:
    """Gate biases of a dual transistor mesh, fitted at one condition.

    Attributes
    ----------
    gate_v : dict
        Conductance name (:data:`CONDUCTANCE_NAMES`) → gate voltage (V).
    target_s : dict
        The conductances the biases were fitted to (S).
    fitted_s : dict
        The conductances ngspice gives at those biases (S), at the fit's condition.
    reference_v : float
        The nodes' rest voltage :math:`V_r` (V).
    size : DeviceSize
        All mesh devices' size.
    pdk, corner : str
        Process and the corner of the fit (``"tt"``).
    temperature_c : float
        Temperature of the fit (°C).
    subthreshold_range_s : tuple of float
        Conductances reachable in weak inversion at the fit's condition (S).
    """

    gate_v: dict[str, float]
    target_s: dict[str, float]
    fitted_s: dict[str, float]
    reference_v: float
    size: DeviceSize
    pdk: str = "sky130"
    corner: str = "tt"
    temperature_c: float = 27.0
    subthreshold_range_s: tuple[float, float] = field(default=(0.0, 0.0))

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready form."""
        return {**asdict(self), "size": asdict(self.size), "subthreshold_range_s": list(self.subthreshold_range_s)}

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> MeshBias:
        """Inverse of :meth:`to_dict`."""
        d = dict(data)
        d["size"] = DeviceSize(**d["size"])
        d["subthreshold_range_s"] = tuple(d.get("subthreshold_range_s", (0.0, 0.0)))
        return cls(**d)


def fit_mesh_bias(
    design: Any,
    *,
    pdk: str = "sky130",
    corner: str = "tt",
    temperature_c: float = 27.0,
    reference_v: float = 0.5,
    size: DeviceSize | None = None,
) -> MeshBias:
    """Gate biases that make the devices reproduce ``design``'s four conductances at one condition.

    Parameters
    ----------
    design : MeshDesign
        The fitted ideal mesh (its ``g_lateral_narrow_s`` … ``g_vertical_wide_s``).
    pdk, corner, temperature_c, reference_v, size
        The condition and device size of the fit (nominal: sky130 tt, 27 °C, V_r = 0.5 V, W/L = 1/2 µm).

    Returns
    -------
    MeshBias
        With ``fitted_s`` measured by a second ngspice run at the fitted biases.

    Raises
    ------
    InputError
        A target conductance lies outside the devices' weak-inversion range at this condition
        (the message gives the range and says to change the device size or ``reference_v``).
    """
    size = size or DeviceSize()
    curve = characterise_conductance(
        pdk=pdk, corner=corner, temperature_c=temperature_c, reference_v=reference_v, size=size
    )
    lo, hi = curve.subthreshold_range_s()
    targets = {n: float(getattr(design, f"g_{n}_s")) for n in CONDUCTANCE_NAMES}
    for name, g in targets.items():
        if not lo <= g <= hi:
            raise InputError(
                f"mesh conductance g_{name} = {g:.3g} S: outside the weak-inversion range {lo:.3g} … {hi:.3g} S of "
                f"{pdk} nfet W/L = {size.w_um}/{size.l_um} µm at {corner} {temperature_c} °C, V_r = {reference_v} V; "
                "change the device size or reference_v, or fit the mesh within this range"
            )
    gates = {n: curve.gate_for(g) for n, g in targets.items()}
    measured = device_conductances(
        [gates[n] for n in CONDUCTANCE_NAMES],
        pdk=pdk,
        corner=corner,
        temperature_c=temperature_c,
        reference_v=reference_v,
        size=size,
    )
    fitted = dict(zip(CONDUCTANCE_NAMES, (float(v) for v in measured)))
    return MeshBias(gates, targets, fitted, float(reference_v), size, pdk, corner, float(temperature_c), (lo, hi))
