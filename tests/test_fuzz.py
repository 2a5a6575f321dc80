"""Fuzzing the readers and the recipe loader (issue 18): whatever the bytes, `read_cloud` either
reads a cloud or raises one `InputError` of one line, and `load_recipe` / `parse_recipe` either give
a recipe or raise one `RecipeError` of one line — never another exception (which the batch would
report as an internal error, "please report").

Reproducible: every test is `derandomize=True` (the same cases on every run and machine) with no
example database.

`test_readers_10000_cases` is the CI run of 10,000 reader cases. Most of them exercise the readers
that are ours — x y z text tables (headers, units, separators, decimal commas, comments, NaN/inf,
ragged rows, BOM/Latin-1), text height matrices, PLY headers and bodies, X3P archives — because
those take a few milliseconds a case; random binary (≈ 2 % here) goes to SurfaceTopography's
detection, which tries every reader it has (≈ 35 ms a case), and is covered at more length by
`test_random_bytes` and `test_truncated_and_damaged_real_files`. About 40 s on a 2-core machine.
"""
from __future__ import annotations

import io
import os
import struct
import tempfile
import zipfile
from pathlib import Path

import pytest
import yaml
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from pointspro.core.errors import InputError, RecipeError
from pointspro.core.io import read_cloud
from pointspro.core.recipe import load_recipe, load_yaml, parse_recipe
from pointspro.core.registry import Registry

from .conftest import EXAMPLE, ROOT

REALDATA = ROOT / "tests" / "data" / "realdata"
FUZZ = dict(derandomize=True, database=None, deadline=None, print_blob=True,
            suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large,
                                   HealthCheck.large_base_example, HealthCheck.filter_too_much])


@pytest.fixture(scope="module")
def scratch():
    """The folder of the case files: in memory where Linux has one (a case opens its file ~6 times;
    on a disk that is a third of the run)."""
    shm = Path("/dev/shm")
    base = str(shm) if shm.is_dir() and os.access(shm, os.W_OK) else None
    with tempfile.TemporaryDirectory(prefix="pointspro-fuzz-", dir=base) as d:
        yield Path(d)


def check_read(folder: Path, suffix: str, content: bytes) -> None:
    """read_cloud on ``content`` saved as ``case<suffix>``: a cloud, or one line of InputError."""
    path = folder / f"case{suffix}"
    path.write_bytes(content)
    try:
        cloud = read_cloud(path)
    except InputError as e:
        msg = str(e)
        assert msg.strip() and "\n" not in msg and "\r" not in msg, repr(msg)
        assert str(path) in msg, msg  # names the file
        return
    assert cloud.n > 0 and cloud.xyz.shape == (cloud.n, 3)


def check_recipe(data, registry, where="fuzz.yaml") -> None:
    try:
        parse_recipe(data, where, registry)
    except RecipeError as e:
        msg = str(e)
        assert msg.strip() and "\n" not in msg and "\r" not in msg, repr(msg)


def check_recipe_text(folder: Path, text: str | bytes, registry) -> None:
    path = folder / "recipe.yaml"
    path.write_bytes(text if isinstance(text, bytes) else text.encode("utf-8", "surrogatepass"))
    try:
        load_recipe(path, registry)
    except RecipeError as e:
        msg = str(e)
        assert msg.strip() and "\n" not in msg and "\r" not in msg, repr(msg)


# --- strategies: files our readers parse ---------------------------------------------------------
# A table's body is drawn as one byte string, each byte picking a token (mostly good numbers, some
# bad ones, row breaks and comments): one draw per file keeps 10,000 cases fast, and shrinking the
# bytes towards zero shrinks the file towards good numbers.
GOOD_TOKENS = [str(v) for v in range(-9, 10)] + ["0.5", "-1.25", "3.14159", "1e-3", "-2.5E+2", "1000000",
                                                 "0.000001", "12.5", "-0.0", "7", "42.000", "1e5", "-3"]
BAD_TOKENS = ["nan", "NaN", "inf", "-inf", "1e308", "1e400", "-1e400", "0x10", "1,5", "1.5e", ".",
              "-", "", " ", "1_000", "1.2.3", "abc", "1e-400", "+", "−1", "１", "9" * 400, "'1'",
              '"2"', "#3", "1;2", "∞", "1 2", "\t", "µ", "x", "index"]
ROW_BREAK, COMMENT_LINE = "\x00row", "\x00comment"
TOKENS = ([GOOD_TOKENS[i % len(GOOD_TOKENS)] for i in range(200)] + BAD_TOKENS
          + [ROW_BREAK] * 12 + [COMMENT_LINE] * 4)
