"""Dotted design keys (``--set KEY=VALUE``, sweep axes): checked against the schema, made canonical, set.

``"asic.bits"`` is short for ``"realisations.asic.bits"``; a key names one value of the layout
(:mod:`fsdvs_hw.design.sections`), and one level deeper only inside a table-valued key. Inside a
``[tasks.datasets.<task>]`` table a key reaches one value of the table, of its ``dataset``,
``train`` or ``network_options`` (``tasks.datasets.recognition.dataset.root``,
``tasks.datasets.recognition.train.epochs_joint``); ``tasks.datasets.recognition.root`` is short
for ``tasks.datasets.recognition.dataset.root`` (a key of the dataset that is not one of the table).
"""

from __future__ import annotations

import difflib
from typing import Any

from ..realise.registry import get_realisation
from .problems import DesignError
from .sections import is_table_field, option_tables, section_keys, section_models
from .user_data_section import ClipCacheSpec, TrainSpec, UserTask, source_models

__all__ = ["canonical_key", "check_key", "set_dotted_key"]


def canonical_key(key: str) -> str:
    """``key`` with a realisation's options under ``realisations.`` (``"asic.bits"`` → ``"realisations.asic.bits"``)
    and a dataset key of a ``[tasks.datasets.<task>]`` table under ``dataset.``
    (``"tasks.datasets.recognition.root"`` → ``"tasks.datasets.recognition.dataset.root"``).

    Examples
    --------
    >>> canonical_key("tasks.datasets.recognition.root")
    'tasks.datasets.recognition.dataset.root'
    >>> canonical_key("tasks.datasets.recognition.n_clips")
    'tasks.datasets.recognition.n_clips'
    """
    first = key.split(".", 1)[0]
    if first in option_tables():
        return "realisations." + key
    parts = key.split(".")
    if (
        parts[:2] == ["tasks", "datasets"]
        and len(parts) >= 4
        and parts[3] not in UserTask.model_fields
        and any(parts[3] in m.model_fields for m in source_models())
    ):
        return ".".join([*parts[:3], "dataset", *parts[3:]])
    return key


def _dataset_table_key(key: str, cparts: list[str], what: str) -> str:
    """Check a key inside a ``[tasks.datasets.<task>]`` table (``cparts`` canonical, 4 parts or more)."""
    field, rest = cparts[3], cparts[4:]
    dataset_keys = sorted({k for m in source_models() for k in m.model_fields})
    nested: dict[str, list[str]] = {
        "dataset": dataset_keys,
        "train": sorted(TrainSpec.model_fields),
    }
    shown = repr(key[:80])
    if field not in UserTask.model_fields:
        close = difflib.get_close_matches(field, [*UserTask.model_fields, *dataset_keys], n=3, cutoff=0.6)
        hint = f"did you mean {', '.join(close)}? " if close else ""
        raise DesignError(
            f"{what} {shown}: unknown key {field[:40]!r} of a [tasks.datasets.<task>] table; {hint}allowed: "
            f"{', '.join(UserTask.model_fields)}, or a dataset key ({', '.join(dataset_keys)})"
        )
    if not rest:
        return ".".join(cparts)
    if field == "network_options" and len(rest) == 1:
        return ".".join(cparts)
    if field not in nested:
        raise DesignError(f"{what} {shown}: tasks.datasets.<task>.{field} is a single value, not a table")
    if rest[0] not in nested[field]:
        close = difflib.get_close_matches(rest[0], nested[field], n=3, cutoff=0.6)
        hint = f"did you mean {', '.join(close)}? " if close else ""
        raise DesignError(
            f"{what} {shown}: unknown key {rest[0][:40]!r} of {field}; {hint}allowed: {', '.join(nested[field])}"
        )
    deeper = field == "dataset" and rest[0] == "cache" and len(rest) == 2 and rest[1] in ClipCacheSpec.model_fields
    if len(rest) > 1 and not deeper:
        raise DesignError(f"{what} {shown}: {field}.{rest[0]} is a single value, not a table")
    return ".".join(cparts)


