"""Start the window: `pointspro [FILE…]` and `pointspro --screenshot PNG [FILE…]`.

The window (app.window.MainWindow) renders core.session.Session and forwards the optician's actions
to it; everything it shows is computed by the core and the steps, the same as in `--batch`.
"""
from __future__ import annotations

import sys
from pathlib import Path


def build_window(files: list[Path]):
    """The main window with the first file opened (data, recipe or project); further data files are
    named in the log (one measurement at a time), recipes and projects are applied in order."""
    from .window import MainWindow

    win = MainWindow()
    data_opened = False
    for f in files:
        f = Path(f)
        is_data = not (f.suffix.lower() in (".yaml", ".yml"))
        if is_data and data_opened:
            win.log(f"{f}: one measurement at a time — open it after this one")
            continue
        win.open_any(str(f))
        data_opened = data_opened or (is_data and win.session.shown is not None)
    return win


def run_window(files: list[Path], screenshot: str | None = None, run: bool = False) -> int:
    from PySide6 import QtWidgets

    app = QtWidgets.QApplication.instance() or QtWidgets.QApplication(sys.argv[:1])
    if screenshot:
        import os

        os.environ["POINTSPRO_NO_DIALOGS"] = "1"  # a render for a picture never waits for a click
    win = build_window(files)
    if screenshot:
        win.banner.hide()  # a picture of the data, not of a leftover autosave
    win.show()
    if run:  # the recipe's steps, as Run all does, before the picture or the user's first look
        import time

        win.pipeline.run_all.click()
        t0 = time.perf_counter()
        while win.runner.busy and time.perf_counter() - t0 < 600:
            app.processEvents()
            time.sleep(0.01)
    if not screenshot:
        return app.exec()
    for _ in range(5):
        app.processEvents()
    win.plotter.render()
    app.processEvents()
    screen = win.screen() or app.primaryScreen()
    img = screen.grabWindow(win.winId())
    if img.isNull():
        img = win.grab()
    # through a temporary file in the same folder, renamed into place: a failed save leaves no
    # empty or half-written picture (the CLI checked the name: an image suffix, never an input)
    target = Path(screenshot)
    tmp = target.with_name(f".{target.stem}.partial{target.suffix}")
    saved = img.save(str(tmp))
    win.close()
    win.deleteLater()
    app.sendPostedEvents(None, 0)
    app.processEvents()
    if not saved:
        tmp.unlink(missing_ok=True)
        print(f"pointspro: --screenshot {screenshot}: the picture could not be written", file=sys.stderr)
        return 2
    tmp.replace(target)
    return 0
