"""Recipes: the YAML that names a nominal surface and the steps to run (README "Recipes").

    pointspro: 1
    surface: {type: even_asphere, c: 3.3333333e-4, k: -0.98, A: {4: 7.0e-13}, aperture: 1300}
    input: {pixel_size_um: 1.1, invalid: drop}   # optional reader options (core.io.formats)
    steps:
      - aperture: {diameter: 1290}
      - manual_edit: {remove: [17, 4212]}
      - misalignment            # a step with all defaults may be written bare

A recipe is parsed with a safe loader that remembers line numbers and reads plain values by the
YAML 1.2 core schema (core.yamlio: ``3e-4`` is a number, ``yes`` and ``on`` are words), and *all* of
it is validated before anything runs: unknown keys, unknown steps, mistyped or out-of-range values
are errors naming the file, line, step and key. Duplicate keys (which YAML would silently collapse)
are errors too.
A step entry may carry ``schema_version: N`` (written by the GUI when it saves) so that the step's
``Params.migrate`` can rewrite parameters saved by an older version.
"""
from __future__ import annotations

import re
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

from pydantic import ValidationError

from .errors import RecipeError
from .registry import Registry
from .surfaces import parse_surface_spec
from .yamlio import LineDict, dump_yaml, load_yaml, read_utf8, yaml_word

RECIPE_VERSION = 1
TOP_KEYS = ("pointspro", "surface", "input", "inputs", "steps", "uncertainty", "tolerance")


#: a pydantic union branch's name at the end of an error's location ("literal['auto']", "int")
_UNION_BRANCH = re.compile(r"^(literal\[.*\]|int|float|str|bool|none|list\[.*\]|dict\[.*\]|tuple\[.*\])$")
#: what a union branch's error says the value should be
_BRANCH_WORDS = {"int_parsing": "a whole number", "int_type": "a whole number",
                 "int_from_float": "a whole number", "float_parsing": "a number", "float_type": "a number",
                 "string_type": "a text", "bool_type": "true or false", "bool_parsing": "true or false",
                 "list_type": "a list", "dict_type": "a mapping"}


def _merged_unions(errors: list[dict]) -> list[dict]:
    """A value that matches no branch of a union (``remove: auto | a count``) gives one error per
    branch, each at the key plus the branch's name — "key 'remove.literal['auto']': Input should be
    'auto'; key 'remove.int': Input should be a valid integer…" (a review). They become one error at
    the key: "'auto' or a whole number"."""
    groups: dict[tuple, list[dict]] = {}
    for err in errors:
        loc = tuple(err["loc"])
        if loc and _UNION_BRANCH.match(str(loc[-1])):
            groups.setdefault(loc[:-1], []).append(err)
    out, done = [], set()
    for err in errors:
        key = tuple(err["loc"])[:-1]
        branches = groups.get(key, [])
        if len(branches) < 2 or not any(err is b for b in branches):
            out.append(err)
            continue
        if key in done:
            continue
        done.add(key)
        words = []
        for b in branches:
            w = (b.get("ctx") or {}).get("expected") if b["type"] == "literal_error" else None
            w = w or _BRANCH_WORDS.get(b["type"]) or b["msg"].removeprefix("Input should be ")
            if w not in words:
                words.append(w)
        out.append({"loc": key, "type": "union", "msg": " or ".join(words), "input": err.get("input")})
    return out