def _all_keys() -> list[str]:
    """Every dotted key a design accepts (sections' keys and realisation options), for messages."""
    keys = [f"{s}.{k}" for s in section_models() for k in section_keys(s)]
    for name in option_tables():
        keys.extend(f"{name}.{opt}" for opt in get_realisation(name).options.model_fields)
    return keys


def check_key(key: str, *, what: str = "--set") -> str:
    """Check a dotted design key (``--set KEY=...``, a sweep axis) against the schema; return its
    canonical form (``"asic.bits"`` → ``"realisations.asic.bits"``).

    A key must name one value of the layout: ``section.key``, ``realisation.option`` (or
    ``realisations.realisation.option``), and one level deeper only inside a table-valued key
    (``kernel.params.sigma_centre_px``, ``tasks.n_test.detection``) or a structured fit option.

    Parameters
    ----------
    key : str
        The dotted key as the user wrote it.
    what : str
        How the key was given, for the message (``"--set"``, ``"sweep.axes"``).

    Raises
    ------
    DesignError
        One line naming the key, what is wrong and the closest allowed keys (or the allowed ones).
    """
    sections = section_models()
    shown = repr(key[:80])
    parts = key.split(".")
    if not key or any(not p.strip() for p in parts):
        raise DesignError(
            f"{what} {shown}: not a dotted design key (an empty part); allowed: section.key, "
            "e.g. sensor.threshold_on or asic.bits"
        )
    ckey = canonical_key(key)
    cparts = ckey.split(".")
    section = cparts[0]
    known = _all_keys()

    def unknown(why: str, allowed: str | None = None) -> DesignError:
        close = difflib.get_close_matches(key, known, n=3, cutoff=0.6)
        hint = f"did you mean {', '.join(close)}? " if close else ""
        return DesignError(f"{what} {shown}: {why}; {hint}allowed: {allowed or 'sections ' + ', '.join(sections)}")

    if section not in sections:
        raise unknown(f"unknown section {section[:40]!r}")
    if len(cparts) == 1:
        sample = ", ".join(f"{section}.{k}" for k in section_keys(section)[:6]) or ", ".join(option_tables())
        raise DesignError(f"{what} {shown}: names a whole section, not a key; allowed: one key of it ({sample})")
    if section == "realisations" and cparts[1] in option_tables():
        spec = get_realisation(cparts[1])
        options = sorted(spec.options.model_fields)
        if len(cparts) < 3:
            raise DesignError(
                f"{what} {shown}: names the [realisations.{cparts[1]}] table, not an option; "
                f"allowed: {cparts[1]}.<option> with option one of {', '.join(options)}"
            )
        if cparts[2] not in spec.options.model_fields:
            raise unknown(f"unknown option of {spec.fit_name}", ", ".join(options))
        if len(cparts) > (4 if is_table_field(spec.options, cparts[2]) else 3):
            raise DesignError(
                f"{what} {shown}: {cparts[1]}.{cparts[2]} is a single value, not a table; "
                f"allowed: {cparts[1]}.{cparts[2]}=VALUE"
            )
        return ckey
    if cparts[:2] == ["tasks", "datasets"] and len(cparts) > 3:
        return _dataset_table_key(key, cparts, what)
    if cparts[1] not in section_keys(section):
        extra = [*option_tables()] if section == "realisations" else []
        raise unknown(f"unknown key {cparts[1][:40]!r} in [{section}]", ", ".join([*section_keys(section), *extra]))
    table = is_table_field(sections[section], cparts[1])
    if len(cparts) > (3 if table else 2):
        raise DesignError(
            f"{what} {shown}: {section}.{cparts[1]} is "
            f"{'a table of single values' if table else 'a single value, not a table'}"
            f"; allowed: {section}.{cparts[1]}" + ("[.NAME]" if table else "") + "=VALUE"
        )
    return ckey


def set_dotted_key(data: dict[str, Any], key: str, value: Any) -> None:
    """Set ``value`` at the dotted ``key`` of ``data``, making the tables on the way."""
    parts = key.split(".")
    node = data
    for p in parts[:-1]:
        if not isinstance(node.get(p), dict):  # a number where a table is set (tasks.n_test.detection)
            node[p] = {}
        node = node[p]
    node[parts[-1]] = value
