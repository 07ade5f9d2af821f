"""The one schema engine: strict pydantic models, a field helper with units, one error formatter.

Every checked table of the package is a :class:`StrictModel`: the sections of a design file
(:mod:`fsdvs_hw.design`) and the fit options of every realisation
(``fsdvs_hw/realise/*/options.py``, held by :attr:`fsdvs_hw.realise.registry.RealisationSpec.options`).
The rules are the model's configuration: an unknown key is refused (``extra="forbid"``); a
boolean is never a number and an integer refuses ``7.0`` (``strict=True``); numbers are finite
(``allow_inf_nan=False``); a number field accepts an integer and stores a float; ``None`` only
where the field is ``Optional``. NumPy scalars are taken as the Python number they hold.

:func:`field` declares one key (default, unit, a few words of meaning, bounds); the unit and the
words go into the JSON Schema (:meth:`pydantic.BaseModel.model_json_schema`). :func:`problems`
turns a :class:`pydantic.ValidationError` into the project's lines, one per problem::

    key '<dotted key>' = <value>: <why>; allowed: <what is allowed (meaning)>

where the allowed text is generated from the field's JSON Schema (:func:`allowed_text`).

Fields whose value is a structured object are typed with :func:`structured` (a table that the
object's own class builds and checks, e.g. ``MeshBounds``) or :data:`PyObject` (an object only a
Python caller can pass, e.g. a ``Geometry``).
"""

from __future__ import annotations

import importlib
import json
from collections.abc import Mapping
from functools import lru_cache
from typing import Annotated, Any, ClassVar

import numpy as np
from pydantic import (
    BaseModel,
    ConfigDict,
    Field,
    PlainValidator,
    ValidationError,
    ValidationInfo,
    WithJsonSchema,
    field_validator,
    model_validator,
)
from pydantic_core import PydanticCustomError

from .errors import InputError

__all__ = [
    "DESIGN_CONTEXT",
    "PyObject",
    "StrictModel",
    "allowed_text",
    "field",
    "field_schema",
    "members",
    "problems",
    "short",
    "structured",
    "validate",
]

#: Validation context of a design file (structured tables are built by their class; Python
#: objects cannot be given).
DESIGN_CONTEXT: dict[str, Any] = {"where": "design"}


class StrictModel(BaseModel):
    """Base of every schema: unknown keys refused, strict types, finite numbers.

    ``unknown_key`` is the words of the message for a key the model does not declare.
    """

    model_config = ConfigDict(extra="forbid", strict=True, allow_inf_nan=False, validate_default=False)

    unknown_key: ClassVar[str] = "unknown key"

    @model_validator(mode="before")
    @classmethod
    def _numpy_scalars(cls, data: Any) -> Any:
        """NumPy scalars (``np.int64(4)``, ``np.bool_``) as the Python value they hold."""
        if isinstance(data, Mapping):
            return {k: v.item() if isinstance(v, np.generic) else v for k, v in data.items()}
        return data

    @field_validator("*", mode="after")
    @classmethod
    def _odd(cls, value: Any, info: ValidationInfo) -> Any:
        """An integer declared ``odd`` (see :func:`field`) must be odd."""
        extra = cls.model_fields[info.field_name].json_schema_extra if info.field_name else None
        if isinstance(extra, dict) and extra.get("odd") and isinstance(value, int) and value % 2 == 0:
            raise PydanticCustomError("odd", "out of range (even)")
        return value


def field(default: Any, unit: str = "", doc: str = "", *, odd: bool = False, **bounds: Any) -> Any:
    """One key of a schema.

    Parameters
    ----------
    default : Any
        The value when the key is not given (a list or dict is copied per model).
    unit : str
        Physical unit of a number (``"m"``, ``"S"``, ``"F"``, ``"px"``, ``"bit"``; ``""`` =
        dimensionless or not a number); written to the JSON Schema as ``"unit"``.
    doc : str
        A few words of meaning (the JSON Schema's ``description``; shown in messages).
    odd : bool
        An integer that must be odd (``"odd": true`` in the JSON Schema).
    **bounds
        ``ge``, ``gt``, ``le``, ``lt``, ``min_length``, ``max_length`` (:func:`pydantic.Field`).
    """
    extra: dict[str, Any] = {"unit": unit}
    if odd:
        extra["odd"] = True
    if isinstance(default, (list, dict)):
        return Field(
            default_factory=lambda d=default: json.loads(json.dumps(d)),
            description=doc,
            json_schema_extra=extra,
            **bounds,
        )
    return Field(default, description=doc, json_schema_extra=extra, **bounds)


