"""Named sensor presets for real event cameras, every value with its source.

A :class:`SensorPreset` describes one camera (DVS128, DAVIS346, Prophesee/Sony IMX636 as in the
EVK4) or one of v2e's parameter sets by a small record per quantity (:class:`SourcedValue`):
the value, its unit, where it comes from and how sure that is. ``status`` is one of

``"published"``
    stated in the cited paper, datasheet or code (the citation names where);
``"unverified"``
    recalled from the named source but not checked against it here: verify before relying on it;
``"assumed"``
    no source: a stated assumption (usually v2e's default, which v2e's authors tuned to a
    DAVIS346) and the reason.

Thresholds are natural-log units: a contrast threshold of ``c`` (fractional change of intensity)
is stored as ``ln(1 + c)``. :meth:`SensorPreset.config` turns a preset into the simulator's
:class:`~fsdvs_hw.sensor.SensorConfig`; resolution, pixel pitch and latency are descriptive only
(the simulator takes its size from the video and does not model latency).
:func:`presets_markdown` renders the table of ``docs/sensors.md``.

References
----------
.. [1] P. Lichtsteiner, C. Posch, T. Delbruck, "A 128x128 120 dB 15 µs Latency Asynchronous
   Temporal Contrast Vision Sensor", IEEE J. Solid-State Circuits 43(2), 2008.
.. [2] iniVation AG, DAVIS346 datasheet / product specifications (346 x 260 pixels, 18.5 µm pitch).
.. [3] T. Finateu et al., "A 1280x720 Back-Illuminated Stacked Temporal Contrast Event-Based Vision
   Sensor with 4.86 µm Pixels, 1.066 GEPS Readout, Programmable Event-Rate Controller and
   Compressive Data-Formatting Pipeline", ISSCC 2020, paper 5.10 (Prophesee Gen4.1 = Sony IMX636).
.. [4] Y. Hu, S.-C. Liu, T. Delbruck, "v2e: From Video Frames to Realistic DVS Events", CVPR
   Workshops 2021; code github.com/SensorsINI/v2e, ``v2ecore/emulator.py`` (``set_dvs_params``)
   and ``v2ecore/v2e_args.py`` (command-line defaults).

Examples
--------
>>> from fsdvs_hw.sensor.cameras.presets import sensor_preset
>>> p = sensor_preset("dvs128")
>>> p.values["pitch_um"].value, p.values["pitch_um"].status
(40.0, 'published')
>>> round(p.config().threshold_sigma, 3)
0.021
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from ...errors import InputError
from ..simulation.config import SensorConfig

__all__ = [
    "DOC_BLOCKS",
    "PRESET_FIELDS",
    "SENSOR_PRESETS",
    "STATUSES",
    "SensorPreset",
    "SourcedValue",
    "preset_input_mapping",
    "presets_markdown",
    "sensor_config",
    "sensor_preset",
    "splice_block",
    "write_presets_page",
]

#: How sure a value is (see the module documentation).
STATUSES = ("published", "unverified", "assumed")

#: quantity -> (unit, description); the rows of every preset, in table order.
PRESET_FIELDS: dict[str, tuple[str, str]] = {
    "width_px": ("px", "array width"),
    "height_px": ("px", "array height"),
    "pitch_um": ("µm", "pixel pitch"),
    "threshold_on": ("ln", "ON threshold (log units)"),
    "threshold_off": ("ln", "OFF threshold (log units)"),
    "threshold_sigma": ("ln", "threshold mismatch, per-pixel standard deviation"),
    "refractory_s": ("s", "refractory period"),
    "cutoff_hz": ("Hz", "photoreceptor bandwidth at full scale (0: none)"),
    "leak_rate_hz": ("Hz", "leak-event rate per pixel"),
    "shot_noise_rate_hz": ("Hz", "shot-noise event rate per pixel (ON + OFF)"),
    "latency_s": ("s", "pixel latency (descriptive; not modelled)"),
}
# fsdvs_hw.scenes.video.INPUT_MAPPINGS (repeated: reading a preset does not import the video module)
_INPUT_MAPPINGS = ("linear_light", "v2e_gray")
# the quantities SensorConfig takes
_CONFIG_FIELDS = (
    "threshold_on",
    "threshold_off",
    "threshold_sigma",
    "refractory_s",
    "cutoff_hz",
    "leak_rate_hz",
    "shot_noise_rate_hz",
)


@dataclass(frozen=True)
class SourcedValue:
    """One quantity of a preset and where it comes from.

    Parameters
    ----------
    value : float or None
        The value in ``PRESET_FIELDS[name][0]`` units; None where no value is given.
    source : str
        Citation (authors, venue, year, table/page) or, for ``"assumed"``, the reason.
    status : {"published", "unverified", "assumed"}
        How sure the value is (module documentation).
    """

    value: float | int | None
    source: str
    status: str = "published"

    def __post_init__(self) -> None:
        if self.status not in STATUSES:
            raise InputError(f"SourcedValue.status: {self.status!r} unknown; allowed: {', '.join(STATUSES)}")
        if not self.source.strip():
            raise InputError("SourcedValue.source: empty; every value needs a source or an assumption's reason")


@dataclass(frozen=True)
class SensorPreset:
    """A named sensor: every quantity of :data:`PRESET_FIELDS` as a :class:`SourcedValue`.

    Parameters
    ----------
    name : str
        Preset name (lower case, e.g. ``"davis346"``).
    description : str
        One line: the camera and its references.
    values : dict of str to SourcedValue
        One entry per key of :data:`PRESET_FIELDS`.
    base : dict
        Further :class:`SensorConfig` fields fixed by the preset (model choices, not camera data).
    input_mapping : {"linear_light", "v2e_gray"}
        How a video file's code values become intensity (:data:`fsdvs_hw.scenes.video.INPUT_MAPPINGS`):
        linear light for a camera (a pixel responds to photons); v2e's gray code values for the
        v2e presets, so that they reproduce v2e from the same file.
    """

    name: str
    description: str
    values: dict[str, SourcedValue]
    base: dict[str, Any] = field(default_factory=dict)
    input_mapping: str = "linear_light"

    def __post_init__(self) -> None:
        missing = set(PRESET_FIELDS) - set(self.values)
        extra = set(self.values) - set(PRESET_FIELDS)
        if missing or extra:
            raise InputError(f"SensorPreset {self.name!r}: fields missing {sorted(missing)}, unknown {sorted(extra)}")
        if self.input_mapping not in _INPUT_MAPPINGS:
            raise InputError(
                f"SensorPreset {self.name!r}: input_mapping {self.input_mapping!r} unknown; allowed: "
                f"{', '.join(_INPUT_MAPPINGS)}"
            )

    def config(self, **overrides: Any) -> SensorConfig:
        """The simulator's :class:`SensorConfig` for this preset; ``overrides`` replace any field."""
        kw = dict(self.base)
        kw.update({k: self.values[k].value for k in _CONFIG_FIELDS})
        kw.update(overrides)
        if self.name.startswith("v2e-"):
            return SensorConfig.preset(self.name, **{k: v for k, v in kw.items() if k not in self.base})
        return SensorConfig(**kw)


