"""Form descriptions built from a step's ``Params`` JSON schema, and the Qt-free half of the forms.

The GUI renders these as widgets (app/param_widgets.py: spin boxes with bounds and the unit as
suffix, check boxes, combo boxes, small tables for lists and mappings, help as tooltips) and
`pointspro steps` prints them; both read the one declaration. What does not need Qt lives here so it
is tested headless: which editor a field gets (``FormField.editor``), how a number is written and
read back (``format_number``/``parse_number``: the shortest text that gives back the same float64,
so a form never rounds 3.3333333e-4 to 0.0003), the bounds message shown while typing, the starting
value when an "auto" box is unticked, and the conversion between a list or mapping and the rows of
its table.
"""
from __future__ import annotations

import math
import re
from dataclasses import dataclass
from typing import Any

#: the coarse kind of a field (`pointspro steps` prints it)
WIDGETS = ("float", "int", "bool", "choice", "union", "text", "list", "mapping")
#: the editor the window builds for a field (``FormField.editor``)
EDITORS = ("float", "int", "bool", "choice", "union", "text", "file", "tuple", "table", "group", "pairs")
#: a list longer than this is kept as it is, not edited in the window (thousands of deleted rows)
MAX_TABLE_ROWS = 50
#: the kinds of a list's entries
ITEMS = ("float", "int", "text", "name_or_int", "choice", "row")

_LENGTH_UNITS = ("mm", "µm", "um", "nm", "m")


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
    #: the value names a file (``param(file=True)``)
    file: bool = False
    #: union (``auto | int``): the kind of the number beside the choices, "int" or "float"
    number: str | None = None
    #: list: the kind of its entries (one of ITEMS), their choices when they have some
    item: str | None = None
    item_choices: list | None = None
    #: list of rows (``[[x, y], ...]``, a matrix): the row length when fixed, else None
    columns: int | None = None
    #: list with a fixed number of entries (``centre: [x, y]``)
    length: int | None = None
    #: mapping with named keys (a nested parameter group): its fields
    fields: list[FormField] | None = None
    #: mapping with free keys (``A: {4: 7e-13}``): the kind of its values
    value_kind: str | None = None

    def bounds_text(self) -> str:
        lo = (f"> {self.exclusive_minimum:g}" if self.exclusive_minimum is not None
              else f"≥ {self.minimum:g}" if self.minimum is not None else "")
        hi = (f"< {self.exclusive_maximum:g}" if self.exclusive_maximum is not None
              else f"≤ {self.maximum:g}" if self.maximum is not None else "")
        return ", ".join(b for b in (lo, hi) if b)

    @property
    def editor(self) -> str:
        """The editor the window builds (one of EDITORS); ``nullable`` adds an "auto" box to it."""
        if self.widget == "text":
            return "file" if self.file else "text"
        if self.widget == "list":
            if self.length is not None and self.item in ("float", "int"):
                return "tuple"
            return "table"
        if self.widget == "mapping":
            return "group" if self.fields is not None else "pairs"
        return self.widget

    @property
    def null_label(self) -> str:
        """The box that stands for None: "auto" where None means computed (a diameter, a centre),
        "none" where it means not given (a file, a pose)."""
        return "none" if self.widget in ("text", "mapping") or self.item == "row" else "auto"

    def tooltip(self) -> str:
        b = self.bounds_text()
        return (self.help + (f" [{self.unit}]" if self.unit else "") + (f" ({b})" if b else "")).strip()

    def column_titles(self) -> list[str]:
        """Titles of a table's or a tuple's columns: x, y(, z) for a point in a length unit."""
        n = self.length if self.editor == "tuple" else (self.columns or (4 if self.item == "row" else 1))
        if self.editor == "tuple" or self.item == "row":
            if 2 <= n <= 3 and self.unit in _LENGTH_UNITS:
                return ["x", "y", "z"][:n]
            return [str(j + 1) for j in range(n)]
        return ["value" + (f" ({self.unit})" if self.unit else "")]


# --- from the schema -----------------------------------------------------------------------------

def _resolve(prop: dict, defs: dict) -> dict:
    if "$ref" in prop:
        return defs[prop["$ref"].split("/")[-1]]
    return prop