def format_validation_error(e: ValidationError, prefix: str = "", model=None, tag: str | None = None) -> str:
    """One line naming each offending key: "key 'diameter': Input should be greater than 0 (got -5)".
    ``model``: the parameters' class — an unknown key then names the keys its mapping takes, the
    closest first ("key 'initial.alpha': unknown key; did you mean 'alpha_deg'? (initial takes
    alpha_deg, beta_deg, dx, dy, dz)": a review found the nested keys written nowhere). ``tag``: a
    tagged union's tag at the head of every location (a surface's type), left out of the key named."""
    parts = []
    for err in _merged_unions(e.errors()):
        names = [str(x) for x in err["loc"] if not str(x).startswith("function-")]
        if tag is not None and names[:1] == [tag]:
            names = names[1:]
        msg = err["msg"].removeprefix("Value error, ")  # a validator's own words, without pydantic's tag
        if err["type"] == "extra_forbidden":
            msg = "unknown key" + _known_keys(model, names)
        elif err["type"] == "missing":
            msg = "required key is missing"
        elif err["type"] in ("union_tag_not_found", "union_tag_invalid"):  # a surface's `type`
            tags = (err.get("ctx") or {}).get("expected_tags")
            msg = ("key 'type' is missing" if err["type"] == "union_tag_not_found" else
                   f"unknown type {err.get('ctx', {}).get('tag')!r}") + (f"; one of {tags}" if tags else "")
        got = err.get("input")
        text = yaml_word(got) if isinstance(got, bool) else repr(got)  # true, as the recipe says
        text = text if len(text) <= 80 else text[:79] + "…"
        shown = "" if err["type"] in ("extra_forbidden", "missing") or isinstance(got, dict) \
            else f" (got {text})"
        if "keys" in (err.get("ctx") or {}) and "detail" in err["ctx"]:
            # core.yamlio.bool_as_number (and the like): the keys down to the value join the key
            # named ('pose.dz'); the message names the item and the value itself
            names += err["ctx"]["keys"]
            msg, shown = err["ctx"]["detail"], ""
        if err["type"] in ("float_parsing", "int_parsing") and isinstance(got, str) and _NUMBER_AND_UNIT.match(got):
            # "window: 15 mm" (the uncertainty block takes "0.5 um"; a step's parameters do not)
            shown += "; write a plain number, in the unit the key's help states (lengths in mm)"
        loc = ".".join(names)
        parts.append(f"key '{loc}': {msg}{shown}" if loc else f"{msg}{shown}")
    return prefix + "; ".join(parts)


def surface_model(kind):
    """The pydantic class of a surface ``type`` (core/surfaces/spec.py), or None."""
    import typing

    from .surfaces.spec import SurfaceSpec

    union = typing.get_args(SurfaceSpec)[0]
    for cls in typing.get_args(union):
        if kind in typing.get_args(cls.model_fields["type"].annotation):
            return cls
    return None


def _known_keys(model, names: list[str]) -> str:
    """"; did you mean 'window'? (knn_denoise takes method, window, …)" for an unknown key at
    ``names`` under the pydantic ``model`` (its nested mappings followed down), or ''."""
    import difflib
    import typing

    from pydantic import BaseModel

    def sub_model(annotation):
        if isinstance(annotation, type) and issubclass(annotation, BaseModel):
            return annotation
        for arg in typing.get_args(annotation):
            found = sub_model(arg)
            if found is not None:
                return found
        return None

    if model is None or not names:
        return ""
    for name in names[:-1]:
        field = getattr(model, "model_fields", {}).get(name)
        model = sub_model(field.annotation) if field is not None else None
        if model is None:
            return ""
    keys = [k for k in model.model_fields if k not in ("schema_version", "type")]
    if not keys:
        return ""
    close = difflib.get_close_matches(names[-1], keys, n=1, cutoff=0.6)
    hint = f"; did you mean '{close[0]}'?" if close else ""
    owner = f"{'.'.join(names[:-1])} takes" if len(names) > 1 else (
        f"{(typing.get_args(model.model_fields['type'].annotation) or ('this type',))[0]} takes"
        if "type" in model.model_fields else "the step takes")
    return f"{hint} ({owner} {', '.join(keys)})"


#: a number followed by a word: a unit written into a value ("15 mm", "0.5um")
_NUMBER_AND_UNIT = re.compile(r"^\s*[-+]?(\d+\.?\d*|\.\d+)([eE][-+]?\d+)?\s*[^\W\d_]+\s*$")


def error_keys(err: dict) -> list:
    """The keys down to the value a pydantic error is about: its location, with the keys within the
    value that core.yamlio.bool_as_number names (['pose', 'dz'])."""
    names = [x for x in err["loc"] if not str(x).startswith("function-")]
    ctx = err.get("ctx") or {}
    if "keys" in ctx and "detail" in ctx:
        names += list(ctx["keys"])
    return names