TOKENS += [GOOD_TOKENS[i % len(GOOD_TOKENS)] for i in range(256 - len(TOKENS))]
COMMENTS = ["# comment", "// note", "% matlab", "! fortran", "#", "", "   ", "Instrument: CMM 7",
            "Date: 2024-01-01", "# Width: 12 µm", "x y z", "\ufeffx,y,z", "ä ö ü"]
NAME = st.sampled_from(["x", "y", "z", "X [µm]", "Y [µm]", "Z [nm]", "x (mm)", "z [m]", "index", "t",
                        "xd", "residual", "pos_x", "Y[mm]", "x [furlong]", "a b", "1x", "", '"x"',
                        "µ", "z []", "x [", "x]", "weight", "X [in]", "z_pos", "c", "x", "y", "z"])
SEPARATOR = st.sampled_from([",", ";", "\t", " ", "  ", ", ", " ,", ";;"])
EOL = st.sampled_from(["\n", "\n", "\n", "\r\n", "\r"])
TEXT_SUFFIX = st.sampled_from([".csv", ".txt", ".xyz", ".asc", ".dat", ".sur", ".opd", ".x3p",
                               ".ply", ".foo", ""])


def _rows(body: bytes, ncols: int, sep: str) -> list[str]:
    """Lines of ``ncols`` tokens from the body's bytes; a row-break byte ends a row early."""
    lines, row = [], []
    for b in body:
        tok = TOKENS[b]
        if tok == ROW_BREAK or tok == COMMENT_LINE:
            if row:
                lines.append(sep.join(row))
                row = []
            if tok == COMMENT_LINE:
                lines.append(COMMENTS[b % len(COMMENTS)])
            continue
        row.append(tok)
        if len(row) == ncols:
            lines.append(sep.join(row))
            row = []
    if row:
        lines.append(sep.join(row))
    return lines


@st.composite
def text_tables(draw) -> tuple[str, bytes]:
    ncols = draw(st.integers(1, 6))
    sep, eol = draw(SEPARATOR), draw(EOL)
    lines = draw(st.lists(st.sampled_from(COMMENTS), max_size=2))
    if draw(st.booleans()):
        lines.append(sep.join(draw(st.lists(NAME, min_size=ncols - 1, max_size=ncols + 1))))
    lines += _rows(draw(st.binary(max_size=160)), ncols, sep)
    text = eol.join(lines) + draw(st.sampled_from(["", eol, sep, eol + eol]))
    variant = draw(st.integers(0, 99))
    if variant < 6:  # decimal commas of a European export
        text = text.replace(".", ",")
    enc = "utf-8-sig" if variant in (6, 7) else "latin-1" if variant in (8, 9, 10) else "utf-8"
    data = text.encode(enc, "replace")
    suffix = ".pcd" if variant == 11 else draw(TEXT_SUFFIX)  # .pcd: open3d's reader (slower: rare)
    return suffix, data


MATRIX_KEY = st.sampled_from(["# Width: 12.34 µm", "# Height: 5678.9 nm", "# Value units: m",
                              "# Value units: nm", "# Value units: furlong", "# Width: abc",
                              "# Height: -1 µm", "# Width: 0 mm", "# Channel: Height",
                              "x-length = 10", "y-length = 5", "x-pixels = 3", "y-pixels = 2",
                              "x-unit = µm", "z-unit = nm", "File Format = ASCII", "NX = 4",
                              "NY = 3", "Scale X = 1", "Scale Y = 1", "# Breite: 3 µm",
                              "# Höhe: 2 µm", "# Width: 1e400 m", "Wyko ASCII Data File Format 0"])


@st.composite
def matrices(draw) -> tuple[str, bytes]:
    header = draw(st.lists(MATRIX_KEY, min_size=2, max_size=6))
    rows = _rows(draw(st.binary(max_size=60)), draw(st.integers(1, 5)),
                 draw(st.sampled_from([" ", "\t", ","])))
    return draw(st.sampled_from([".txt", ".asc", ".csv", ".dat"])), \
        ("\n".join(header + rows) + "\n").encode("utf-8")


PLY_TYPE = st.sampled_from(["float", "double", "int", "uchar", "char", "short", "ushort", "uint",
                            "float32", "float64", "int8", "quad", ""])
PLY_LINE = st.one_of(
    st.tuples(PLY_TYPE, st.sampled_from(["x", "y", "z", "nx", "red", "index", "x"])).map(
        lambda t: f"property {t[0]} {t[1]}"),
    st.sampled_from(["property list uchar int vertex_indices", "element face 1", "element vertex",
                     "element vertex -1", "element vertex abc", "element vertex 99999999999",
                     "element", "property", "format", "format ascii", "comment hello", "obj_info",
                     "element edge 2", "property float", ""]))