def _numeric_kind(s: dict) -> str | None:
    return {"number": "float", "integer": "int"}.get(s.get("type"))


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
        consts = [v for v in non_null if "const" in v or "enum" in v]
        choices = [c for v in consts for c in v.get("enum", [v.get("const")])]
        if len(consts) == len(non_null):
            return "choice", {"enum": choices}, nullable
        numbers = [v for v in non_null if _numeric_kind(v)]
        if consts and len(consts) + len(numbers) == len(non_null) and len(numbers) == 1:
            # a union such as "auto" | int: the choices plus a number
            return "union", {**numbers[0], "enum": choices, "number": _numeric_kind(numbers[0])}, nullable
        return "text", prop, nullable  # any other union: a text field validated by the model
    if "enum" in prop or "const" in prop:
        return "choice", {"enum": prop.get("enum", [prop.get("const")])}, nullable
    t = prop.get("type")
    kind = {"number": "float", "integer": "int", "boolean": "bool", "string": "text",
            "array": "list", "object": "mapping"}.get(t)
    if kind is None:
        raise ValueError(f"no form widget for schema {prop}")
    return kind, prop, nullable


def _item(schema: dict, defs: dict) -> tuple[str, list | None, int | None]:
    """(kind of a list's entry, its choices, its row length) for an ``items`` schema."""
    s = _resolve(schema or {}, defs)
    variants = s.get("anyOf") or s.get("oneOf")
    if variants:
        kinds = {_resolve(v, defs).get("type") for v in variants}
        if kinds == {"string", "integer"}:
            return "name_or_int", None, None
        if all("const" in v or "enum" in v for v in variants):
            return "choice", [c for v in variants for c in v.get("enum", [v.get("const")])], None
        return "text", None, None
    if "enum" in s or "const" in s:
        return "choice", s.get("enum", [s.get("const")]), None
    t = s.get("type")
    if t == "array":
        prefix = s.get("prefixItems")
        n = len(prefix) if prefix and s.get("minItems") == s.get("maxItems") == len(prefix) else None
        return "row", None, n
    return {"number": "float", "integer": "int"}.get(t, "text"), None, None


def _fields(props: dict, required: set, defs: dict, defaults: dict) -> list[FormField]:
    out = []
    for key, prop in props.items():
        kind, s, nullable = _widget(prop, defs)
        extra = {}
        if kind == "union":
            extra["number"] = s["number"]
        elif kind == "list":
            prefix = s.get("prefixItems")
            if prefix and s.get("minItems") == s.get("maxItems") == len(prefix):  # a fixed tuple
                item, choices, _ = _item(prefix[0], defs)
                extra.update(item=item, item_choices=choices, length=len(prefix))
            else:
                item, choices, columns = _item(s.get("items", {}), defs)
                extra.update(item=item, item_choices=choices, columns=columns)
        elif kind == "mapping":
            if s.get("properties"):
                sub_defaults = {k: p.get("default") for k, p in s["properties"].items()}
                extra["fields"] = _fields(s["properties"], set(s.get("required", [])), defs, sub_defaults)
            else:
                extra["value_kind"], _, _ = _item(s.get("additionalProperties") or {}, defs)
        default = defaults.get(key)
        out.append(FormField(
            key=key, widget=kind, default=default, required=key in required,
            unit=prop.get("unit") or s.get("unit"), help=prop.get("description", ""),
            minimum=s.get("minimum"), maximum=s.get("maximum"),
            exclusive_minimum=s.get("exclusiveMinimum"), exclusive_maximum=s.get("exclusiveMaximum"),
            choices=s.get("enum"), nullable=nullable, file=bool(prop.get("file") or s.get("file")),
            **extra))
    return out


def form_fields(params_cls) -> list[FormField]:
    schema = params_cls.model_json_schema()
    defs = schema.get("$defs", {})
    defaults = {}
    for key, field_info in params_cls.model_fields.items():
        default = None if field_info.is_required() else field_info.get_default(call_default_factory=True)
        if hasattr(default, "model_dump"):  # a nested parameter group: show its set values
            default = default.model_dump(mode="json", exclude_none=True)
        defaults[key] = default
    return _fields(schema.get("properties", {}), set(schema.get("required", [])), defs, defaults)


# --- numbers: written and read back exactly ------------------------------------------------------