def key_line(mapping, names) -> int | None:
    """The line of the deepest of ``names`` (keys within keys) found in a mapping read from YAML
    (core.yamlio.LineDict); None when the first is not found (or the mapping has no lines)."""
    line, node = None, mapping
    for name in names:
        lines = getattr(node, "key_lines", None) if isinstance(node, dict) else None
        if not lines:
            break
        key = name if name in lines else next((k for k in lines if str(k) == str(name)), None)
        if key is None:
            break
        line, node = lines[key], node.get(key)
    return line


@dataclass(frozen=True)
class RecipeStep:
    id: str
    params: Any  # the step's validated Params instance
    step_cls: type
    line: int | None = None
    enabled: bool = True

    def to_yaml_entry(self, full: bool = False) -> dict:
        """``{id: params}``; only the non-default parameters unless ``full`` (reports record all)."""
        data = self.params.model_dump(mode="json", exclude_defaults=not full)
        entry = {self.id: data}
        if not self.enabled:
            entry["enabled"] = False
        return entry


@dataclass(frozen=True)
class Recipe:
    """A validated recipe. Immutable: the edits below return a new Recipe and leave this one as it
    was, so the window's undo history can keep old recipes by reference."""

    steps: list[RecipeStep]
    surface_spec: dict | None = None
    inputs: dict[str, Path] = field(default_factory=dict)
    path: Path | None = None
    #: reader options of the measurement files (``input:`` block), as read_cloud's keywords
    input: dict = field(default_factory=dict)
    #: the ``uncertainty:`` block (core.uncertainty.UncertaintySpec), None when the recipe has none
    uncertainty: Any = None
    #: the ``tolerance:`` block (core.tolerance.ToleranceSpec), None when the recipe has none
    tolerance: Any = None

    @property
    def base_dir(self) -> Path | None:
        return self.path.parent if self.path else None

    def build_surface(self):
        """The nominal surface (None when the recipe names none)."""
        if self.surface_spec is None:
            return None
        return parse_surface_spec(self.surface_spec).build(self.base_dir)

    def to_dict(self, full: bool = False) -> dict:
        d: dict = {"pointspro": RECIPE_VERSION}
        if self.surface_spec is not None:
            d["surface"] = _plain(self.surface_spec)
        if self.input:
            d["input"] = dict(self.input)
        if self.inputs:
            d["inputs"] = {k: str(v) for k, v in self.inputs.items()}
        d["steps"] = [s.to_yaml_entry(full) for s in self.steps]
        if self.uncertainty is not None:
            d["uncertainty"] = self.uncertainty.to_dict()
        if self.tolerance is not None:
            d["tolerance"] = self.tolerance.to_dict()
        return d

    def to_yaml(self) -> str:
        return dump_yaml(self.to_dict(), sort_keys=False)

    # -- edits: each returns a new Recipe (steps not edited are shared, never copied) ----------------
    def with_steps(self, steps) -> Recipe:
        return replace(self, steps=list(steps))

    def inserted(self, step: RecipeStep, at: int | None = None) -> Recipe:
        """``step`` added at position ``at`` (0-based; None: at the end)."""
        steps = list(self.steps)
        steps.insert(len(steps) if at is None else at, step)
        return self.with_steps(steps)

    def removed(self, i: int) -> Recipe:
        steps = list(self.steps)
        del steps[i]
        return self.with_steps(steps)

    def moved(self, i: int, j: int) -> Recipe:
        """Step ``i`` taken out and put back at position ``j``."""
        steps = list(self.steps)
        steps.insert(j, steps.pop(i))
        return self.with_steps(steps)

    def with_params(self, i: int, params: dict, registry: Registry | None = None,
                    where: str = "recipe") -> Recipe:
        """New parameters (a mapping, as in the YAML) for step ``i``, validated by its Params;
        RecipeError naming the step and the key when a value is invalid."""
        old = self.steps[i]
        entry = {old.id: dict(params)} | ({} if old.enabled else {"enabled": False})
        step = _parse_step(entry, i + 1, where, where, registry or Registry())
        steps = list(self.steps)
        steps[i] = step
        return self.with_steps(steps)

    def with_enabled(self, i: int, enabled: bool) -> Recipe:
        steps = list(self.steps)
        steps[i] = replace(steps[i], enabled=bool(enabled))
        return self.with_steps(steps)


