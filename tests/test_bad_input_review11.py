"""Bad input found by an independent review (291 adversarial cases): each gets one clear line naming
the file, line or key — a truncated instrument file's library log, a corrupt 1e300, a link to
itself, a pipe or a device, a truncated .npz's open handle, a union parameter's pydantic words."""
from __future__ import annotations

import gc
import os
import subprocess
import sys
import warnings
from pathlib import Path

import pytest

from pointspro.core.errors import InputError, RecipeError
from pointspro.core.io import read_cloud
from pointspro.core.recipe import load_recipe

from .conftest import EXAMPLE, write

REALDATA = Path(__file__).parent / "data" / "realdata"
MAP_RECIPE = "pointspro: 1\nsteps:\n  - zernike: {terms: 4, remove: [piston, tilt]}\n"


def test_a_truncated_opd_is_one_line_not_a_library_log_of_the_file(tmp_path):
    """Trying each format on a cut .opd, igor2's reader logged an error quoting the whole file:
    a 6.5 MB line on stderr before PointsPro's own."""
    data = (REALDATA / "opd-1.opd").read_bytes()
    cut = tmp_path / "cut.opd"
    cut.write_bytes(data[: len(data) // 2])
    recipe = write(tmp_path / "r.yaml", MAP_RECIPE)
    proc = subprocess.run([sys.executable, "-m", "pointspro.core.cli", "--batch", str(recipe), str(cut),
                           "--out", str(tmp_path / "o"), "--figures", "none", "--quiet"],
                          capture_output=True, timeout=300)
    err = proc.stderr.decode("utf-8", "replace")
    assert proc.returncode == 2
    assert len(err) < 2000 and "igor2" not in err, err[:300]
    assert "cut.opd: a damaged or truncated Wyko OPD file" in err


@pytest.mark.parametrize("where, row", [("x", 3), ("z", 7)])
def test_a_coordinate_beyond_any_machine_is_refused_by_its_line(tmp_path, where, row):
    lines = ["x,y,z"] + [f"{i * 0.5},{i * 0.25},{i * 1e-3}" for i in range(20)]
    x, y, z = lines[row].split(",")
    lines[row] = ",".join(v if a != where else "1e300" for a, v in zip("xyz", (x, y, z)))
    path = write(tmp_path / "p.csv", "# a comment\n" + "\n".join(lines) + "\n")
    with pytest.raises(InputError) as e:
        read_cloud(path)
    assert str(e.value).startswith(f"{path}, line {row + 2}: {where} = 1e+300 mm lies beyond any measuring")
    lines[row] = f"{x},{y},{z}"  # 5.4·10⁹ mm: far, but a coordinate (a UTM northing; 10⁹ refused it)
    lines[1] = "5.4e9,2.0,0.0"
    assert read_cloud(write(tmp_path / "q.csv", "\n".join(lines) + "\n")).n == 20


def test_a_coordinate_beyond_any_machine_in_a_ply_names_the_point(tmp_path):
    rows = [f"{i} {i} {i * 0.01}" for i in range(10)]
    rows[4] = "4 1e300 0.04"
    ply = "ply\nformat ascii 1.0\nelement vertex 10\nproperty double x\nproperty double y\n" \
          "property double z\nend_header\n" + "\n".join(rows) + "\n"
    with pytest.raises(InputError, match=r"the point with index 4: y = 1e\+300 mm lies beyond"):
        read_cloud(write(tmp_path / "p.ply", ply))


def test_a_link_to_itself_a_pipe_and_a_device_are_said_what_they_are(tmp_path, run_cli):
    loop = tmp_path / "loop.csv"
    loop.symlink_to(loop)
    with pytest.raises(InputError, match="a loop of symbolic links"):
        read_cloud(loop)
    dangling = tmp_path / "gone.csv"
    dangling.symlink_to(tmp_path / "nothing.csv")
    with pytest.raises(InputError, match="a symbolic link to .*nothing.csv, which leads to no file"):
        read_cloud(dangling)
    if hasattr(os, "mkfifo"):
        fifo = tmp_path / "fifo.csv"
        os.mkfifo(fifo)
        with pytest.raises(InputError, match="a pipe, not a regular file"):
            read_cloud(fifo)  # refused before opening: reading it would wait for a writer
    if Path("/dev/null").exists():
        with pytest.raises(RecipeError, match="/dev/null: a device, not a regular file"):
            load_recipe("/dev/null")  # said "recipe file not found"
        with pytest.raises(InputError, match="a device, not a regular file"):
            read_cloud(Path("/dev/null"))
    # the whole batch: the looped input fails alone, by name — it ended the batch with "internal
    # error: RuntimeError: Symlink loop … please report it"
    code, out, err = run_cli("--batch", EXAMPLE / "recipe.yaml", loop, "--out", tmp_path / "o")
    assert code == 2 and "internal error" not in err and "loop.csv: a loop of symbolic links" in err


def test_a_truncated_npz_leaves_no_file_open(tmp_path):
    import numpy as np

    from pointspro.core.cloud import PointCloud
    from pointspro.core.io.npz import write_npz_cloud

    good = tmp_path / "c.npz"
    write_npz_cloud(PointCloud.from_xyz(*np.random.default_rng(0).normal(size=(3, 50))), good)
    cut = tmp_path / "cut.npz"
    cut.write_bytes(good.read_bytes()[: good.stat().st_size // 2])
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        with pytest.raises(InputError, match="a damaged or truncated .npz"):
            read_cloud(cut)
        gc.collect()
    assert not [w for w in caught if issubclass(w.category, ResourceWarning)]


def test_a_value_no_branch_of_a_union_takes_is_said_in_words(tmp_path):
    recipe = write(tmp_path / "r.yaml", "pointspro: 1\nsteps:\n  - knn_denoise: {remove: all}\n")
    with pytest.raises(RecipeError) as e:
        load_recipe(recipe)
    assert str(e.value).endswith("key 'remove': 'auto' or a whole number (got 'all')")
    assert "literal" not in str(e.value) and "valid integer" not in str(e.value)
    write(recipe, "pointspro: 1\nsteps:\n  - knn_denoise: {remove: 2.5}\n")
    with pytest.raises(RecipeError, match=r"key 'remove': 'auto' or a whole number \(got 2.5\)$"):
        load_recipe(recipe)


def test_quiet_drops_only_the_reading_threads_library_records():
    """While a file is read, its libraries' records are dropped — not other threads' (the window
    reads in a worker thread) nor PointsPro's own; nothing stays attached after."""
    import logging
    import threading

    from pointspro.core.io.instruments import quiet

    seen = []

    class Keep(logging.Handler):
        def emit(self, record):
            seen.append(record.name)

    h = Keep()
    root = logging.getLogger()
    root.addHandler(h)
    try:
        with quiet():
            with quiet():  # nested: the inner exit leaves the outer filter
                pass
            logging.getLogger("igor2.binarywave").error("a whole file")
            logging.getLogger("pointspro.test").error("ours")
            t = threading.Thread(target=lambda: logging.getLogger("myapp").error("another thread"))
            t.start()
            t.join()
        logging.getLogger("igor2.binarywave").error("after")
    finally:
        root.removeHandler(h)
    assert seen == ["pointspro.test", "myapp", "igor2.binarywave"]
    assert not h.filters