def _import(ref: str) -> Any:
    module, name = ref.split(":")
    return getattr(importlib.import_module(module), name)


def structured(factory: str, what: str) -> Any:
    """Type of a field holding a structured object given as a table.

    In a design file (:data:`DESIGN_CONTEXT`) the table must build: ``factory(**table)`` is called
    and its :class:`~fsdvs_hw.errors.InputError` / ``TypeError`` is reported; the table is kept as
    given (the fit function builds it again). From Python any object other than a string, number
    or boolean passes (the fit function checks it).

    Parameters
    ----------
    factory : str
        ``"module:Class"`` of the class (imported when a table is checked).
    what : str
        The class's name in messages and the JSON Schema.
    """

    def check(value: Any, info: ValidationInfo) -> Any:
        if isinstance(value, (str, bool, int, float)):
            raise PydanticCustomError("structured_type", "wrong type {word}", {"word": _word(value)})
        if info.context is not None and info.context.get("where") == "design":
            if not isinstance(value, Mapping):
                raise PydanticCustomError("structured", "must be a table of {what} fields", {"what": what})
            try:
                _import(factory)(**value)
            except TypeError as exc:
                raise PydanticCustomError(
                    "structured", "not valid {what} fields ({exc})", {"what": what, "exc": str(exc)}
                ) from None
            except InputError as exc:
                raise PydanticCustomError("structured", "invalid ({exc})", {"exc": str(exc)}) from None
            return dict(value)
        return value

    return Annotated[
        Any, PlainValidator(check), WithJsonSchema({"type": "object", "title": what, "description": f"{what} fields"})
    ]


def _python_object(value: Any, info: ValidationInfo) -> Any:
    if value is None:  # a field where None means "default" says so with ``| None``
        raise PydanticCustomError("object_type", "wrong type None")
    if isinstance(value, (str, bool, int, float)):
        raise PydanticCustomError("object_type", "wrong type {word}", {"word": _word(value)})
    if isinstance(value, Mapping) and info.context is not None and info.context.get("where") == "design":
        raise PydanticCustomError("object_type", "cannot be given in a design file (a Python object)")
    return value


#: A Python object the fit function checks itself (a ``Geometry``, a spectral distribution).
PyObject = Annotated[Any, PlainValidator(_python_object), WithJsonSchema({"type": "array", "title": "Python object"})]


def validate(model: type[BaseModel], values: Any, *, context: Mapping[str, Any] | None = None) -> BaseModel:
    """``model.model_validate(values)``; a :class:`pydantic.ValidationError` becomes one
    :class:`~fsdvs_hw.errors.InputError` listing :func:`problems`."""
    try:
        return model.model_validate(values, context=dict(context) if context else None)
    except ValidationError as exc:
        lines = problems(exc, model)
        raise InputError(lines[0] if len(lines) == 1 else f"{len(lines)} problems:\n  " + "\n  ".join(lines)) from None


# ---------------------------------------------------------------------------------- messages
_TYPE_WORDS = {
    "str": "string",
    "float": "number",
    "int": "integer",
    "bool": "boolean",
    "dict": "table",
    "list": "list",
    "NoneType": "None",
}
_RANGE = {"greater_than", "greater_than_equal", "less_than", "less_than_equal", "odd"}


def _word(value: Any) -> str:
    name = type(value).__name__
    return "table" if isinstance(value, Mapping) else _TYPE_WORDS.get(name, name)


def short(value: Any) -> str:
    """A value as JSON on one line, at most 80 characters (a table as ``{...}``)."""
    shown = json.dumps(value, default=repr) if not isinstance(value, Mapping) else "{...}"
    return shown if len(shown) <= 80 else shown[:77] + "..."


@lru_cache(maxsize=256)
def _json_schema(model: type[BaseModel]) -> dict[str, Any]:
    return model.model_json_schema()


def _resolve(node: dict[str, Any], defs: Mapping[str, Any]) -> dict[str, Any]:
    while "$ref" in node:
        node = {**defs[node["$ref"].rsplit("/", 1)[-1]], **{k: v for k, v in node.items() if k != "$ref"}}
    return node


