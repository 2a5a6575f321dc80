"""YAML as PointsPro reads and writes it: the YAML 1.2 core schema, line numbers, no duplicate keys.

PyYAML resolves plain scalars by YAML 1.1, where ``c: 3e-4`` is the *string* '3e-4' (an exponent
without a dot), ``yes``/``no``/``on``/``off``/``y``/``n`` are booleans, ``010`` is octal 8, ``1_000`` is
1000 and ``1:20`` is the sexagesimal 80. Every YAML file PointsPro reads (recipes, projects,
measurement models) is read here by the YAML 1.2 core schema instead:

    int     [-+]?[0-9]+ (decimal, so 010 is 10), 0o[0-7]+, 0x[0-9a-fA-F]+
    float   [-+]?(\\.[0-9]+|[0-9]+(\\.[0-9]*)?)([eE][-+]?[0-9]+)?, [-+]?.inf/.Inf/.INF, .nan/.NaN/.NAN
    bool    true/True/TRUE, false/False/FALSE only
    null    ~, null/Null/NULL, empty

anything else is a string (``yes``, ``on``, ``1_000``, ``2020-01-01``). The merge key ``<<`` is kept.
The loader is PyYAML's safe loader (plain data only, never objects or code); a mapping is a
:class:`LineDict` that remembers the line of itself and of each key, and a duplicate key (which YAML
would silently collapse) is an error naming its line.

Writing: :func:`dump_yaml` quotes a string that *either* YAML 1.1 or 1.2 would read as something else
('yes', 'on', 'y', '3e-4', '010'), so what PointsPro writes reads back the same here and in YAML
1.1 readers; floats are written as PyYAML does (1e-05 as ``1.0e-05``, a float under both).
"""
from __future__ import annotations

import collections.abc as abc
import enum
import itertools
import math
import numbers
import re
import types
import typing
from pathlib import Path
from typing import Any, Hashable

import yaml

from .errors import InputError, PointsProError, RecipeError

# -- the YAML 1.2 core schema (https://yaml.org/spec/1.2.2/#1032-tag-resolution) ------------------------
_INT10 = re.compile(r"[-+]?[0-9]+")
_INT8 = re.compile(r"0o[0-7]+")
_INT16 = re.compile(r"0x[0-9a-fA-F]+")
_FLOAT = re.compile(r"[-+]?(?:\.[0-9]+|[0-9]+(?:\.[0-9]*)?)(?:[eE][-+]?[0-9]+)?")
_INF = re.compile(r"[-+]?\.(?:inf|Inf|INF)")
_NAN = re.compile(r"\.(?:nan|NaN|NAN)")
_BOOL = {"true": True, "True": True, "TRUE": True, "false": False, "False": False, "FALSE": False}

CORE_RESOLVERS = (  # (tag, regexp, first characters), in the order they are tried
    ("tag:yaml.org,2002:null", re.compile(r"^(?:~|null|Null|NULL|)$"), ["~", "n", "N", ""]),
    ("tag:yaml.org,2002:bool", re.compile(r"^(?:true|True|TRUE|false|False|FALSE)$"), list("tTfF")),
    ("tag:yaml.org,2002:int", re.compile(r"^(?:[-+]?[0-9]+|0o[0-7]+|0x[0-9a-fA-F]+)$"), list("-+0123456789")),
    ("tag:yaml.org,2002:float",
     re.compile(r"^(?:[-+]?(?:\.[0-9]+|[0-9]+(?:\.[0-9]*)?)(?:[eE][-+]?[0-9]+)?"
                r"|[-+]?\.(?:inf|Inf|INF)|\.(?:nan|NaN|NAN))$"), list("-+.0123456789")),
    ("tag:yaml.org,2002:merge", re.compile(r"^(?:<<)$"), ["<"]),
)


class LineDict(dict):
    """A mapping that remembers the YAML line of itself and of each key (1-based)."""

    line: int | None = None
    key_lines: dict


class _Problem(Exception):
    """A value the loader refuses, as "line N: why" (load_yaml names the file and the error class)."""


