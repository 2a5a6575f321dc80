"""Issue 17: the batch's start-up imports only what every input needs; scipy.optimize (0.8 s) and
scipy.special (0.85 s with numpy.f2py, pulled in by scipy's array-API layer) load when a fit or a
Forbes surface first asks for them."""
from __future__ import annotations

import subprocess
import sys


def test_batch_start_does_not_import_optimize_or_special():
    code = ("import sys, pointspro.core.batch, pointspro.core.executors, pointspro.core.params, "
            "pointspro.core.surfaces; "
            "print(sorted(m for m in ('scipy.optimize', 'scipy.special', 'numpy.f2py') if m in sys.modules))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True,
                         encoding="utf-8")
    assert out.stdout.strip() == "[]"


def test_lazy_imports_still_work():
    import numpy as np

    from pointspro.core.geometry import fit_sphere
    from pointspro.core.surfaces.forbes import qcon_series

    rng = np.random.default_rng(0)
    d = rng.standard_normal((200, 3))
    p = 5.0 * d / np.linalg.norm(d, axis=1)[:, None] + [1.0, 2.0, 3.0]
    fit = fit_sphere(p)
    assert np.allclose(fit.params["radius"], 5.0, atol=1e-9)
    s, s1, s2 = qcon_series([1.0, 0.5], np.linspace(0.0, 1.0, 5))
    assert np.all(np.isfinite(s)) and s[0] != s[-1]


def test_reading_a_recipe_imports_no_scipy():
    """The batch's own process reads and checks the recipe while its pool's workers import scipy
    (core/executors.py WARM_MODULES): the steps import scipy where they use it."""
    code = ("import sys; from pathlib import Path; from pointspro.core.batch import load_batch_recipe; "
            "r = load_batch_recipe(Path(sys.argv[1])); r.build_surface(); "
            "print(sorted(m for m in sys.modules if m == 'scipy' or m.startswith('scipy.')))")
    from .conftest import EXAMPLE

    out = subprocess.run([sys.executable, "-c", code, str(EXAMPLE / "recipe.yaml")], capture_output=True,
                         text=True, check=True, encoding="utf-8")
    assert out.stdout.strip() == "[]"


def test_a_big_csv_is_read_exactly_without_pandas(tmp_path):
    """Files above 4 MB go through Arrow's CSV reader (core/io/text.py `_arrow_parse`): no pandas
    import (0.3 s of a batch's start), and every value read back to the last bit — 17-digit values
    over 600 decades, subnormals and the largest double included (in a channel: a coordinate beyond
    10¹² mm is refused as corrupt, docs/formats.md; the coordinates span 24 decades)."""
    import numpy as np

    rng = np.random.default_rng(7)
    v = rng.normal(0, 1, 4 * 70_000) * 10.0 ** rng.integers(-300, 300, 4 * 70_000)
    v[:4] = [5e-324, 2.2250738585072014e-308, 1.7976931348623157e308, 0.1]
    v = v.reshape(-1, 4)
    v[:, :3] = rng.normal(0, 1, (len(v), 3)) * 10.0 ** rng.integers(-12, 12, (len(v), 3))
    p = tmp_path / "big.csv"
    p.write_text("x,y,z,q\n" + "".join(f"{a!r},{b!r},{c!r},{d!r}\n" for a, b, c, d in v.tolist()))
    assert p.stat().st_size > 4_000_000
    out = tmp_path / "xyzq.npy"
    code = ("import sys, numpy as np; from pathlib import Path; from pointspro.core.io.text import read_text; "
            "xyz, cols, _ = read_text(Path(sys.argv[1])); np.save(sys.argv[2], np.column_stack([xyz, cols['q']])); "
            "print('pandas' in sys.modules)")
    res = subprocess.run([sys.executable, "-c", code, str(p), str(out)], capture_output=True, text=True,
                         check=True, encoding="utf-8")
    assert res.stdout.strip() == "False"
    assert np.array_equal(np.load(out).view(np.int64), v.view(np.int64))


def test_figures_none_does_not_load_matplotlib(tmp_path):
    """`--figures none` draws nothing, so its process never loads matplotlib (~0.2–0.35 s of a
    10,000-point input's 1.1–1.5 s)."""
    import numpy as np

    rng = np.random.default_rng(3)
    x, y = np.meshgrid(np.linspace(-60.0, 60.0, 41), np.linspace(-60.0, 60.0, 41))
    z = 1e-4 * (x**2 + y**2) + 1e-4 * rng.standard_normal(x.shape)
    data = tmp_path / "plate.csv"
    np.savetxt(data, np.column_stack([x.ravel(), y.ravel(), z.ravel()]), delimiter=",", header="x,y,z",
               comments="")
    recipe = tmp_path / "recipe.yaml"
    recipe.write_text("pointspro: 1\nsteps:\n  - zernike: {terms: 4, remove: [piston, tilt]}\n  - bspline_map: {}\n",
                      encoding="utf-8")
    code = ("import sys; from pointspro.core.cli import main\n"
            "try:\n    main(sys.argv[1:])\nexcept SystemExit as e:\n    assert not e.code, e.code\n"
            "print(sorted(m for m in ('matplotlib',) if m in sys.modules))")
    out = subprocess.run([sys.executable, "-c", code, "--batch", str(recipe), str(data), "--out",
                          str(tmp_path / "out"), "--quiet", "--figures", "none"],
                         capture_output=True, text=True, encoding="utf-8")
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip().splitlines()[-1] == "[]"
    assert (tmp_path / "out" / "plate" / "report.json").is_file()
    assert not list((tmp_path / "out" / "plate").glob("*.png"))