def members(node: Mapping[str, Any], defs: Mapping[str, Any] | None = None) -> list[dict[str, Any]]:
    """The alternatives of a field's JSON Schema (``anyOf`` flattened, references resolved)."""
    node = _resolve(dict(node), defs or {})
    alternatives = node.get("anyOf", node.get("oneOf"))  # oneOf: a union told apart by a discriminator
    return [_resolve(dict(m), defs or {}) for m in alternatives] if alternatives is not None else [node]


def field_schema(model: type[BaseModel], name: str) -> dict[str, Any]:
    """The JSON Schema of one field of ``model`` (references resolved; ``anyOf`` kept)."""
    schema = _json_schema(model)
    node = _resolve(dict(schema["properties"][name]), schema.get("$defs", {}))
    if "anyOf" in node:
        node["anyOf"] = members(node, schema.get("$defs", {}))
    return node


def _number_text(m: Mapping[str, Any], unit: str, odd: bool = False) -> str:
    text = ("an odd integer" if odd else "an integer") if m.get("type") == "integer" else "a number"
    lo = m.get("minimum", m.get("exclusiveMinimum"))
    hi = m.get("maximum", m.get("exclusiveMaximum"))
    if lo is not None or hi is not None:
        a = "-inf" if lo is None else f"{lo:g}"
        b = "inf" if hi is None else f"{hi:g}"
        text += f" in {'(' if 'exclusiveMinimum' in m else '['}{a}, {b}{')' if 'exclusiveMaximum' in m else ']'}"
    return text + (f" {unit}" if unit else "")


def _member_text(m: Mapping[str, Any], unit: str, defs: Mapping[str, Any], odd: bool = False) -> str:
    t = m.get("type")
    if "enum" in m or "const" in m:
        return "one of " + ", ".join(repr(c) for c in m.get("enum", [m.get("const")]))
    if t in ("integer", "number"):
        return _number_text(m, unit, odd)
    if t == "string":
        return "a string"
    if t == "boolean":
        return "a boolean"
    if t == "array" and m.get("title") == "Python object":
        return "a Python object (from Python; a list in a design file)"
    if t == "array":
        n = m.get("minItems") if m.get("minItems") == m.get("maxItems") else None
        item = "; ".join(_member_text(i, unit, defs) for i in members(m.get("items", {}), defs))
        return f"a list of {n} items, each {item}" if n else (f"a list, each item {item}" if item else "a list")
    if t == "object":
        return f"a table of {m['title']} fields" if m.get("description", "").endswith(" fields") else "a table"
    return "a value"


def allowed_text(node: Mapping[str, Any], defs: Mapping[str, Any] | None = None) -> str:
    """What a field allows, in words, from its JSON Schema: types, range, choices, unit, meaning.

    ``{"type": "integer", "minimum": 2, "maximum": 24, "unit": "bit", "description": "tap width"}``
    → ``"an integer in [2, 24] bit (tap width)"``.
    """
    defs = defs or {}
    unit = node.get("unit", "")
    parts, nullable = [], False
    for m in members(node, defs):
        if m.get("type") == "null":
            nullable = True
            continue
        parts.append(_member_text(m, unit, defs, bool(node.get("odd"))))
    text = " or ".join(dict.fromkeys(parts)) + (" or None (automatic)" if nullable else "")
    return text + (f" ({node['description']})" if node.get("description") else "")


def _walk(model: type[BaseModel], loc: tuple[Any, ...]) -> tuple[str, dict[str, Any] | None, dict[str, Any]]:
    """The dotted key of an error's ``loc`` (union-member tags dropped), the JSON Schema of the
    deepest field it names (None at the top) and the schema of the table holding that field."""
    schema = _json_schema(model)
    defs = schema.get("$defs", {})
    node: dict[str, Any] = schema
    parent: dict[str, Any] = schema
    key, fld = "", None
    for part in loc:
        if isinstance(part, int):
            key += f"[{part}]"
            continue
        tables = [m for m in members(node, defs) if "properties" in m] if fld is not None or node is schema else []
        table = next((t for t in tables if part in t["properties"]), None)
        values = node.get("additionalProperties") if fld is not None and not tables else None
        if table is not None:
            parent, fld = table, _resolve(dict(table["properties"][part]), defs)
            node = fld
            key += ("." if key else "") + part
        elif isinstance(values, dict) and "$ref" in values:  # a key of a table of tables (dict[str, Model])
            fld = node = _resolve(dict(values), defs)
            key += "." + str(part)
        # otherwise a union-member tag ('float', "literal['a','b']"): not part of the key
    return key, fld, parent


