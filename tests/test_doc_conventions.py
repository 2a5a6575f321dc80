"""The conventions the code relies on live in the project's documents (docs/conventions.md, Units;
docs/formats.md, Measurement models and explain.json) and say what the code does: the measurement
model's effect parameters in mm read in mm wherever a table labels numbers by their key (explain.json's
`amplitude` and `a3` were shown without a unit), every bare length key is named in the unit rule, the
rule's example formats as written, and formats.md names every key of a model and of explain.json."""
from __future__ import annotations

import re

import pytest

from .conftest import ROOT

CONVENTIONS = (ROOT / "docs" / "conventions.md").read_text(encoding="utf-8")
FORMATS = (ROOT / "docs" / "formats.md").read_text(encoding="utf-8")


def _section(text: str, title: str) -> str:
    m = re.search(rf"^## {re.escape(title)}\n(.*?)(?=^## |\Z)", text, re.S | re.M)
    assert m, f"no section '## {title}'"
    return m.group(1)


def _harmonic(name: str) -> bool:
    return re.fullmatch(r"[ab]\d+", name) is not None


def test_effect_parameters_in_mm_read_in_mm():
    """Each library effect's parameter in mm (core/simulate/effects.py `units`) is a length by its key,
    as explain.json reports it under found[].params; no parameter of another unit reads as mm."""
    from pointspro.core.simulate.effects import LIBRARY
    from pointspro.core.units import unit_of_key

    for eff in LIBRARY.values():
        for name, unit in zip(eff.params, eff.units):
            got = unit_of_key(name)
            assert (got == "mm") == (unit == "mm"), (eff.name, name, unit, got)
            assert unit_of_key(f"found.params.{name}") == got


def test_explain_lengths_are_shown_in_their_unit():
    from pointspro.core.units import format_keyed

    assert format_keyed("amplitude", 8.0e-6) == "8 nm"  # vibration.amplitude, mm
    assert format_keyed("a3", 5.0e-6) == "5 nm" and format_keyed("b5", 4.0e-6) == "4 nm"  # spindle_axial
    assert format_keyed("a2_arcsec", 0.3) == "0.3″"  # spindle_tilt keeps its suffix's unit
    assert format_keyed("a33", 1.0) == "1"  # beyond the library's 32 harmonics: no rule


def test_every_bare_length_key_is_named_in_the_unit_rule():
    from pointspro.core.units import BARE_LENGTH_KEYS

    units = _section(CONVENTIONS, "Units")
    named = set(re.findall(r"`([A-Za-z_0-9]+)`", units))
    missing = sorted(k for k in BARE_LENGTH_KEYS if not _harmonic(k) and k not in named)
    assert missing == []
    if any(_harmonic(k) for k in BARE_LENGTH_KEYS):
        assert "`a1`…`b32`" in units


def test_the_unit_rules_examples_are_what_the_code_prints():
    from pointspro.core.units import format_keyed

    units = _section(CONVENTIONS, "Units")
    examples = re.findall(r"`(\w+)`\s+([0-9.e+-]+) → \"([^\"]+)\"", units)
    assert examples
    for key, value, shown in examples:
        assert format_keyed(key, float(value)) == shown, (key, value)


def test_formats_names_every_key_of_a_measurement_model():
    from pointspro.core.simulate.effects import LIBRARY
    from pointspro.core.simulate.model import ModelSpec, ProbeSpec
    from pointspro.core.simulate.scan import ScanSpec

    doc = _section(FORMATS, "Measurement models and explain.json")
    for spec in (ModelSpec, ScanSpec, ProbeSpec):
        for key in spec.model_fields:
            assert f"`{key}`" in doc, (spec.__name__, key)
    for eff in LIBRARY.values():
        assert f"`{eff.name}`" in doc
        for name in eff.params:
            k = re.fullmatch(r"([ab])(\d+)(_arcsec)?", name)
            if k and int(k.group(2)) not in (eff.harmonics[0], eff.harmonics[-1]):
                continue  # a harmonic between the first and the last: "a2_arcsec … b32_arcsec"
            assert f"`{name}`" in doc, (eff.name, name)