@st.composite
def plys(draw) -> tuple[str, bytes]:
    fmt = draw(st.sampled_from(["ascii", "binary_little_endian", "binary_big_endian", "foo"]))
    n = draw(st.integers(0, 6))
    head = ["ply", f"format {fmt} 1.0"]
    if draw(st.integers(0, 4)):
        head.append(f"element vertex {n}")
        head += [f"property {t} {a}" for a, t in zip("xyz", draw(st.lists(PLY_TYPE.filter(bool),
                                                                          min_size=3, max_size=3)))]
    head += draw(st.lists(PLY_LINE, max_size=4))
    if draw(st.integers(0, 9)):
        head.append("end_header")
    body_kind = draw(st.integers(0, 3))
    if body_kind == 0:
        body = ("\n".join(_rows(draw(st.binary(max_size=30)), 3, " ")) + "\n").encode()
    elif body_kind == 1:
        body = b"".join(struct.pack("<ddd", *draw(st.tuples(*[st.floats(width=64)] * 3)))
                        for _ in range(n))
    else:
        body = draw(st.binary(max_size=120))
    return draw(st.sampled_from([".ply", ".ply", ".xyz"])), ("\n".join(head) + "\n").encode() + body


X3P_XML = st.sampled_from([
    "<ISO5436><Record1><FeatureType>SUR</FeatureType><Axes><CX><AxisType>I</AxisType>"
    "<Increment>1e-6</Increment></CX><CY><AxisType>I</AxisType><Increment>1e-6</Increment></CY>"
    "<CZ><AxisType>A</AxisType><DataType>{dt}</DataType></CZ></Axes></Record1><Record3>"
    "<MatrixDimension><SizeX>{nx}</SizeX><SizeY>{ny}</SizeY><SizeZ>1</SizeZ></MatrixDimension>"
    "<DataLink><PointDataLink>bindata/data.bin</PointDataLink></DataLink></Record3></ISO5436>",
    "<ISO5436><Record1><FeatureType>PRF</FeatureType></Record1><Record3/></ISO5436>",
    "<ISO5436><Record1><FeatureType>SUR</FeatureType><Axes><CX><AxisType>I</AxisType>"
    "<Increment>abc</Increment></CX><CY><AxisType>I</AxisType></CY><CZ/></Axes></Record1>"
    "<Record3><MatrixDimension><SizeX>{nx}</SizeX></MatrixDimension></Record3></ISO5436>",
    "<p:ISO5436_2 xmlns:p='http://www.opengps.eu/2008/ISO5436_2'><Record1><Revision>ISO5436 - 2000"
    "</Revision><FeatureType>SUR</FeatureType></Record1></p:ISO5436_2>",
    "<ISO5436>", "not xml at all", ""])


@st.composite
def x3ps(draw) -> tuple[str, bytes]:
    buf = io.BytesIO()
    nx, ny = draw(st.integers(-1, 4)), draw(st.integers(0, 4))
    xml = draw(X3P_XML).replace("{nx}", str(nx)).replace("{ny}", str(ny)).replace(
        "{dt}", draw(st.sampled_from(["D", "F", "L", "I", "Q", ""])))
    with zipfile.ZipFile(buf, "w") as zf:
        if draw(st.integers(0, 5)):
            zf.writestr("main.xml", xml)
        if draw(st.booleans()):
            zf.writestr("bindata/data.bin", draw(st.binary(max_size=200)))
    data = buf.getvalue()
    if draw(st.integers(0, 4)) == 0:
        data = data[:draw(st.integers(0, len(data)))]
    return draw(st.sampled_from([".x3p", ".x3p", ".zip", ".csv"])), data


# (sdf-1.sdf, a SurfaceTopography text format at ~45 ms a case, is left to the truncation test)
SMALL_REAL = {p.name: p.read_bytes() for p in (REALDATA / "xyz-1.txt",
                                              REALDATA / "gwyddion-export-english.txt")}
SMALL_REAL["asphere_head.csv"] = (EXAMPLE / "asphere_cmm.csv").read_bytes()[:3000]
SMALL_REAL["matrix_head.txt"] = (REALDATA / "matrix-3.txt").read_bytes()[:3000]


