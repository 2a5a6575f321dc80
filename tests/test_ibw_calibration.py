"""Igor binary waves (.ibw) without lateral calibration (review, 2026-11-27): a wave saved without
x/y scaling has Igor's default scaling — sfA = 1 per point and no dimension unit — which
SurfaceTopography 1.27 reads as physical sizes (10, 10) in the height unit, so PointsPro gave a
silent 1 nm pixel (with `height_unit: nm`, or a data unit of nm) and refused `pixel_size_um` as
"the file gives its own lateral calibration". Such a map now needs `pixel_size_um`; a calibrated
wave keeps its own pixel (and refuses the option). Checked against the wave header decoded here with
struct (BinHeader5, 64 bytes, then WaveHeader5: nDim at +68, sfA at +84, dataUnits at +148,
dimUnits char[4][4] at +152 — Igor Technical Note 003, as igor2 spells it), cross-checked with igor2.

Files (tests/data/realdata; LICENSE-SurfaceTopography.md beside them):
  10x10-one_channel_without_name.ibw  SurfaceTopography test/file_format_examples/ (MIT)
  spot_1-1000nm.ibw                   idem (Asylum Research, 256 × 256 × 8, dimUnits m)
  10x10-dataunit_nm-no_dimunit.ibw    derived from the first: dataUnits set to "nm", checksum fixed
"""
from __future__ import annotations

import struct
from pathlib import Path

import numpy as np
import pytest

from pointspro.core.errors import InputError
from pointspro.core.io import read_cloud

DATA = Path(__file__).parent / "data" / "realdata"
CALIBRATED = DATA / "spot_1-1000nm.ibw"
NO_UNITS = DATA / "10x10-one_channel_without_name.ibw"          # no data unit, no dimension unit
NM_HEIGHTS = DATA / "10x10-dataunit_nm-no_dimunit.ibw"          # data unit nm, no dimension unit
UNCALIBRATED = [(NO_UNITS, {"height_unit": "nm"}), (NM_HEIGHTS, {})]
_DTYPES = {2: "f4", 4: "f8", 0x08: "i1", 0x10: "i2", 0x20: "i4"}


def _ibw_by_hand(path):
    """The v5 wave header and data decoded with struct/numpy, checked against igor2's decode:
    (nDim, sfA, dataUnits, [dimUnits] (extended units where present), data as [layer][q][p])."""
    b = Path(path).read_bytes()
    order = "<" if struct.unpack_from("<h", b, 0)[0] == 5 else ">"
    assert struct.unpack_from(order + "h", b, 0)[0] == 5
    assert sum(struct.unpack_from(order + "192h", b, 0)) % 65536 == 0  # Igor's header checksum
    wfm, formula, note, data_eu, *rest = struct.unpack_from(order + "4i4i4i", b, 4)
    dim_eu = rest[:4]
    wh = 64
    n_dim = struct.unpack_from(order + "4i", b, wh + 68)
    sf_a = struct.unpack_from(order + "4d", b, wh + 84)
    data_unit = b[wh + 148:wh + 152].split(b"\0")[0].decode("latin-1")
    dim_units = [b[wh + 152 + 4 * d:wh + 156 + 4 * d].split(b"\0")[0].decode("latin-1")
                 for d in range(4)]
    p = 64 + wfm + formula + note + data_eu
    for d in range(4):  # extended dimension units (names longer than 3 characters) replace them
        if dim_eu[d]:
            dim_units[d] = b[p:p + dim_eu[d]].split(b"\0")[0].decode("latin-1")
        p += dim_eu[d]
    typ = struct.unpack_from(order + "h", b, wh + 16)[0]
    n = int(np.prod([k for k in n_dim if k]))
    data = np.frombuffer(b, order + _DTYPES[typ & 0x3F], count=n, offset=wh + 320)
    data = data.reshape(max(n_dim[2], 1), n_dim[1], n_dim[0]).astype(np.float64)

    from igor2.binarywave import load  # an independent decode of the same header

    w = load(str(path))["wave"]
    assert list(w["wave_header"]["nDim"]) == list(n_dim)
    assert list(w["wave_header"]["sfA"]) == list(sf_a)
    assert w["wave_header"]["dataUnits"].tobytes().split(b"\0")[0].decode("latin-1") == data_unit
    assert [u.tobytes().split(b"\0")[0].decode("latin-1") for u in w["wave_header"]["dimUnits"]] \
        == [u if not dim_eu[d] else "" for d, u in enumerate(dim_units)]
    return n_dim, sf_a, data_unit, dim_units, data


def _one_line(e, p):
    msg = str(e.value)
    assert msg.startswith(str(p)) and "\n" not in msg and "internal error" not in msg
    assert "Traceback" not in msg and len(msg) < 400
    return msg