class Loader(yaml.SafeLoader):
    """PyYAML's safe loader with the YAML 1.2 core schema, line numbers and duplicate keys refused."""

    yaml_implicit_resolvers: dict = {}

    def construct_object(self, node, deep=False):
        """A value YAML's own constructors refuse (a bad !!int, !!timestamp 2020-13-45) is an error
        naming its line, not a ValueError from deep inside PyYAML."""
        try:
            return super().construct_object(node, deep)
        except (_Problem, yaml.YAMLError, RecursionError):
            raise
        except Exception as e:  # noqa: BLE001 - PyYAML's constructors raise ValueError, TypeError,
            # AttributeError (!!timestamp on a non-date) …
            text = str(e).strip().splitlines()[0] if str(e).strip() else type(e).__name__
            raise _Problem(f"line {node.start_mark.line + 1}: cannot read the value {node.tag} "
                           f"({text})") from None


for _tag, _regexp, _first in CORE_RESOLVERS:
    Loader.add_implicit_resolver(_tag, _regexp, _first)


def _construct_mapping(loader: Loader, node):
    loader.flatten_mapping(node)
    d = LineDict()
    d.line = node.start_mark.line + 1
    d.key_lines = {}
    for knode, vnode in node.value:
        key = loader.construct_object(knode, deep=True)
        if not isinstance(key, Hashable):
            raise _Problem(f"line {knode.start_mark.line + 1}: a key must be a name or a number, "
                           f"not a {type(key).__name__}")
        if key in d:
            raise _Problem(f"line {knode.start_mark.line + 1}: duplicate key {key!r}")
        d[key] = loader.construct_object(vnode, deep=True)
        d.key_lines[key] = knode.start_mark.line + 1
    return d


def _construct_int(loader: Loader, node) -> int:
    value = str(loader.construct_scalar(node)).strip()
    if _INT10.fullmatch(value):
        return int(value, 10)
    if _INT8.fullmatch(value):
        return int(value[2:], 8)
    if _INT16.fullmatch(value):
        return int(value[2:], 16)
    raise ValueError(f"{value!r} is not a YAML 1.2 integer")


def _construct_float(loader: Loader, node) -> float:
    value = str(loader.construct_scalar(node)).strip()
    if _FLOAT.fullmatch(value):
        return float(value)
    if _INF.fullmatch(value):
        return -math.inf if value.startswith("-") else math.inf
    if _NAN.fullmatch(value):
        return math.nan
    raise ValueError(f"{value!r} is not a YAML 1.2 number")


def _construct_bool(loader: Loader, node) -> bool:
    value = str(loader.construct_scalar(node)).strip()
    if value in _BOOL:
        return _BOOL[value]
    raise ValueError(f"{value!r} is not true or false")


Loader.add_constructor(yaml.resolver.BaseResolver.DEFAULT_MAPPING_TAG, _construct_mapping)
Loader.add_constructor("tag:yaml.org,2002:int", _construct_int)
Loader.add_constructor("tag:yaml.org,2002:float", _construct_float)
Loader.add_constructor("tag:yaml.org,2002:bool", _construct_bool)


def load_yaml(text: str, where: str, error: type[PointsProError] = RecipeError) -> Any:
    """The data of a YAML text by the YAML 1.2 core schema; ``error`` (RecipeError unless told) naming
    ``where`` and the line when the text is not valid YAML, repeats a key or has an unreadable value."""
    try:
        loader = Loader(text)
        try:
            return loader.get_single_data()
        finally:
            loader.dispose()
    except _Problem as e:
        raise error(f"{where}, {e}") from None
    except yaml.YAMLError as e:
        mark = getattr(e, "problem_mark", None)
        pos = f", line {mark.line + 1}" if mark else ""
        problem = getattr(e, "problem", None) or getattr(e, "reason", None) or str(e)
        problem = " ".join(str(problem).split()) if str(problem).strip() else type(e).__name__
        raise error(f"{where}{pos}: not valid YAML ({problem})") from None
    except RecursionError:
        raise error(f"{where}: not valid YAML (nested too deeply)") from None


def read_utf8(path: Path, what: str, error: type[PointsProError] = InputError) -> str:
    """The text of a YAML file PointsPro reads (a recipe, a project, a measurement model); ``error``
    naming the line of a byte that is not UTF-8 (not its offset) and what to do, or why it cannot be
    read."""
    try:
        return Path(path).read_text(encoding="utf-8")
    except UnicodeDecodeError as e:
        line = Path(path).read_bytes()[:e.start].count(b"\n") + 1
        raise error(f"{path}, line {line}: not UTF-8 text (byte 0x{e.object[e.start]:02x}); save the "
                    f"{what} as UTF-8") from None
    except OSError as e:
        raise error(f"{path}: cannot read the {what} ({e.strerror or e})") from None