def _pub(value: float | None, source: str) -> SourcedValue:
    return SourcedValue(value, source, "published")


def _unv(value: float | None, source: str) -> SourcedValue:
    return SourcedValue(value, source, "unverified")


def _ass(value: float | None, reason: str) -> SourcedValue:
    return SourcedValue(value, reason, "assumed")


_V2E = "v2e (Hu, Liu & Delbruck, CVPR-W 2021)"
_V2E_TUNED = "v2e's default, which v2e's authors matched to a DAVIS346 [4]; no published value for this camera"
_NOT_MODELLED = "not given here (latency is not modelled by the simulator)"
_SIZE_FROM_VIDEO = "v2e takes the size of the input video (no fixed array)"


def _v2e_preset(name: str, description: str, code_place: str) -> SensorPreset:
    cfg = SensorConfig.preset(name)
    src = f"{_V2E}, {code_place}"
    values = {
        "width_px": _ass(None, _SIZE_FROM_VIDEO),
        "height_px": _ass(None, _SIZE_FROM_VIDEO),
        "pitch_um": _ass(None, "v2e has no pixel pitch (an emulator, not a chip)"),
        "latency_s": _ass(None, _NOT_MODELLED),
    }
    for k in _CONFIG_FIELDS:
        values[k] = _pub(float(getattr(cfg, k)), src)
    return SensorPreset(name, description, values, input_mapping="v2e_gray")


