"""Issue 17: a batch process imports scipy without parsing every docstring into a "supported
backends" table (core/lean_imports.py) — the same functions and results, only help() text differs;
the window's and the API's processes keep scipy as it is."""
from __future__ import annotations

import json
import subprocess
import sys

from .conftest import EXAMPLE

SCIPY_MODULES = "scipy.spatial, scipy.linalg, scipy.ndimage, scipy.interpolate, scipy.optimize, scipy.signal"


def _run(code: str, *args: str) -> str:
    out = subprocess.run([sys.executable, "-c", code, *args], capture_output=True, text=True,
                         encoding="utf-8", timeout=300)
    assert out.returncode == 0, out.stderr
    return out.stdout.strip()


def test_scipy_imports_and_computes_the_same_with_its_notes_skipped():
    code = (f"import sys, json, numpy as np\n"
            f"from pointspro.core.lean_imports import skip_scipy_capability_notes, scipy_notes_skipped\n"
            f"hooked = skip_scipy_capability_notes() if sys.argv[1] == 'skip' else False\n"
            f"import {SCIPY_MODULES}\n"
            f"from scipy.spatial import cKDTree\n"
            f"from scipy.ndimage import gaussian_filter\n"
            f"rng = np.random.default_rng(3); p = rng.standard_normal((500, 2))\n"
            f"d, i = cKDTree(p).query(p, k=5)\n"
            f"D = gaussian_filter(p, 1.5)\n"
            f"print(json.dumps(dict(hooked=hooked, skipped=scipy_notes_skipped(), d=d.sum().hex(),"
            f" i=int(i.sum()), D=D.sum().hex(), doc=gaussian_filter.__doc__)))")
    plain = json.loads(_run(code, "plain"))
    lean = json.loads(_run(code, "skip"))
    assert lean["hooked"] and lean["skipped"] and not plain["skipped"]
    assert (lean["d"], lean["i"], lean["D"]) == (plain["d"], plain["i"], plain["D"])
    # the docstring as written, without the table scipy appends to its Notes
    assert lean["doc"].startswith("Multidimensional Gaussian filter.") and "Parameters" in lean["doc"]
    assert "Array API Standard Support" in plain["doc"] and "Array API Standard Support" not in lean["doc"]


def test_the_stand_in_answers_other_questions_with_a_real_parse():
    """A future scipy asking the parsed docstring for more than its Notes and its text gets the real
    parse: the saving lost, the import not broken."""
    code = ("from pointspro.core.lean_imports import skip_scipy_capability_notes, _UnparsedDoc\n"
            "assert skip_scipy_capability_notes() and skip_scipy_capability_notes()  # idempotent\n"
            "import scipy._lib._array_api as xp\n"
            "def f(a):\n    '''Add one.\n\n    Parameters\n    ----------\n    a : float\n        a number\n    '''\n"
            "doc = xp.FunctionDoc(f)\n"
            "print(type(doc).__name__, doc['Notes'], str(doc).split(chr(10), 1)[1].lstrip(), "
            "sorted(doc._parsed_data)[:2] if hasattr(doc, '_parsed_data') else 'none')")
    out = _run(code)
    assert out.startswith("_UnparsedDoc [] Add one.")
    assert out.endswith("['Attributes', 'Examples']")  # _parsed_data: only a real parse has it


def test_a_scipy_without_the_hook_is_left_alone(monkeypatch):
    import types

    from pointspro.core import lean_imports

    fake = types.ModuleType("scipy._lib._array_api")  # a layout without FunctionDoc/xp_capabilities
    monkeypatch.setitem(sys.modules, "scipy._lib._array_api", fake)
    assert lean_imports.skip_scipy_capability_notes() is False
    assert not hasattr(fake, "FunctionDoc") and lean_imports.scipy_notes_skipped() is False


def test_only_the_batch_skips_the_notes(tmp_path):
    """`pointspro --batch` running its inputs itself skips them; the Python API does not."""
    batch = ("import sys; from pointspro.core.cli import main\n"
             "rc = main(['--batch', sys.argv[1], sys.argv[2], '--out', sys.argv[3], '--quiet', '--figures', 'none'])\n"
             "from pointspro.core.lean_imports import scipy_notes_skipped\n"
             "print(rc, scipy_notes_skipped(), 'scipy.spatial' in sys.modules)")
    assert _run(batch, str(EXAMPLE / "recipe.yaml"), str(EXAMPLE / "asphere_cmm.csv"),
                str(tmp_path / "out")) == "0 True True"
    api = ("import sys; import pointspro.core as pp\n"
           "r = pp.run(sys.argv[1], sys.argv[2])\n"
           "from pointspro.core.lean_imports import scipy_notes_skipped\n"
           "print(scipy_notes_skipped(), 'scipy.spatial' in sys.modules)")
    assert _run(api, str(EXAMPLE / "recipe.yaml"), str(EXAMPLE / "asphere_cmm.csv")) == "False True"


def test_a_pool_worker_skips_the_notes():
    from pointspro.core.executors import start_pool

    pool = start_pool(1, "none")
    try:
        assert pool.apply(_worker_state) == (True, True)
    finally:
        pool.terminate()
        pool.join()


def _worker_state():
    from pointspro.core.lean_imports import scipy_notes_skipped

    return scipy_notes_skipped(), "scipy.spatial" in sys.modules