def read_yaml_mapping(path, what: str, version_key: str, version: int = 1,
                      error: type[PointsProError] = InputError) -> LineDict:
    """A YAML file whose top level is a mapping with ``version_key: version`` (e.g. a project's
    ``pointspro_project: 1``); ``error`` naming the file (and the line) when it is missing, unreadable,
    not YAML, not such a mapping or of another format version. ``what`` names the kind of file
    ("project", "measurement model")."""
    path = Path(path)
    if not path.is_file():
        raise error(f"{path}: " + (f"is a folder, not a {what} file" if path.is_dir() else f"{what} file not found"))
    text = read_utf8(path, what, error)
    data = load_yaml(text, str(path), error)
    if not isinstance(data, dict) or version_key not in data:
        raise error(f"{path}: not a PointsPro {what} (no '{version_key}: {version}')")
    found = data[version_key]
    if type(found) is not int or found != version:  # true is not 1, nor is 1.0
        line = data.key_lines.get(version_key) if isinstance(data, LineDict) else None
        at = f", line {line}" if line else ""
        raise error(f"{path}{at}: {what} format {found!r} is not supported (this PointsPro reads "
                    f"'{version_key}: {version}')")
    return data


# -- writing ---------------------------------------------------------------------------------------------
def _quoting(cls):
    """``cls`` (a safe dumper) with the YAML 1.2 resolvers added after its YAML 1.1 ones: a string
    that either would read as non-string is written quoted."""
    for tag, regexp, first in CORE_RESOLVERS:
        cls.add_implicit_resolver(tag, regexp, first)
    # y/n: booleans to YAML 1.1 readers other than PyYAML
    cls.add_implicit_resolver("tag:yaml.org,2002:bool", re.compile(r"^(?:y|Y|n|N)$"), list("yYnN"))
    cls.add_representer(LineDict, yaml.representer.SafeRepresenter.represent_dict)  # data read back
    return cls


@_quoting
class Dumper(yaml.SafeDumper):
    pass


if getattr(yaml, "__with_libyaml__", False):
    @_quoting
    class CDumper(yaml.CSafeDumper):  # libyaml's emitter: 20× faster on long edit lists
        pass
else:  # pragma: no cover - PyYAML without libyaml
    CDumper = Dumper


def dump_yaml(data, fast: bool = False, **kwargs) -> str:
    """YAML text of plain data (dicts, lists, str, int, float, bool, None) that :func:`load_yaml`
    reads back equal; ``fast`` uses libyaml's emitter; other keywords as yaml.dump's."""
    return yaml.dump(data, Dumper=CDumper if fast else Dumper, **kwargs)


# -- true and false are not numbers ------------------------------------------------------------------------
# YAML's true/false load as Python's True/False, which are the integers 1 and 0 to Python and to
# pydantic's lax mode: `radius: true` would run with radius 1.0 and `side: true` with side 1. The
# models that read recipes (core.step.Params, core.surfaces.spec) refuse them wherever the declared type
# wants a number — a plain, Optional or Union number, a Literal of numbers, a list, tuple or mapping of
# numbers, a field of a nested model — through :func:`bool_as_number`.

_TAKES_BOOL = object()  # the annotation takes true/false as a yes/no (bool, Any, Literal[True])


def yaml_word(value) -> str:
    """``value`` as a recipe writes it where that differs from Python: true, false, null; lists of
    them too (``[520, true]``); anything else as ``repr``."""
    if isinstance(value, bool):
        return "true" if value else "false"
    if value is None:
        return "null"
    if isinstance(value, (list, tuple)):
        return "[" + ", ".join(yaml_word(v) for v in value) + "]"
    return repr(value)