# a camera has been running before a recording starts: each pixel's leak cycle is at a random phase
# (as v2e's presets with leak); otherwise the first leak event of every pixel comes 1 / leak_rate_hz late
_CAMERA_BASE: dict[str, Any] = {"random_reference_phase": True}
_LICHTSTEINER = "Lichtsteiner, Posch & Delbruck, IEEE JSSC 43(2), 2008"
_FINATEU = "Finateu et al., ISSCC 2020, paper 5.10"

_PRESET_LIST = [
    SensorPreset(
        "dvs128",
        "DVS128 (Lichtsteiner, Posch & Delbruck, IEEE JSSC 2008)",
        {
            "width_px": _pub(128, f"{_LICHTSTEINER}, title (128x128)"),
            "height_px": _pub(128, f"{_LICHTSTEINER}, title (128x128)"),
            "pitch_um": _pub(40.0, f"{_LICHTSTEINER}, abstract and specification table (40 x 40 µm² pixel)"),
            "threshold_on": _unv(
                round(math.log(1.15), 4),
                f"{_LICHTSTEINER}: about 15 % contrast at the "
                "characterisation biases (bias-dependent, not a chip constant)",
            ),
            "threshold_off": _unv(
                round(math.log(1.15), 4),
                f"{_LICHTSTEINER}: about 15 % contrast at the "
                "characterisation biases (bias-dependent, not a chip constant)",
            ),
            "threshold_sigma": _pub(
                0.021, f"{_LICHTSTEINER}, abstract: 2.1 % contrast-threshold mismatch (ln(1 + c) ≈ c at 2 %)"
            ),
            "refractory_s": _ass(5e-4, "bias-dependent (refractory bias); v2e's default 0.5 ms"),
            "cutoff_hz": _ass(
                300.0,
                "bandwidth grows with photocurrent [1] (bias- and light-dependent); v2e's default 300 Hz at full scale",
            ),
            "leak_rate_hz": _ass(0.01, "junction leakage, temperature-dependent; v2e's default 0.01 Hz"),
            "shot_noise_rate_hz": _ass(1e-3, "light-dependent; v2e's default 0.001 Hz"),
            "latency_s": _pub(15e-6, f"{_LICHTSTEINER}, title (15 µs at high illuminance)"),
        },
        _CAMERA_BASE,
    ),
    SensorPreset(
        "davis346",
        "DAVIS346 (iniVation AG datasheet; the DAVIS pixel of Brandli et al., IEEE JSSC 2014, DAVIS240)",
        {
            "width_px": _pub(346, "iniVation DAVIS346 datasheet (346 x 260 pixels)"),
            "height_px": _pub(260, "iniVation DAVIS346 datasheet (346 x 260 pixels)"),
            "pitch_um": _pub(18.5, "iniVation DAVIS346 datasheet (18.5 µm pixel)"),
            "threshold_on": _unv(
                round(math.log(1.143), 4),
                "iniVation DAVIS346 specifications, contrast "
                "sensitivity 14.3 % ON (recalled, not checked against the current PDF)",
            ),
            "threshold_off": _unv(
                round(math.log(1.225), 4),
                "iniVation DAVIS346 specifications, contrast "
                "sensitivity 22.5 % OFF (recalled, not checked against the current PDF)",
            ),
            "threshold_sigma": _ass(0.03, _V2E_TUNED),
            "refractory_s": _ass(5e-4, _V2E_TUNED),
            "cutoff_hz": _ass(300.0, _V2E_TUNED),
            "leak_rate_hz": _ass(0.01, _V2E_TUNED),
            "shot_noise_rate_hz": _ass(1e-3, _V2E_TUNED),
            "latency_s": _ass(None, _NOT_MODELLED),
        },
        _CAMERA_BASE,
    ),
    SensorPreset(
        "imx636",
        "Prophesee Gen4.1 / Sony IMX636, as in the EVK4 (Finateu et al., ISSCC 2020)",
        {
            "width_px": _pub(1280, f"{_FINATEU}, title (1280x720)"),
            "height_px": _pub(720, f"{_FINATEU}, title (1280x720)"),
            "pitch_um": _pub(4.86, f"{_FINATEU}, title (4.86 µm pixels)"),
            "threshold_on": _ass(
                0.2, "no published nominal threshold checked here (bias-programmable); v2e's default 0.2"
            ),
            "threshold_off": _ass(
                0.2, "no published nominal threshold checked here (bias-programmable); v2e's default 0.2"
            ),
            "threshold_sigma": _ass(0.03, "no published mismatch checked here; v2e's default 0.03"),
            "refractory_s": _ass(5e-4, "bias-programmable (bias_refr); v2e's default 0.5 ms"),
            "cutoff_hz": _ass(300.0, "bias-programmable (bias_fo); v2e's default 300 Hz"),
            "leak_rate_hz": _ass(0.01, "no published background rate checked here; v2e's default 0.01 Hz"),
            "shot_noise_rate_hz": _ass(1e-3, "light-dependent, no published value checked here; v2e's 0.001 Hz"),
            "latency_s": _ass(None, _NOT_MODELLED),
        },
        _CAMERA_BASE,
    ),
    _v2e_preset(
        "v2e-clean", "v2e --dvs_params clean (v2e's frame mapping)", "v2ecore/emulator.py set_dvs_params('clean')"
    ),
    _v2e_preset("v2e-default", "v2e command-line defaults (v2e's frame mapping)", "v2ecore/v2e_args.py defaults"),
    _v2e_preset(
        "v2e-noisy", "v2e --dvs_params noisy (v2e's frame mapping)", "v2ecore/emulator.py set_dvs_params('noisy')"
    ),
]