@dataclass(frozen=True)
class NamedFile:
    """A file a recipe names: a mesh surface's ``path`` (section "surface"), a step's file parameter
    ("step": its position, id and recipe line) or an ``inputs:`` entry ("inputs"). ``path`` is
    resolved against the recipe's folder (``inputs:`` are resolved when the recipe is read)."""

    section: str
    key: str
    path: Path
    step: int = 0
    step_id: str = ""
    line: int | None = None


def named_files(recipe: Recipe) -> list[NamedFile]:
    """Every file the recipe names, in recipe order — the one enumeration behind the CLI's
    allowed-folder check (cli._check_recipe_files) and --resume's digests
    (batch.parameter_file_digests)."""
    from .step import file_parameters

    base = recipe.base_dir

    def at(value) -> Path:
        p = Path(value)
        return p if p.is_absolute() or base is None else base / p

    out = []
    spec = recipe.surface_spec or {}
    if spec.get("type") == "mesh" and isinstance(spec.get("path"), str):
        out.append(NamedFile("surface", "path", at(spec["path"])))
    for i, rs in enumerate(recipe.steps, 1):
        out += [NamedFile("step", k, at(v), i, rs.id, rs.line) for k, v in file_parameters(rs.params).items()]
    out += [NamedFile("inputs", k, Path(v)) for k, v in recipe.inputs.items()]
    return out


def make_step(step_id: str, params: dict | None = None, registry: Registry | None = None,
              position: int = 1, where: str = "recipe") -> RecipeStep:
    """One validated step, as the YAML entry ``- step_id: params`` at 1-based ``position`` would be
    (the same RecipeError for an unknown step or an invalid value)."""
    return _parse_step({step_id: dict(params or {})}, position, where, where, registry or Registry())


def _plain(o):
    if isinstance(o, dict):
        return {k: _plain(v) for k, v in o.items()}
    if isinstance(o, list):
        return [_plain(v) for v in o]
    return o


def load_recipe(path, registry: Registry | None = None, whole: bool = True) -> Recipe:
    """The recipe file, validated; ``whole``: also the checks across its steps and its surface
    (check_recipe_whole) — left to the caller that applies ``--set`` overrides first, so that an
    override can mend what the file as written breaks (a review)."""
    from .pathnames import why_not_a_file

    path = Path(path)
    why = why_not_a_file(path, "recipe file")
    if why is not None:
        raise RecipeError(f"{path}: {why}")
    text = read_utf8(path, "recipe", RecipeError)
    recipe = parse_recipe(load_yaml(text, str(path)), str(path), registry, base=path, design_dof=whole)
    # a recipe file is what a batch runs: its order is checked as it is read (a session's project
    # may hold a recipe mid-edit; run_pipeline checks before running any)
    if whole:
        check_recipe_whole(recipe, str(path))
    return recipe


def check_recipe_whole(recipe: Recipe, where: str) -> None:
    """The checks across a recipe's steps and its nominal: the steps' order (check_step_order) and a
    pose fit's design DOF against the surface type (_check_design_dof)."""
    check_step_order(recipe.steps, where)
    _check_design_dof(recipe.steps, recipe.surface_spec, where)