def _bool_path(ann, value):
    """_TAKES_BOOL where ``ann`` takes ``value``'s true/false as such; the path (a list of ("item", i),
    ("in", key) or ("key", key) steps) to a true/false that ``ann`` would take as a number; None when
    neither (no true/false in it, or one pydantic refuses by itself, as a string field does)."""
    if ann is typing.Any or ann is object:
        return _TAKES_BOOL
    origin, args = typing.get_origin(ann), typing.get_args(ann)
    if origin is typing.Annotated:
        return _bool_path(args[0], value)
    if origin is typing.Union or origin is types.UnionType:
        found = None
        for a in args:
            r = _bool_path(a, value)
            if r is _TAKES_BOOL:
                return r
            found = r if found is None else found
        return found
    if isinstance(value, bool):
        if ann is bool:
            return _TAKES_BOOL
        if origin is typing.Literal:
            if any(isinstance(a, bool) for a in args):
                return _TAKES_BOOL
            return [] if any(isinstance(a, numbers.Number) for a in args) else None
        if isinstance(ann, type) and issubclass(ann, enum.Enum):
            numeric = any(isinstance(m.value, numbers.Number) and not isinstance(m.value, bool)
                          for m in ann)
            return [] if numeric else None
        if isinstance(ann, type) and issubclass(ann, numbers.Number):
            return []  # int, float, Decimal, Fraction, complex, numpy's numbers
        return None
    if isinstance(value, (list, tuple)) and origin in (list, tuple, set, frozenset, abc.Sequence,
                                                       abc.MutableSequence, abc.Set, abc.Iterable,
                                                       abc.Collection):
        if origin is tuple and args and not (len(args) == 2 and args[1] is Ellipsis):
            anns = list(args)  # tuple[float, float]: one type per place (extra items: pydantic's)
        else:
            anns = [args[0] if args else typing.Any] * len(value)
        for i, (a, v) in enumerate(zip(anns, value)):
            r = _bool_path(a, v)
            if isinstance(r, list):
                return [("item", i), *r]
        return None
    if isinstance(value, dict):
        if origin in (dict, abc.Mapping, abc.MutableMapping):
            key_ann, value_ann = args if len(args) == 2 else (typing.Any, typing.Any)
            for k, v in value.items():
                if isinstance(_bool_path(key_ann, k), list):
                    return [("key", k)]
                r = _bool_path(value_ann, v)
                if isinstance(r, list):
                    return [("in", k), *r]
            return None
        fields = getattr(ann, "model_fields", None) if isinstance(ann, type) else None
        if isinstance(fields, dict):  # a nested pydantic model: its fields by name
            for k, v in value.items():
                f = fields.get(k)
                r = _bool_path(f.annotation, v) if f is not None else None
                if isinstance(r, list):
                    return [("in", k), *r]
        return None
    return None


def _holds(value, wanted: type, keys: bool) -> bool:
    """Whether a ``wanted`` value is anywhere in ``value`` (its lists, tuples, mappings' values, and
    their keys with ``keys``), level by level at C speed: a list of 10⁵ index pairs is looked through
    in milliseconds."""
    level = [value]
    while level:
        items = level[0] if len(level) == 1 and isinstance(level[0], (list, tuple)) else list(
            itertools.chain.from_iterable(
                (itertools.chain(c.keys(), c.values()) if keys else c.values()) if isinstance(c, dict) else c
                for c in level))
        kinds = set(map(type, items))
        if any(issubclass(k, wanted) for k in kinds):
            return True
        if not any(issubclass(k, (list, tuple, dict)) for k in kinds):
            return False
        level = [x for x in items if isinstance(x, (list, tuple, dict))]
    return False


def _holds_bool(value) -> bool:
    """Whether true or false is anywhere in ``value``, mappings' keys included."""
    return _holds(value, bool, keys=True)


#: the words of the refusal of a number written as text (a step's parameter, a surface's key)
NUMBER_TEXT = "Input should be a number, not text (write it without quotes or underscores)"


def numeric_text(text: str) -> bool:
    """Text Python would read as a number ("1_290", " 1290", "3.33e-4"): pydantic's lax mode would
    take it as the number, where a number is written as one (a review: `diameter: 1_290`, a word in
    YAML 1.2, and a quoted "1290" both ran)."""
    try:
        float(text)
    except ValueError:
        return False
    return True


