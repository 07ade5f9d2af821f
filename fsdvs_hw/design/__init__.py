"""Design files: the TOML input of an exploration, read, validated and typed.

A design file says *what* to explore (kernel, sensor, optics, realisations, tasks, sweep);
every layer above reads it as a :class:`Design` (:func:`load_design`, :func:`parse_design`):

- :mod:`~fsdvs_hw.design.design`: the :class:`Design` object, reading and validating a file,
  overrides and the fingerprint;
- :mod:`~fsdvs_hw.design.sections`: the sections as pydantic models and the model of a whole
  file (:func:`design_model`, :func:`design_json_schema`);
- :mod:`~fsdvs_hw.design.keys`: dotted keys (``--set``, sweep axes) checked against the schema;
- :mod:`~fsdvs_hw.design.checks`: the checks across sections, run before any work starts;
- :mod:`~fsdvs_hw.design.checkpoints`: task checkpoint entries and their glob patterns;
- :mod:`~fsdvs_hw.design.user_data_section` and :mod:`~fsdvs_hw.design.user_data_inputs`: the
  ``[tasks.datasets.<task>]`` tables, and the datasets and networks they name;
- :mod:`~fsdvs_hw.design.display_settings`: the emulation track's display (``[emulation]``).

The exploration pipeline that runs a design is :mod:`fsdvs_hw.explore`.
"""

from __future__ import annotations

from .design import Design, load_design, parse_design
from .keys import check_key
from .problems import DesignError
from .sections import design_json_schema, design_model

__all__ = [
    "Design",
    "DesignError",
    "check_key",
    "design_json_schema",
    "design_model",
    "load_design",
    "parse_design",
]