@st.composite
def damaged_small_real(draw) -> tuple[str, bytes]:
    name = draw(st.sampled_from(sorted(SMALL_REAL)))
    data = bytearray(SMALL_REAL[name])
    for _ in range(draw(st.integers(0, 4))):
        if not data:
            break
        i = draw(st.integers(0, len(data) - 1))
        op = draw(st.integers(0, 2))
        if op == 0:
            data[i] = draw(st.integers(0, 255))
        elif op == 1:
            del data[i:i + draw(st.integers(1, 40))]
        else:
            data[i:i] = draw(st.sampled_from([b"\n", b",", b"nan", b"#", b"\t", b"1e999", b"x", b"\xb5"]))
    data = bytes(data[:draw(st.integers(0, len(data)))]) if draw(st.booleans()) else bytes(data)
    return Path(name).suffix, data


RANDOM_SUFFIX = st.sampled_from([".csv", ".dat", ".sur", ".opd", ".sdf", ".mi", ".x3p", ".ply",
                                 ".bin", ".datx", ".txt"])


@st.composite
def reader_cases(draw) -> tuple[str, bytes]:
    """Mostly our own readers: 50 % text tables, 14 % PLY, 14 % text matrices, 4 % X3P, 16 % damaged
    small real text files; 2 % random bytes (SurfaceTopography's detection)."""
    k = draw(st.integers(0, 99))
    if k < 50:
        return draw(text_tables())
    if k < 64:
        return draw(plys())
    if k < 78:
        return draw(matrices())
    if k < 82:
        return draw(x3ps())
    if k < 98:
        return draw(damaged_small_real())
    return draw(RANDOM_SUFFIX), draw(st.binary(max_size=300))


# --- the readers ---------------------------------------------------------------------------------
def test_readers_10000_cases(scratch):
    seen = []

    @settings(max_examples=10_000, **FUZZ)
    @given(reader_cases())
    def run(case):
        suffix, content = case
        check_read(scratch, suffix, content)
        seen.append(1)

    run()
    assert len(seen) >= 10_000


@settings(max_examples=150, **FUZZ)
@given(st.tuples(RANDOM_SUFFIX, st.binary(max_size=2000)))
def test_random_bytes(scratch, case):
    check_read(scratch, *case)


REAL = sorted(p for p in REALDATA.iterdir() if p.suffix not in (".md",)) + [EXAMPLE / "asphere_cmm.csv"]
_REAL_BYTES: dict[Path, bytes] = {}


def _real(p: Path) -> bytes:
    if p not in _REAL_BYTES:
        _REAL_BYTES[p] = p.read_bytes()
    return _REAL_BYTES[p]


@settings(max_examples=150, **FUZZ)
@given(st.sampled_from(REAL), st.floats(0.0, 1.0), st.lists(st.tuples(st.floats(0.0, 1.0),
                                                                       st.integers(0, 255)), max_size=3))
def test_truncated_and_damaged_real_files(scratch, src, cut, flips):
    data = bytearray(_real(src)[:int(len(_real(src)) * cut)])
    for where, byte in flips:
        if data:
            data[min(int(where * len(data)), len(data) - 1)] = byte
    check_read(scratch, src.suffix, bytes(data))


@pytest.mark.parametrize("src", REAL, ids=lambda p: p.name)
def test_every_real_file_cut_at_its_header(scratch, src):
    """Cuts in the first kilobyte, where the headers are (a damaged header is the usual crash)."""
    data = _real(src)
    for cut in (0, 1, 2, 3, 4, 7, 8, 16, 31, 64, 100, 128, 255, 256, 511, 512, 1000, 1024):
        check_read(scratch, src.suffix, data[:cut])


# --- the recipe loader ---------------------------------------------------------------------------
@pytest.fixture(scope="module")
def registry():
    return Registry()


STEP_IDS = ["aperture", "manual_edit", "transform", "probe_radius", "misalignment", "knn_denoise",
            "zernike", "dynamic", "z_scale", "nope"]
KEYS = st.sampled_from(["pointspro", "surface", "input", "inputs", "steps", "type", "c", "k", "A",
                        "aperture", "diameter", "remove", "enabled", "schema_version", "pixel_size_um",
                        "wavelength_nm", "height_unit", "invalid", "path", "mesh", "radius", "order",
                        "norm_radius", "a", "calibration", *STEP_IDS])
SCALARS = st.one_of(st.none(), st.booleans(), st.integers(-10**20, 10**20), st.floats(),
                    st.sampled_from([10**400, -10**400, 2**63, 2**64]),
                    st.text(max_size=8), st.sampled_from(["even_asphere", "sphere", "mesh", "drop",
                                                          "error", "nm", "µm", "1", "1.0", "-5"]))
YAML_DATA = st.recursive(SCALARS, lambda inner: st.one_of(
    st.lists(inner, max_size=4), st.dictionaries(st.one_of(KEYS, st.integers(-3, 6)), inner,
                                                 max_size=5)), max_leaves=25)