def _texts(ann, value, path=()):
    """(path, text) of each string in ``value`` where ``ann`` wants a number: a float or int field,
    a mapping's values, a list's or tuple's items, a nested pydantic model's fields (the path: the
    ("in", key) and ("item", i) steps down to it, as core.yamlio.bool_as_number's)."""
    origin, args = typing.get_origin(ann), typing.get_args(ann)
    if origin is typing.Annotated:
        yield from _texts(args[0], value, path)
    elif origin is typing.Union or origin is types.UnionType:
        # text where the type admits text is text (zernike's `remove: [tilt, "4"]`: an unknown name,
        # which the step says, not "a number, not text")
        if isinstance(value, str) and any(a in (float, int) for a in args) and str not in args:
            yield path, value
        elif not isinstance(value, str):
            for a in args:
                yield from _texts(a, value, path)
    elif ann in (float, int):
        if isinstance(value, str):
            yield path, value
    elif isinstance(value, (list, tuple)) and origin in (list, tuple):
        fixed = origin is tuple and args and not (len(args) == 2 and args[1] is Ellipsis)
        for i, v in enumerate(value):
            a = (args[i] if i < len(args) else None) if fixed else (args[0] if args else None)
            if a is not None:
                yield from _texts(a, v, (*path, ("item", i)))
    elif isinstance(value, dict) and origin is dict and len(args) == 2:
        for k, v in value.items():
            yield from _texts(args[1], v, (*path, ("in", k)))
    elif isinstance(value, dict) and isinstance(getattr(ann, "model_fields", None), dict):
        for k, v in value.items():
            f = ann.model_fields.get(k) if isinstance(k, str) else None
            if f is not None:
                yield from _texts(f.annotation, v, (*path, ("in", k)))


def number_as_text(annotation, value, name: str | None = None):
    """A pydantic error (type ``number_text``) when ``value`` holds a number written as text where
    ``annotation`` wants a number — `aperture: 1_300` (a word in YAML 1.2) or `c: "3.33e-4"`, which
    pydantic's lax mode would read as the number — refused with the steps' own rule and words
    (core.yamlio.numeric_text, NUMBER_TEXT); None otherwise (text that is no number is left to
    pydantic's own message).
    As core.yamlio.bool_as_number's: its context has ``keys`` (``name``, the field the value is of,
    then the mapping keys down to the text) and ``detail`` (the message without them)."""
    if isinstance(value, (list, tuple, dict)) and not _holds_text(value):
        return None  # a list of 10⁵ row numbers: looked through at C speed, not item by item
    from pydantic_core import PydanticCustomError

    for path, text in _texts(annotation, value, (("in", name),) if name is not None else ()):
        if not numeric_text(text):
            continue
        n = next((i for i, (kind, _) in enumerate(path) if kind != "in"), len(path))
        keys = [str(k) for _, k in path[:n]]  # the keys down to it ('A', '4'); the rest: "item 2: …"
        where = "'s ".join(f"item {k + 1}" if kind == "item" else f"key {yaml_word(k)}"
                           for kind, k in path[n:])
        detail = (f"{where}: " if where else "") + f"{NUMBER_TEXT} (got {text!r})"
        return PydanticCustomError("number_text", "{detail}", {"keys": keys, "detail": detail})
    return None


def _holds_text(value) -> bool:
    """Whether a string is anywhere in ``value`` (its lists, tuples and mappings' values)."""
    return _holds(value, str, keys=False)


def bool_as_number(annotation, value, name: str | None = None):
    """A pydantic error (type ``bool_not_number``) when ``value`` holds a true/false where
    ``annotation`` wants a number; None otherwise. Its message names the place within the value
    ("item 2 should be a number (got true)", "key 'dz' should be a number (got false)"); its context
    has ``keys`` (the mapping keys leading to it, which core.recipe.format_validation_error adds to
    the key it names: 'pose.dz') and ``detail`` (the message without them). ``name``: the field the
    value is of, when the error is raised for the whole model (a model validator)."""
    if not _holds_bool([value]):
        return None
    path = _bool_path(annotation, value)
    if not isinstance(path, list):
        return None
    from pydantic_core import PydanticCustomError

    got = value
    for kind, k in path:
        got = got[k] if kind != "key" else k
    path = path if name is None else [("in", name), *path]
    keys = []
    for kind, k in path:
        if kind != "in":
            break
        keys.append(k)

    def words(steps) -> str:  # "item 2 ", "item 3's item 4 ", "item 1's key 'x' ", "key true "
        out = [f"item {k + 1}" if kind == "item" else
               f"key {yaml_word(k)}" if kind == "key" else f"key {k!r}" for kind, k in steps]
        return "'s ".join(out) + " " if out else ""

    # a mapping's key that is true/false: "key true should be a number", the value is the key
    tail = "should be a number" + ("" if path and path[-1][0] == "key" else f" (got {yaml_word(got)})")
    return PydanticCustomError("bool_not_number", "{where}" + tail,
                               {"where": words(path), "keys": [str(k) for k in keys],
                                "detail": words(path[len(keys):]) + tail})