@pytest.fixture(scope="module")
def explain_report(tmp_path_factory):
    """explain on a small spiral with a vibration and a spindle_axial harmonic hidden (~2 s)."""
    from pointspro.core import PointCloud
    from pointspro.core.explain.workflow import explain
    from pointspro.core.io import write_csv
    from pointspro.core.simulate.model import ModelSpec, simulate

    d = tmp_path_factory.mktemp("explain_doc")
    base = {"pointspro_model": 1, "surface": {"type": "even_asphere", "R": 200.0, "k": -0.5, "aperture": 30.0},
            "scan": {"type": "spiral", "radius": 10.0, "rpm": 60.0, "pitch": 0.4, "fs": 100.0},
            "probe": {"noise": 2e-6}, "seed": 1}
    truth = ModelSpec.model_validate({**base, "effects": [{"vibration": {"frequency_hz": 7.3, "amplitude": 8e-6}},
                                                           {"spindle_axial": {"a3": 5e-6}}]})
    sim = simulate(truth)
    write_csv(PointCloud.from_xyz(sim["x"], sim["y"], sim["z"], t=sim["t"], c=sim["c"]), d / "meas.csv")
    (d / "model.yaml").write_text(ModelSpec.model_validate(base).to_yaml(), encoding="utf-8")
    return explain(d / "meas.csv", d / "out", d / "model.yaml", bootstrap=0)


def test_formats_names_every_key_of_explain_json(explain_report):
    rep = explain_report
    assert {f["effect"] for f in rep["found"]} == {"vibration", "spindle_axial"}
    doc = _section(FORMATS, "Measurement models and explain.json")
    keys = set(rep) | set(rep["checks"]) | set(rep["unexplained"]) | set(rep["gap_before"])
    for f in rep["found"]:
        keys |= set(f) | set(f["evidence"])
        keys |= {k for h in f["evidence"].get("harmonics", []) for k in h}
    keys |= {k for a in rep["ambiguous_with"] for k in a}
    missing = sorted(k for k in keys if f"`{k}`" not in doc and f"`{k}[]`" not in doc)  # lists: `found[]`
    assert missing == []


def test_the_zernike_section_is_what_the_basis_does():
    """docs/conventions.md, Zernike: its index table is core/metrics/zernike.py's, and its signs are a
    fit's: z = 1e-4·x over a disk of 10 mm → m = +1 at +500 nm, 1e-4·y → m = −1, x² − y² → m = +2."""
    import numpy as np

    import pointspro.core as pp
    from pointspro.core.metrics import zernike as zk

    doc = _section(CONVENTIONS, "Zernike")
    rows = re.findall(r"^\| \((\d[^|]*)\) \| [^|]+ \| ([^|]+) \| ([^|]+) \| ([^|]+) \|$", doc, re.M)
    assert len(rows) == 7
    for pairs, *orders in rows:
        nm = [tuple(int(v.replace("−", "-")) for v in p.split(",")) for p in pairs.split(") / (")]
        for ordering, cell in zip(("ansi", "noll", "fringe"), orders):
            assert [int(j) for j in cell.split(" / ")] == [zk.index_of(n, m, ordering) for n, m in nm], (nm, ordering)

    rng = np.random.default_rng(0)
    r, a = 10 * np.sqrt(rng.uniform(0, 1, 4000)), rng.uniform(0, 2 * np.pi, 4000)
    x, y = r * np.cos(a), r * np.sin(a)

    def fit(z, normalization="rms"):
        cloud = pp.PointCloud.from_numpy(np.column_stack([x, y, z]))
        res = pp.step("zernike", ordering="fringe", terms=9, normalization=normalization, remove=[],
                      centre=[0, 0], norm_radius=10)(cloud)
        rep = next(s["report"] for s in res.report["steps"] if s["id"] == "zernike")
        return {(c["n"], c["m"]): c["coefficient_nm"] for c in rep["coefficients"] if abs(c["coefficient_nm"]) > 1e-6}

    assert fit(1e-4 * x) == pytest.approx({(1, 1): 500.0})
    assert fit(1e-4 * x, "peak") == pytest.approx({(1, 1): 1000.0})
    assert fit(1e-4 * y) == pytest.approx({(1, -1): 500.0})
    assert fit(1e-6 * (x * x - y * y)) == pytest.approx({(2, 2): 100 / np.sqrt(6)})
    assert fit(2e-6 * x * y) == pytest.approx({(2, -2): 100 / np.sqrt(6)})