def parse_recipe(data, where: str = "recipe", registry: Registry | None = None,
                 base: Path | None = None, design_dof: bool = True) -> Recipe:
    """A recipe mapping, validated: its keys, steps, parameters and blocks, and (``design_dof``) a
    pose fit's design DOF against the surface type — the window, the Python API and projects read
    recipes here (a review: a Q-con with `dof: […, radius]` was accepted there and failed each run);
    the order of the steps is the caller's to check (a recipe may be held mid-edit)."""
    registry = registry or Registry()
    if not isinstance(data, dict):
        raise RecipeError(f"{where}: a recipe is a mapping with `pointspro: 1` and `steps:`")
    lines = getattr(data, "key_lines", {})

    def at(key=None, node=None) -> str:
        ln = (lines.get(key) if key is not None else None) or getattr(node, "line", None)
        return f"{where}, line {ln}" if ln else where

    for key in data:
        if key not in TOP_KEYS:
            raise RecipeError(f"{at(key)}: unknown key '{key}' (a recipe has {', '.join(TOP_KEYS)})")
    if "pointspro" not in data:
        raise RecipeError(f"{where}: missing `pointspro: {RECIPE_VERSION}` (the recipe format version)")
    if type(data["pointspro"]) is not int or data["pointspro"] != RECIPE_VERSION:  # true is not 1
        raise RecipeError(f"{at('pointspro')}: recipe format {data['pointspro']!r} is not supported "
                          f"(this PointsPro reads {RECIPE_VERSION})")

    surface = data.get("surface")
    if surface is not None:
        if not isinstance(surface, dict):
            raise RecipeError(f"{at('surface')}: surface: must be a mapping with a `type`")
        try:
            parse_surface_spec(surface)
        except ValidationError as e:
            # the line of the offending key, when the surface is written over several lines
            names = error_keys(e.errors()[0])
            names = names[1:] if names[:1] == [surface.get("type")] else names  # the union's tag
            ln = key_line(surface, names)
            loc = f"{where}, line {ln}" if ln else at("surface")
            raise RecipeError(format_validation_error(e, f"{loc}: surface: ", surface_model(surface.get("type")),
                                                      tag=surface.get("type"))) from None

    reader_options = _parse_input_block(data, at, where)

    inputs = data.get("inputs") or {}
    if not isinstance(inputs, dict):
        raise RecipeError(f"{at('inputs')}: inputs: must map names to file paths")
    resolved_inputs = {}
    for name, p in inputs.items():
        p = Path(str(p))
        if not p.is_absolute() and base is not None:
            p = base.parent / p
        if not _is_file(p):
            raise RecipeError(f"{at('inputs')}: inputs: key '{name}': file {p} not found")
        resolved_inputs[str(name)] = p

    if "steps" not in data:
        raise RecipeError(f"{where}: missing `steps:` (the list of steps; `steps: []` for none)")
    raw_steps = data["steps"]
    if raw_steps is None:
        raise RecipeError(f"{at('steps')}: steps: is empty — give the list of steps, or `steps: []` for none")
    if not isinstance(raw_steps, list):
        raise RecipeError(f"{at('steps')}: steps: must be a list of `- step_id: {{params}}`")
    steps = []
    for i, entry in enumerate(raw_steps, start=1):
        steps.append(_parse_step(entry, i, at("steps"), where, registry))

    # the shop's blocks (docs/uncertainty.md): validated here, before any file is read
    uncertainty = tolerance = None
    for key, what in (("uncertainty", "samples, noise, sources"), ("tolerance", "the drawing's form or limits")):
        if key in data and data[key] is None:  # `tolerance:` with nothing under it was silently dropped
            raise RecipeError(f"{at(key)}: {key}: is empty — give {what}, or remove the key")
    if data.get("uncertainty") is not None:
        from .uncertainty import parse_uncertainty

        # steps: a source needing a step the recipe lacks (probe_radius) is refused here too
        uncertainty = parse_uncertainty(data["uncertainty"], at("uncertainty"), where, steps=steps)
    if data.get("tolerance") is not None:
        from .tolerance import parse_tolerance

        tolerance = parse_tolerance(data["tolerance"], at("tolerance"), where)
        # a tolerance on a quantity these steps and this surface do not compute: one line, now
        tolerance.check_computable(steps, surface, at("tolerance"))
    if design_dof:
        _check_design_dof(steps, surface, where)
    return Recipe(steps, surface, resolved_inputs, base, reader_options, uncertainty, tolerance)