def problems(exc: ValidationError, model: type[BaseModel], *, prefix: str = "") -> list[str]:
    """One line per problem of a validation of ``model``, in the project's words.

    Errors of the alternatives of one union field are merged into one line: a value of the right
    type that breaks a bound or a choice is reported as that, otherwise as its wrong type.

    Parameters
    ----------
    exc : pydantic.ValidationError
    model : type of BaseModel
        The model that was validated (its JSON Schema gives the allowed text).
    prefix : str
        Prepended to every dotted key (``"realisations.asic."``).
    """
    defs = _json_schema(model).get("$defs", {})
    by_key: dict[str, list[dict[str, Any]]] = {}
    for detail in exc.errors():
        loc = tuple(detail["loc"])
        entry: dict[str, Any]
        if detail["type"] == "extra_forbidden":
            key, fld, parent = _walk(model, loc[:-1])
            key = f"{key}.{loc[-1]}" if key else str(loc[-1])
            entry = {**detail, "_table": fld if fld is not None else parent}
        else:
            key, fld, _ = _walk(model, loc)
            entry = {**detail, "_field": fld}
        by_key.setdefault(key, []).append(entry)
    lines = []
    for key, errs in by_key.items():
        err = (
            next((e for e in errs if not e["type"].endswith("_type") and e["type"] != "literal_error"), None)
            or next((e for e in errs if e["type"] == "literal_error"), None)
            or errs[0]
        )
        value: Any = err.get("input")
        if err["type"] == "extra_forbidden":
            table = _resolve(dict(err["_table"]), defs)
            tables = [m for m in members(table, defs) if "properties" in m]
            title = tables[0].get("title") if tables else None
            words = _unknown_words(model, title)
            allowed = ", ".join(tables[0]["properties"]) if tables else "none"
            lines.append(f"key '{prefix}{key}' = {short(value)}: {words}; allowed: {allowed}")
            continue
        kind = err["type"]
        if kind in ("union_tag_invalid", "union_tag_not_found"):  # a discriminated union: name its tag key
            ctx, fld = err.get("ctx") or {}, err.get("_field") or {}
            tag = ctx.get("discriminator", "").strip("'")
            tags = ", ".join(repr(t) for t in (fld.get("discriminator") or {}).get("mapping", {}))
            shown = short(ctx.get("tag")) if kind == "union_tag_invalid" else "missing"
            why = "not one of the allowed values" if kind == "union_tag_invalid" else "required"
            lines.append(f"key '{prefix}{key}.{tag}' = {shown}: {why}; allowed: one of {tags}")
            continue
        if value is None and kind.endswith("_type"):
            why = "None is not allowed"
        elif kind.endswith("_type") and kind not in ("structured_type", "object_type"):
            why = f"wrong type {_word(value)}"
        elif kind in _RANGE:
            why = "out of range" if kind != "odd" else err["msg"]
        elif kind == "missing":
            why, value = "required", "missing"
        elif kind == "finite_number":
            why = "not a finite number"
        elif kind == "literal_error":
            why = "not one of the allowed values"
        elif kind in ("too_short", "too_long"):
            why = f"wrong length ({len(value) if hasattr(value, '__len__') else '?'} items)"
        else:
            why = err["msg"]
        fld = err.get("_field")
        allowed = allowed_text(fld, defs) if fld is not None else "a table"
        shown = value if kind == "missing" else short(value)
        lines.append(f"key '{prefix}{key}' = {shown}: {why}; allowed: {allowed}")
    return lines


def _unknown_words(model: type[BaseModel], title: str | None) -> str:
    """The ``unknown_key`` words of the (sub)model called ``title`` inside ``model``."""
    seen: set[type[BaseModel]] = set()
    stack: list[type[BaseModel]] = [model]
    while stack:
        m = stack.pop()
        if m in seen:
            continue
        seen.add(m)
        if m.__name__ == title or title is None:
            return getattr(m, "unknown_key", "unknown key")
        for f in m.model_fields.values():
            ann = f.annotation
            for t in (ann, *getattr(ann, "__args__", ())):
                if isinstance(t, type) and issubclass(t, BaseModel):
                    stack.append(t)
    return "unknown key"
