"""The one contract every registered step keeps (core/step.py), built-in or third-party."""
from __future__ import annotations

import numpy as np
import pytest
from pydantic import ValidationError

from pointspro.core.errors import Cancelled
from pointspro.core.forms import WIDGETS, form_fields
from pointspro.core.progress import CancelToken, Progress
from pointspro.core.recipe import format_validation_error
from pointspro.core.registry import Registry
from pointspro.core.step import Context, Params, Step, StepResult

REGISTRY = Registry()
STEP_IDS = REGISTRY.ids()


def test_builtin_steps_are_registered_through_entry_points():
    assert {"aperture", "manual_edit", "transform"} <= set(STEP_IDS)


@pytest.fixture(params=STEP_IDS)
def step_cls(request):
    return REGISTRY.load(request.param)


def test_identity_and_params_declaration(step_cls):
    assert step_cls.id.isidentifier() and step_cls.id == step_cls.id.lower()
    assert step_cls.title
    assert issubclass(step_cls.Params, Params)
    cfg = step_cls.Params.model_config
    assert cfg.get("extra") == "forbid" and cfg.get("frozen") is True
    assert isinstance(step_cls.Params.schema_version, int)
    for name, f in step_cls.Params.model_fields.items():
        assert f.description, f"{step_cls.id}.{name} has no help text"


def test_form_builds_from_schema(step_cls):
    fields = form_fields(step_cls.Params)
    assert [f.key for f in fields] == list(step_cls.Params.model_fields)
    for f in fields:
        assert f.widget in WIDGETS
        if f.widget == "choice":
            assert f.choices


def _invalid_values(step_cls):
    """Generated from the schema: below a bound, above a bound, wrong type, unknown key."""
    out = [("__no_such_key__", 1.0)]
    for f in form_fields(step_cls.Params):
        if f.widget in ("float", "int"):
            if f.minimum is not None:
                out.append((f.key, f.minimum - 1))
            if f.exclusive_minimum is not None:
                out.append((f.key, f.exclusive_minimum))
            if f.maximum is not None:
                out.append((f.key, f.maximum + 1))
            if f.exclusive_maximum is not None:
                out.append((f.key, f.exclusive_maximum))
            out.append((f.key, "not a number"))
        elif f.widget == "bool":
            out.append((f.key, "maybe"))
        elif f.widget == "choice":
            out.append((f.key, "__not_a_choice__"))
        elif f.widget == "list":
            out.append((f.key, 12.5))
    return out


def test_invalid_values_rejected_naming_the_key(step_cls):
    base = step_cls.example_params()
    cases = _invalid_values(step_cls)
    assert cases
    for key, value in cases:
        with pytest.raises(ValidationError) as ei:
            step_cls.Params.model_validate({**base, key: value})
        assert f"key '{key}" in format_validation_error(ei.value), (key, value)


def test_defaults_or_example_validate_and_params_are_frozen(step_cls):
    p = step_cls.Params.model_validate(step_cls.example_params())
    first = next(iter(step_cls.Params.model_fields))
    with pytest.raises(ValidationError):
        setattr(p, first, getattr(p, first))


def _ctx(surface, token=None):
    return Context(progress=Progress(None, token), surface=surface)


def test_runs_without_touching_its_input(step_cls, raster_cloud, asphere_002):
    raster_cloud = step_cls.example_cloud(raster_cloud)
    before_xyz = raster_cloud.xyz.copy()
    before = {k: v.copy() for k, v in raster_cloud.channels.items()}
    params = step_cls.Params.model_validate(step_cls.example_params())
    res = step_cls().run(raster_cloud, params, _ctx(asphere_002))
    assert isinstance(res, StepResult)
    assert res.cloud is not raster_cloud
    assert np.array_equal(raster_cloud.xyz, before_xyz)
    assert all(np.array_equal(raster_cloud.channels[k], v) for k, v in before.items())
    assert "index" in res.cloud.channels and res.cloud.xyz.dtype == np.float64
    assert np.all(np.diff(np.searchsorted(raster_cloud.index, res.cloud.index)) > 0)  # order kept
    import json

    json.dumps(res.report)  # JSON-able


def test_cancellation_is_honoured(step_cls, raster_cloud, asphere_002):
    raster_cloud = step_cls.example_cloud(raster_cloud)
    tok = CancelToken()
    tok.cancel()
    params = step_cls.Params.model_validate(step_cls.example_params())
    with pytest.raises(Cancelled):
        step_cls().run(raster_cloud, params, _ctx(asphere_002, tok))


def test_registry_unknown_step_message():
    from pointspro.core.errors import RecipeError

    with pytest.raises(RecipeError, match="unknown step 'nope'; installed steps: aperture"):
        Registry().load("nope")


def test_third_party_step_is_a_step_like_any_other():
    class Shift(Step):
        id, title = "shift_z", "Shift z"

        class Params(Params):
            dz: float = 0.0

        def run(self, cloud, params, ctx):
            ctx.progress.check()
            return StepResult(cloud.replace(xyz=cloud.xyz + [0, 0, params.dz]))

    reg = Registry(extra={"shift_z": Shift})
    assert "shift_z" in reg.ids() and reg.load("shift_z") is Shift


def test_a_mapping_entry_is_read_as_a_recipe_reads_it():
    """The window's table of a free-form mapping (correction's `programmed_surface`) kept "3.3e-4" as
    text, which the surface refused ("a number, not text"): each entry is read as YAML 1.2, as the
    recipe's value would be, and written back so that it reads the same."""
    from pointspro.core import forms
    from pointspro.plugins.correction import CorrectionStep

    field = next(f for f in forms.form_fields(CorrectionStep.Params) if f.key == "programmed_surface")
    rows = [["type", "even_asphere"], ["c", "3.3e-4"], ["k", "-1"], ["A", "{4: 1e-10, 6: -2e-15}"]]
    value = forms.pairs_value(field, rows)
    assert value == {"type": "even_asphere", "c": 3.3e-4, "k": -1, "A": {4: 1e-10, 6: -2e-15}}
    params = CorrectionStep.Params(programmed_surface=value)
    assert params.programmed_surface["c"] == 3.3e-4
    assert forms.pairs_value(field, forms.pairs_rows(value)) == value
    import pytest

    with pytest.raises(ValueError, match="programmed_surface"):
        forms.pairs_value(field, [["c", "[1, 2"]])
    with pytest.raises(ValueError, match="empty entry"):
        forms.pairs_value(field, [["c", " "]])
    # text YAML would read as something else comes back as itself (a review: "lens #2.stl" read back
    # as "lens", "null" as None, "1e3" as 1000.0, "[draft] lens.stl" refused)
    for path in ("parts/lens #2.stl", "#2.stl", "null", "1e3", "a: b.stl", "- a.stl", "[draft] lens.stl",
                 "'quoted'.stl", "%x.stl", "@a.stl", "*a.stl", "&a.stl", "!a.stl", "{a}.stl", "a.stl ",
                 "C:\\x\\a.stl", "plain.stl"):
        v = {"type": "mesh", "path": path}
        assert forms.pairs_value(field, forms.pairs_rows(v)) == v, path