def _check_design_dof(steps, surface, where: str) -> None:
    """A pose fit asked to fit the nominal's own parameters (``dof`` with radius, conic or A_n:
    misalignment, probe_radius) on a nominal other than an even asphere is refused with the recipe:
    it failed each input at run time (core/geometry/posed_fit.py) while --check-only called the
    recipe ready (a review)."""
    if not isinstance(surface, dict) or surface.get("type") in (None, "even_asphere"):
        return
    from .geometry.posed_fit import POSE_DOF

    for k, s in enumerate(steps, start=1):
        dof = getattr(s.params, "dof", None)
        if not s.enabled or s.id not in ("misalignment", "probe_radius") or not dof:
            continue
        design = [n for n in dof if n not in POSE_DOF]
        if design:
            loc = f"{where}, line {s.line}" if s.line else where
            raise RecipeError(f"{loc}: step {k} '{s.id}': key 'dof': fitting {', '.join(design)} needs an "
                              f"even_asphere nominal (this recipe's surface is {surface.get('type')}); "
                              "fit the pose alone (alpha, beta, dx, dy, dz)")


def check_step_order(steps, where: str = "recipe") -> None:
    """Refuse a step that works on the form error (Step.reads_residual: zernike, bspline_map,
    correction — their ``channel`` left at "auto") placed before the step that makes it
    (Step.makes_residual: misalignment, register): run first, it would take the heights z — the
    part's sag on a curved part — for the form error, and write a "map" or a "correction" of the
    whole surface with exit 0 (a review: bspline_map first wrote a 71.8 mm PV map.asc) — unless a
    residual-making step ran before it too. README, "Step order". Disabled steps are not checked."""
    live = [(k, s) for k, s in enumerate(steps, start=1) if s.enabled]
    for pos, (k, s) in enumerate(live):
        if getattr(s.step_cls, "moves_points", False):
            _check_mover(live, pos, where)
        if not getattr(s.step_cls, "reads_residual", False):
            continue
        # the steps since the last that dropped the residual (transform: it referred to the old frame;
        # a review: misalignment, transform, zernike passed --check-only and zernike worked on z)
        since = next((i + 1 for i in range(pos - 1, -1, -1)
                      if getattr(live[i][1].step_cls, "drops_residual", False)), 0)
        if any(getattr(t.step_cls, "makes_residual", False) for _, t in live[since:pos]):
            continue  # a residual is there already (a second misalignment later refines it)
        if getattr(s.params, "channel", "auto") == "z":
            continue  # heights asked for by name: a map that is already form error
        if since > 0:
            j, t = live[since - 1]
            loc = f"{where}, line {s.line}" if s.line else where
            raise RecipeError(f"{loc}: step {k} '{s.id}' works on the form error (the residual), which "
                              f"step {j} '{t.id}' drops (it referred to the frame before): it would take "
                              f"the heights z for it — make the residual again after '{t.id}' "
                              "(misalignment, register)")
        maker = next(((j, t) for j, t in live[pos + 1:] if getattr(t.step_cls, "makes_residual", False)),
                     None)
        if maker is not None:
            j, t = maker
            loc = f"{where}, line {s.line}" if s.line else where
            raise RecipeError(f"{loc}: step {k} '{s.id}' works on the form error (the residual), which "
                              f"step {j} '{t.id}' makes later: it would take the heights z for it — move "
                              f"'{s.id}' after '{t.id}'")


def _check_mover(live, pos: int, where: str) -> None:
    """A step that moves the points (Step.moves_points) after the step that made the residual: the
    step right after it must make the residual again — else the form error used, carried or written
    is the points' before the move (a review: probe_radius after misalignment, summary RMS 27.8 µm
    for a true 0.99 µm). The same rule as core.pipeline's at run time, which failed every input of a
    night batch that --check-only had called ready."""
    k, s = live[pos]
    made = [(j, t) for j, t in live[:pos] if getattr(t.step_cls, "makes_residual", False)]
    if not made:
        return
    nxt = live[pos + 1] if pos + 1 < len(live) else None
    if nxt is not None and getattr(nxt[1].step_cls, "makes_residual", False):
        return
    j, t = made[-1]
    use = f"step {nxt[0]} '{nxt[1].id}' would use it" if nxt else "it would be written as the form error"
    loc = f"{where}, line {s.line}" if s.line else where
    raise RecipeError(f"{loc}: step {k} '{s.id}' moves the points, but the residual (the form error) is "
                      f"made before it by step {j} '{t.id}' and would no longer match them, and {use} — "
                      f"move '{s.id}' before '{t.id}', or make the residual again right after it "
                      "(misalignment, register)")


