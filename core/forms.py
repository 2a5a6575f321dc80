"""Form descriptions built from a step's ``Params`` JSON schema.

The GUI renders these as widgets (spin boxes with bounds and units, check boxes, combo boxes, text
fields with help as tooltips) and `pointspro steps` prints them; both read the one declaration.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Any

WIDGETS = ("float", "int", "bool", "choice", "text", "list", "mapping")


@dataclass
class FormField:
    key: str
    widget: str  # one of WIDGETS
    default: Any
    required: bool
    unit: str | None
    help: str
    minimum: float | None = None
    maximum: float | None = None
    exclusive_minimum: float | None = None
    exclusive_maximum: float | None = None
    choices: list | None = None
    nullable: bool = False

    def bounds_text(self) -> str:
        lo = (f"> {self.exclusive_minimum:g}" if self.exclusive_minimum is not None
              else f"≥ {self.minimum:g}" if self.minimum is not None else "")
        hi = (f"< {self.exclusive_maximum:g}" if self.exclusive_maximum is not None
              else f"≤ {self.maximum:g}" if self.maximum is not None else "")
        return ", ".join(b for b in (lo, hi) if b)


def _resolve(prop: dict, defs: dict) -> dict:
    if "$ref" in prop:
        return defs[prop["$ref"].split("/")[-1]]
    return prop


def _widget(prop: dict, defs: dict) -> tuple[str, dict, bool]:
    """(widget kind, the schema that carries bounds/choices, nullable)."""
    prop = _resolve(prop, defs)
    variants = prop.get("anyOf") or prop.get("oneOf")
    nullable = False
    if variants:
        non_null = [_resolve(v, defs) for v in variants if v.get("type") != "null"]
        nullable = len(non_null) < len(variants)
        if len(non_null) == 1:
            kind, schema, _ = _widget(non_null[0], defs)
            return kind, schema, nullable
        if all("const" in v or "enum" in v for v in non_null):
            return "choice", {"enum": [c for v in non_null for c in v.get("enum", [v.get("const")])]}, nullable
        # a union such as int | "auto": a text field validated by the model
        return "text", prop, nullable
    if "enum" in prop or "const" in prop:
        return "choice", {"enum": prop.get("enum", [prop.get("const")])}, nullable
    t = prop.get("type")
    kind = {"number": "float", "integer": "int", "boolean": "bool", "string": "text",
            "array": "list", "object": "mapping"}.get(t)
    if kind is None:
        raise ValueError(f"no form widget for schema {prop}")
    return kind, prop, nullable


def form_fields(params_cls) -> list[FormField]:
    schema = params_cls.model_json_schema()
    defs = schema.get("$defs", {})
    required = set(schema.get("required", []))
    out = []
    for key, prop in schema.get("properties", {}).items():
        kind, s, nullable = _widget(prop, defs)
        field_info = params_cls.model_fields[key]
        default = None if field_info.is_required() else field_info.get_default(call_default_factory=True)
        if hasattr(default, "model_dump"):  # a nested parameter group: show its set values
            default = default.model_dump(mode="json", exclude_none=True)
        out.append(FormField(
            key=key, widget=kind, default=default, required=key in required,
            unit=prop.get("unit") or s.get("unit"), help=prop.get("description", ""),
            minimum=s.get("minimum"), maximum=s.get("maximum"),
            exclusive_minimum=s.get("exclusiveMinimum"), exclusive_maximum=s.get("exclusiveMaximum"),
            choices=s.get("enum"), nullable=nullable))
    return out