#: preset name -> :class:`SensorPreset`
SENSOR_PRESETS: dict[str, SensorPreset] = {p.name: p for p in _PRESET_LIST}


def sensor_preset(name: str) -> SensorPreset:
    """The preset called ``name`` (case-insensitive; see :data:`SENSOR_PRESETS`).

    Raises
    ------
    InputError
        Unknown name (the message lists the allowed ones).

    Examples
    --------
    >>> sensor_preset("IMX636").values["width_px"].value
    1280
    """
    key = str(name).lower()
    if key not in SENSOR_PRESETS:
        raise InputError(f"sensor preset {name!r} unknown; allowed: {', '.join(SENSOR_PRESETS)}")
    return SENSOR_PRESETS[key]


def sensor_config(name: str, **overrides: Any) -> SensorConfig:
    """The :class:`SensorConfig` of preset ``name`` (a camera here or any of ``SensorConfig.preset``'s names).

    Examples
    --------
    >>> sensor_config("davis346").threshold_off > sensor_config("davis346").threshold_on
    True
    >>> sensor_config("ideal").threshold_sigma
    0.0
    """
    if str(name).lower() in SENSOR_PRESETS:
        return sensor_preset(name).config(**overrides)
    from ..simulation.config import PRESETS

    if name in PRESETS:
        return SensorConfig.preset(name, **overrides)
    raise InputError(f"sensor preset {name!r} unknown; allowed: {', '.join([*SENSOR_PRESETS, *PRESETS])}")