def format_number(v) -> str:
    """The shortest text that reads back as the same float64 (Python's repr): 3.3333333e-4 →
    "0.00033333333", 7e-13 → "7e-13", 10.0 → "10"; an int as an int."""
    if isinstance(v, bool):
        return str(v).lower()
    if isinstance(v, int):
        return str(v)
    r = repr(float(v))
    return r[:-2] if r.endswith(".0") else r


_PARTIAL_NUMBER = re.compile(r"[+-]?(\d*\.?\d*)?([eE][+-]?)?")


def is_partial_number(text: str) -> bool:
    """A beginning of a number that is not one yet ("", "-", "1e", "1.5e-"): typing goes on."""
    t = text.strip().replace("−", "-")
    if t == "" or t in ("-", "+", ".", "-.", "+."):
        return True
    return bool(_PARTIAL_NUMBER.fullmatch(t)) and t[-1] in "eE+-"


def parse_number(text: str, kind: str = "float"):
    """A number typed in a form: "12.5", "1e-3", "−2" (a typographic minus); ValueError with a
    message naming the text when it is not a finite number (or not a whole one for "int")."""
    t = str(text).strip().replace("−", "-").replace("\u2009", "").replace(" ", "")
    if kind == "int":
        if re.fullmatch(r"[+-]?\d+", t):
            return int(t)
        try:
            v = float(t)
        except ValueError:
            raise ValueError(f"'{text}' is not a number") from None
        if math.isfinite(v) and v == int(v) and abs(v) < 2 ** 53:
            return int(v)
        raise ValueError(f"'{text}' is not a whole number")
    try:
        v = float(t)
    except ValueError:
        raise ValueError(f"'{text}' is not a number") from None
    if not math.isfinite(v):
        raise ValueError(f"'{text}' is not a finite number")
    return v


def bounds_problem(field: FormField, v) -> str | None:
    """None when ``v`` lies within the field's bounds, else the message: "window must be > 0 mm
    (got -5 mm)"."""
    unit = f" {field.unit}" if field.unit else ""
    lo, hi = field.minimum, field.maximum
    bad = ((field.exclusive_minimum is not None and not v > field.exclusive_minimum)
           or (lo is not None and v < lo)
           or (field.exclusive_maximum is not None and not v < field.exclusive_maximum)
           or (hi is not None and v > hi))
    if not bad:
        return None
    return f"{field.key} must be {field.bounds_text()}{unit} (got {format_number(v)}{unit})"


def step_size(v: float) -> float:
    """An arrow's step: a tenth of the value's decade (10 → 1, 0.0033 → 0.0001), 1 at zero."""
    if v == 0 or not math.isfinite(v):
        return 1.0
    return 10.0 ** (math.floor(math.log10(abs(v))) - 1)


def stepped(field: FormField, v: float, steps: int) -> float:
    """``v`` moved by ``steps`` arrow steps, kept inside the bounds (a step that would leave them
    is not taken), written to the step's decimals (0.9 − 0.01 = 0.89, not 0.8899999999999999)."""
    step = step_size(v)
    digits = max(0, -math.floor(math.log10(step)))
    out = round(v + steps * step, digits)
    return v if bounds_problem(field, out) else out


def initial_value(field: FormField):
    """The value a field starts from when its "auto" (None) box is unticked: its default when it
    has one, else a value inside its bounds (0, the lower bound, or one above a strict one)."""
    if field.default is not None:
        return field.default
    e = field.editor
    if e in ("float", "int", "union"):
        kind = field.number if e == "union" else e
        for v in (0, 1, field.minimum, (field.exclusive_minimum or 0) + 1, field.exclusive_maximum,
                  field.maximum):
            if v is not None and bounds_problem(field, v) is None:
                return float(v) if kind == "float" else int(v)
        if field.exclusive_minimum is not None and field.exclusive_maximum is not None:
            mid = (field.exclusive_minimum + field.exclusive_maximum) / 2
            return float(mid) if kind == "float" else int(mid)
        return 0.0 if kind == "float" else 0
    if e == "bool":
        return False
    if e == "choice":
        return field.choices[0]
    if e == "tuple":
        return [0.0 if field.item == "float" else 0] * field.length
    if e in ("table",):
        return []
    if e in ("group", "pairs"):
        return {}
    return ""


# --- lists and mappings as the rows of a table ---------------------------------------------------