def _is_file(p: Path) -> bool:
    try:
        return p.is_file()
    except (OSError, ValueError):  # a name too long, a NUL byte in it: no such file either
        return False


def _parse_input_block(data, at, where: str) -> dict:
    """``input: {pixel_size_um, wavelength_nm, height_unit, invalid}`` → read_cloud's keywords
    (validated here, so a typo stops the recipe before any file is read)."""
    block = data.get("input")
    if block is None:
        return {}
    if not isinstance(block, dict):
        raise RecipeError(f"{at('input')}: input: must be a mapping of reader options "
                          "(pixel_size_um, wavelength_nm, height_unit, invalid)")
    from .io.formats import ReaderOptions

    lines = getattr(block, "key_lines", {})
    for key in block:
        try:
            ReaderOptions.parse({key: block[key]})
        except ValueError as e:
            ln = lines.get(key)
            loc = f"{where}, line {ln}" if ln else at("input")
            raise RecipeError(f"{loc}: input: {e}") from None
    return ReaderOptions.parse(dict(block)).to_dict()


def _parse_step(entry, i: int, steps_at: str, where: str, registry: Registry) -> RecipeStep:
    line = getattr(entry, "line", None)
    loc = f"{where}, line {line}" if line else steps_at
    enabled = True
    if isinstance(entry, str):
        step_id, raw = entry, {}
    elif isinstance(entry, dict):
        entry = dict(entry) if not isinstance(entry, LineDict) else entry
        keys = [k for k in entry if k != "enabled"]
        if len(keys) != 1:
            raise RecipeError(f"{loc}: step {i}: write one step per list item as `- step_id: {{params}}` "
                              f"(found keys {keys})")
        step_id, raw = keys[0], entry[keys[0]]
        if "enabled" in entry:
            if not isinstance(entry["enabled"], bool):
                raise RecipeError(f"{loc}: step {i} '{step_id}': key 'enabled' must be true or false")
            enabled = entry["enabled"]
        raw = {} if raw is None else raw
    else:
        raise RecipeError(f"{loc}: step {i}: expected `- step_id: {{params}}`, got {entry!r}")
    if not isinstance(step_id, str) or step_id not in registry:
        raise RecipeError(f"{loc}: step {i}: unknown step '{step_id}'; installed steps: "
                          f"{', '.join(registry.ids())}")
    if not isinstance(raw, dict):
        raise RecipeError(f"{loc}: step {i} '{step_id}': parameters must be a mapping, got {raw!r}")
    cls = registry.load(step_id)
    raw = dict(raw)
    if "enabled" in raw and "enabled" not in cls.Params.model_fields:
        # a review: `- knn_denoise: {window: 15, enabled: false}` read "unknown key" for the documented switch
        ln = key_line(entry[step_id] if isinstance(entry, dict) else None, ["enabled"]) or line
        raise RecipeError(f"{f'{where}, line {ln}' if ln else loc}: step {i} '{step_id}': key 'enabled' "
                          f"belongs beside the step, not among its parameters: `- {step_id}: {{…}}` with "
                          "`enabled: false` on the next line, indented under it")
    version = raw.pop("schema_version", cls.Params.schema_version)
    try:
        raw = cls.Params.migrate(raw, int(version))
        params = cls.Params.model_validate(raw)
    except ValidationError as e:
        # name the line of the first offending key when we know it
        ln = key_line(entry[step_id] if isinstance(entry, dict) else None, error_keys(e.errors()[0]))
        loc2 = f"{where}, line {ln}" if ln else loc
        raise RecipeError(format_validation_error(e, f"{loc2}: step {i} '{step_id}': ", cls.Params)) from None
    except (ValueError, TypeError) as e:
        raise RecipeError(f"{loc}: step {i} '{step_id}': {e}") from None
    return RecipeStep(step_id, params, cls, line, enabled)