def test_calibrated_ibw_keeps_its_78_nm_pixel_and_refuses_the_option():
    """The Asylum map states its step: sfA = 7.843e-8 per point in m for x and y (20 µm / 255).
    A guard: this file was read right before the fix and must stay so."""
    n_dim, sf_a, data_unit, dim_units, data = _ibw_by_hand(CALIBRATED)
    assert n_dim == (256, 256, 8, 0) and dim_units[:2] == ["m", "m"] and data_unit == "m"
    assert sf_a[0] == sf_a[1] == pytest.approx(7.843e-8, rel=1e-4)
    c = read_cloud(CALIBRATED)
    assert c.meta["instrument_format"] == "ibw" and c.meta["grid"] == [256, 256] and c.n == 256 * 256
    assert c.meta["pixel_mm"] == pytest.approx([sf_a[0] * 1e3, sf_a[1] * 1e3], rel=1e-12)  # m → mm
    assert c.meta["pixel_mm"][0] * 1e6 == pytest.approx(78.43, abs=0.005)  # nm
    assert np.allclose(c.x, c["col"] * sf_a[0] * 1e3, rtol=1e-12, atol=0)
    assert np.allclose(c.y, c["row"] * sf_a[1] * 1e3, rtol=1e-12, atol=0)
    # heights: layer 0 (HeightTrace) in m, at the wave's own coordinates x = i·sfA₀, y = j·sfA₁
    # (SurfaceTopography gives dimension 1 reversed: a y mirror, corrected in the reader)
    assert np.allclose(c.z, data[0][c["row"], c["col"]] * 1e3, rtol=1e-6, atol=0)
    with pytest.raises(InputError, match=r"gives its own lateral calibration; remove the reader "
                                         r"option pixel_size_um"):
        read_cloud(CALIBRATED, pixel_size_um=0.1)


@pytest.mark.parametrize("path,opts", UNCALIBRATED, ids=["no-units", "dataunit-nm"])
def test_uncalibrated_ibw_is_refused_without_pixel_size_um(path, opts):
    """Before: a 1 nm pixel, silently (sfA = 1 read as 1 of the height unit)."""
    n_dim, sf_a, _, dim_units, _ = _ibw_by_hand(path)
    assert n_dim[:2] == (10, 10) and sf_a[:2] == (1.0, 1.0) and dim_units == ["", "", "", ""]
    with pytest.raises(InputError) as e:
        read_cloud(path, **opts)
    msg = _one_line(e, path)
    assert msg == (f"{path}: the Igor binary wave file gives no lateral calibration (pixel size: "
                   "x and y have Igor's default scaling, 1 per point without a unit); give the "
                   "reader option pixel_size_um (µm), e.g. `input: {pixel_size_um: 1.1}` in the "
                   "recipe")


def test_uncalibrated_ibw_without_height_unit_names_both_options():
    """Before: only height_unit was asked for — and once given, the map was read with a 1 nm pixel."""
    with pytest.raises(InputError) as e:
        read_cloud(NO_UNITS)
    msg = _one_line(e, NO_UNITS)
    assert "gives no length unit for its heights and no lateral calibration" in msg
    assert "give the reader options height_unit (nm, µm, mm or m) and pixel_size_um (µm)" in msg


@pytest.mark.parametrize("path,opts", UNCALIBRATED, ids=["no-units", "dataunit-nm"])
def test_uncalibrated_ibw_takes_the_pixel_size_um_given(path, opts):
    """Before: refused ("the file gives its own lateral calibration")."""
    _, _, _, _, data = _ibw_by_hand(path)
    c = read_cloud(path, pixel_size_um=[2.0, 3.0], **opts)
    assert c.meta["instrument_format"] == "ibw" and c.meta["grid"] == [10, 10] and c.n == 100
    assert c.meta["pixel_mm"] == pytest.approx([2e-3, 3e-3], rel=1e-15)
    assert np.array_equal(c.x, c["col"] * 2e-3) and np.array_equal(c.y, c["row"] * 3e-3)
    assert np.isclose(np.ptp(c.x), 9 * 2e-3) and np.isclose(np.ptp(c.y), 9 * 3e-3)
    assert np.allclose(c.z, data[0][c["row"], c["col"]] * 1e-6, rtol=1e-12, atol=0)  # nm → mm
    c1 = read_cloud(path, pixel_size_um=1.1, **opts)
    assert c1.meta["pixel_mm"] == pytest.approx([1.1e-3, 1.1e-3], rel=1e-15)


@pytest.mark.parametrize("path", [NO_UNITS, NM_HEIGHTS], ids=["no-units", "dataunit-nm"])
def test_uncalibrated_ibw_refusal_is_one_line_from_the_cli(run_cli, path):
    """Before: `pointspro info` printed "pixel 1 nm × 1 nm" (dataunit-nm) or asked for height_unit
    alone (no-units)."""
    code, out, err = run_cli("info", path)
    assert code == 2 and out == "" and "Traceback" not in err
    assert err.strip().count("\n") == 0 and str(path) in err and "pixel_size_um" in err
