"""A flat view of one field of a pydantic schema, read from its JSON Schema (for the property and
contract tests that generate good and bad values from the declared limits)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from pydantic import BaseModel, ValidationError

from fsdvs_hw.schema import DESIGN_CONTEXT, field_schema, members


@dataclass(frozen=True)
class FieldView:
    """Kinds (``int``, ``float``, ``str``, ``bool``, ``list``, ``dict``, ``object``), bounds, choices."""

    model: type[BaseModel]
    name: str
    kinds: frozenset[str]
    default: Any
    unit: str
    doc: str
    lo: float | None
    hi: float | None
    lo_open: bool
    hi_open: bool
    choices: tuple[Any, ...] | None
    nullable: bool
    odd: bool
    length: int | None
    item: FieldView | None = None
    table: bool = False  # given as a table in a design file (a dict, or a structured object's fields)

    def ok(self, value: Any, *, design: bool = False) -> bool:
        """The model accepts ``value`` for this field."""
        try:
            self.model.model_validate({self.name: value}, context=DESIGN_CONTEXT if design else None)
        except ValidationError:
            return False
        return True


_KIND = {"integer": "int", "number": "float", "string": "str", "boolean": "bool", "object": "dict"}


def _view(model, name, node, default, unit, doc, odd) -> FieldView:
    kinds: set[str] = set()
    lo = hi = choices = length = item = None
    lo_open = hi_open = nullable = False
    for m in members(node):
        t = m.get("type")
        if t == "null":
            nullable = True
        elif m.get("title") in ("Python object",) or (t == "object" and m.get("description", "").endswith(" fields")):
            kinds.add("object")
        elif t == "array":
            kinds.add("list")
            length = m.get("minItems") if m.get("minItems") == m.get("maxItems") else None
            fixed = m.get("prefixItems")  # a tuple[...]: a list of fixed length (its first item's rules)
            if fixed and "items" not in m:
                length = len(fixed)
            item = _view(model, name, m.get("items") or (fixed or [{}])[0], None, unit, doc, odd)
        else:
            kinds.add(_KIND[t])
            if "enum" in m:
                choices = tuple(m["enum"])
            if t in ("integer", "number"):
                lo = m.get("minimum", m.get("exclusiveMinimum"))
                hi = m.get("maximum", m.get("exclusiveMaximum"))
                lo_open, hi_open = "exclusiveMinimum" in m, "exclusiveMaximum" in m
    table = any(m.get("type") == "object" for m in members(node))
    return FieldView(
        model,
        name,
        frozenset(kinds),
        default,
        unit,
        doc,
        lo,
        hi,
        lo_open,
        hi_open,
        choices,
        nullable,
        odd,
        length,
        item,
        table,
    )


def view(model: type[BaseModel], name: str) -> FieldView:
    """The view of field ``name`` of ``model``."""
    node = field_schema(model, name)
    info = model.model_fields[name]
    default = info.get_default(call_default_factory=True)
    return _view(model, name, node, default, node.get("unit", ""), node.get("description", ""), bool(node.get("odd")))