@st.composite
def recipes(draw):
    """Recipe-shaped data: the right top keys most of the time, anything beneath them."""
    d = {}
    if draw(st.integers(0, 9)):
        d["pointspro"] = draw(st.sampled_from([1, 1, 1, 2, "1", None, 1.0]))
    for key in ("surface", "input", "inputs"):
        if draw(st.integers(0, 2)) == 0:
            d[key] = draw(YAML_DATA)
    if draw(st.integers(0, 3)) == 0:
        d["input"] = draw(st.dictionaries(st.sampled_from(["pixel_size_um", "wavelength_nm",
                                                           "height_unit", "invalid"]),
                                          st.one_of(SCALARS, st.integers(), st.lists(SCALARS, max_size=3)),
                                          max_size=3))
    if draw(st.integers(0, 4)):
        steps = []
        for _ in range(draw(st.integers(0, 4))):
            sid = draw(st.sampled_from(STEP_IDS))
            steps.append(draw(st.one_of(st.just(sid), st.fixed_dictionaries({sid: YAML_DATA}),
                                        YAML_DATA)))
        d["steps"] = steps
    else:
        d["steps"] = draw(YAML_DATA)
    if draw(st.integers(0, 9)) == 0:
        d[draw(KEYS)] = draw(YAML_DATA)
    return d


@settings(max_examples=1500, **FUZZ)
@given(recipes())
def test_random_recipe_data(registry, data):
    check_recipe(data, registry)


@settings(max_examples=1000, **FUZZ)
@given(recipes(), st.integers(0, 3), st.data())
def test_random_recipe_yaml_text(scratch, registry, data, mangle, draw):
    """Recipes as YAML text: dumped, then cut, spliced with YAML syntax, or tagged."""
    text = yaml.safe_dump(data, allow_unicode=True, sort_keys=False)
    if mangle == 1:
        text = text[:draw.draw(st.integers(0, len(text)))]
    elif mangle == 2:
        i = draw.draw(st.integers(0, len(text)))
        text = text[:i] + draw.draw(YAML_SNIPPET) + text[i:]
    elif mangle == 3:
        text = draw.draw(YAML_SNIPPET) + "\n" + text
    check_recipe_text(scratch, text, registry)


YAML_SNIPPET = st.sampled_from([
    "&a [*a]", "*undefined", "!!python/object:os.system {}", "!!binary 'not base64!'",
    "!!timestamp 2020-13-45", "2020-13-45", "? [1, 2]\n: 3", "? {a: 1}\n: b", "{[1]: 2}",
    "!!int '12x'", "!!float 'x'", "!!set {a, b}", "!!omap [a: 1]", "!!omap x", "!!pairs [1]",
    "<<: 5", "<<: [1, 2]", "<<: *a", "%YAML 1.1\n---", "---\n---", "...", "\t", ": :", "- - -",
    "'unterminated", '"\\x', "\x00", "\ufeff", "@", "`", "|\n  block", ">-", "{a: 1, a: 2}",
    "steps: [{aperture: {diameter: 1}, manual_edit: {}}]", "pointspro: 1\nsteps: !!str x",
    "1e400", ".nan", "-.inf", "0o17", "0x1F", "~", "[" * 200, "{" * 50, "2001-12-14t21:59:43.10-05:00",
])


@settings(max_examples=1000, **FUZZ)
@given(st.one_of(st.text(max_size=200), st.binary(max_size=200),
                 st.lists(YAML_SNIPPET, max_size=5).map("\n".join)))
def test_random_recipe_text(scratch, registry, text):
    check_recipe_text(scratch, text, registry)


@pytest.mark.parametrize("text", [
    "a: &a [*a, *a]\nb: &b [*a, *a]\nc: &c [*b, *b]\nd: &d [*c, *c]\ne: &e [*d, *d]\n"
    "f: &f [*e, *e]\ng: &g [*f, *f]\nh: &h [*g, *g]\ni: &i [*h, *h]\npointspro: *i\n",
    "pointspro: 1\nsteps:\n  - aperture: &x {diameter: [*x]}\n",
    "pointspro: 1\nsteps:\n  - aperture: {diameter: " + "[" * 2000 + "]" * 2000 + "}\n",
])
def test_hostile_yaml(scratch, registry, text):
    """Recursive aliases, an alias bomb and deep nesting: one line, quickly."""
    check_recipe_text(scratch, text, registry)


def test_the_example_recipe_still_loads():
    assert load_recipe(EXAMPLE / "recipe.yaml").steps
    assert load_yaml("a: 1", "x") == {"a": 1}