def entry_text(v) -> str:
    if isinstance(v, (int, float)) and not isinstance(v, bool):
        return format_number(v)
    if isinstance(v, (bool, list, tuple)) or v is None:  # as a recipe writes them: true, [1, 2]
        from .yamlio import yaml_word

        return yaml_word(v)
    text = str(v)
    if isinstance(v, str):  # a word YAML would read as something else ("null", "1e3", "lens #2.stl",
        # "[draft] lens.stl", "a: b"): quoted, so that the mapping tables read it back as itself
        try:
            same = _yaml_entry(text) == text
        except ValueError:
            same = False
        if not same:
            import json

            return json.dumps(text, ensure_ascii=False)  # a JSON string is a YAML double-quoted scalar
    return text


def _yaml_entry(text: str):
    """A mapping's free-form entry read as a recipe reads a value (YAML 1.2): "3.3e-4" a number,
    "even_asphere" a word, "[1e-5, 2e-7]" a list, "true" a yes — the window's `programmed_surface`
    table kept "3.3e-4" as text, which the surface then refused ("a number, not text")."""
    from .errors import RecipeError
    from .yamlio import load_yaml

    if not text.strip():
        raise ValueError("empty entry")
    try:
        return load_yaml(text, "the entry")
    except RecipeError as e:
        raise ValueError(str(e).split(": ", 1)[-1]) from None


def parse_entry(text: str, kind: str, choices: list | None = None):
    """One entry of a list: a number, a name, or (``name_or_int``) an index when it is a whole
    number and a name otherwise ("tilt", "4"); ValueError with the message otherwise."""
    t = str(text).strip()
    if t == "":
        raise ValueError("empty entry")
    if kind in ("float", "int"):
        return parse_number(t, kind)
    if kind == "name_or_int":
        return int(t) if re.fullmatch(r"[+-]?\d+", t) else t
    if kind == "choice":
        for c in choices or []:
            if str(c) == t:
                return c
        raise ValueError(f"'{t}' is not one of {', '.join(str(c) for c in choices or [])}")
    return t


def table_rows(field: FormField, value) -> list[list[str]]:
    """The cells of a list's table: one row per entry; a list of rows (``[[x, y], …]``) in columns."""
    if field.item == "row":
        return [[entry_text(x) for x in row] for row in (value or [])]
    return [[entry_text(x)] for x in (value or [])]


def table_value(field: FormField, rows: list[list[str]]) -> list:
    """The list a table's cells stand for; ValueError naming the row (1-based) and the cell's text.
    Empty rows are skipped; in a row of numbers, empty cells at its end are (a 3 × 4 matrix in a
    4-column table)."""
    out = []
    for r, cells in enumerate(rows, start=1):
        cells = [c.strip() for c in cells]
        if not any(cells):
            continue
        try:
            if field.item == "row":
                while cells and not cells[-1]:
                    cells.pop()
                out.append([parse_entry(c, "float") for c in cells])
            else:
                out.append(parse_entry(cells[0], field.item or "text", field.item_choices))
        except ValueError as e:
            raise ValueError(f"{field.key}, row {r}: {e}") from None
    return out


def pairs_rows(value: dict | None) -> list[list[str]]:
    def key_text(k):  # keys are read as names or whole numbers (parse_entry "name_or_int"), unquoted
        return format_number(k) if isinstance(k, (int, float)) and not isinstance(k, bool) else str(k)

    return [[key_text(k), entry_text(v)] for k, v in (value or {}).items()]


def pairs_value(field: FormField, rows: list[list[str]]) -> dict:
    """The mapping a key/value table stands for: keys that are whole numbers become ints (``A: {4:
    7e-13}``, powers); ValueError naming the row."""
    out = {}
    for r, (k, v) in enumerate(rows, start=1):
        k, v = k.strip(), v.strip()
        if not k and not v:
            continue
        try:
            if not k:
                raise ValueError("no key")
            key = parse_entry(k, "name_or_int")
            if key in out:
                raise ValueError(f"key {k} given twice")
            kind = field.value_kind or "text"
            out[key] = _yaml_entry(v) if kind == "text" else parse_entry(v, kind)
        except ValueError as e:
            raise ValueError(f"{field.key}, row {r}: {e}") from None
    return out


def group_value(values: dict) -> dict:
    """A nested group's mapping as the recipe writes it: the keys that are set (None left out)."""
    return {k: v for k, v in values.items() if v is not None}