def preset_input_mapping(name: str) -> str:
    """How ``simulate`` maps a video file's code values for preset ``name`` (any preset name).

    ``"v2e_gray"`` for v2e's parameter sets (``v2e-clean``, ``v2e-default``, ``v2e-noisy``): v2e's
    gray code values as intensity; ``"linear_light"`` for every other preset (display decoding).

    Examples
    --------
    >>> preset_input_mapping("v2e-default"), preset_input_mapping("default"), preset_input_mapping("imx636")
    ('v2e_gray', 'linear_light', 'linear_light')
    """
    key = str(name).lower()
    if key in SENSOR_PRESETS:
        return SENSOR_PRESETS[key].input_mapping
    sensor_config(name)  # unknown names raise InputError with the allowed ones
    return "linear_light"


def _cell(v: SourcedValue) -> str:
    if v.value is None:
        return "—"
    x = v.value
    text = f"{x:g}" if isinstance(x, float) else str(x)
    return text if v.status == "published" else f"{text} ({v.status[0]})"


def presets_markdown() -> str:
    """The presets as Markdown: one value table and one source list per preset (``docs/sensors.md``).

    In the value table ``(u)`` marks unverified and ``(a)`` assumed values; the source lists give
    every value's citation or reason.

    Examples
    --------
    >>> presets_markdown().splitlines()[0].startswith("| quantity |")
    True
    """
    names = list(SENSOR_PRESETS)
    lines = ["| quantity | unit | " + " | ".join(f"`{n}`" for n in names) + " |", "|---|---|" + "---|" * len(names)]
    for k, (unit, desc) in PRESET_FIELDS.items():
        lines.append(
            f"| {desc} (`{k}`) | {unit} | " + " | ".join(_cell(SENSOR_PRESETS[n].values[k]) for n in names) + " |"
        )
    lines.append("")
    lines.append(
        "(u) unverified: recalled from the named source, not checked here; (a) assumed: no source, "
        "reason given below; — no value."
    )
    for n in names:
        p = SENSOR_PRESETS[n]
        lines += ["", f"**`{n}`** — {p.description}", ""]
        for k in PRESET_FIELDS:
            v = p.values[k]
            lines.append(f"- `{k}` = {_cell(v)}: {v.status}; {v.source}")
    return "\n".join(lines) + "\n"


#: Markers of the generated block in ``docs/sensors.md``; name -> (begin, end).
DOC_BLOCKS = {
    name: (f"<!-- generated:{name} begin (do not edit; regenerate) -->", f"<!-- generated:{name} end -->")
    for name in ("presets", "calibration")
}


def splice_block(text: str, name: str, content: str) -> str:
    """``text`` with the generated block ``name`` (:data:`DOC_BLOCKS`) replaced by ``content``.

    Raises
    ------
    InputError
        The page lacks the block's markers.

    Examples
    --------
    >>> b, e = DOC_BLOCKS["presets"]
    >>> splice_block(f"a\\n{b}\\nold\\n{e}\\nz", "presets", "new\\n")
    'a\\n<!-- generated:presets begin (do not edit; regenerate) -->\\nnew\\n<!-- generated:presets end -->\\nz'
    """
    begin, end = DOC_BLOCKS[name]
    i, j = text.find(begin), text.find(end)
    if i < 0 or j < i:
        raise InputError(f"page: no generated block {name!r} (markers {begin!r} ... {end!r})")
    return text[: i + len(begin)] + "\n" + content + text[j:]


def write_presets_page(path: str | Path) -> Path:
    """Regenerate the presets table inside ``path`` (``docs/sensors.md``), atomically.

    Run as ``python -m fsdvs_hw.sensor.cameras.presets docs/sensors.md``.
    """
    from ...paths import write_output

    p = Path(path)
    return write_output(p, splice_block(p.read_text(encoding="utf-8"), "presets", presets_markdown()), flag="path")


if __name__ == "__main__":  # pragma: no cover - the page's regeneration command
    import sys

    print(write_presets_page(sys.argv[1] if len(sys.argv) > 1 else "docs/sensors.md"))
