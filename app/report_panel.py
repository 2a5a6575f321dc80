"""The report panel: after a run, the form-error summary and each step's numbers and figures — the
same tables (core.report.table_html) and the same figure writers as the batch's report.html.

Figures are drawn only when a step is looked at, in a worker thread (matplotlib's Agg canvas with the
object API is safe off the GUI thread), into a folder that lives as long as the panel.
"""
from __future__ import annotations

import html
from pathlib import Path

from PySide6 import QtCore, QtWidgets

from .worker import Worker


def shown_report(report: dict) -> dict:
    """A step's report as the panel's table shows it: a key without a unit left out where the same
    number stands under its name with the unit (zernike reports ``norm_radius`` for its parameter and
    ``norm_radius_mm`` for the pupil: the table showed the radius twice). report.json keeps both."""
    import math

    from pointspro.core.units import KEY_UNITS, SHOWN_LENGTH_MM, unit_of_key

    def number(x):
        return isinstance(x, (int, float)) and not isinstance(x, bool) and math.isfinite(x)

    def same(k, twin, twin_unit):
        a, b = report[k], report[twin]
        if not (number(a) and number(b)):
            return False
        unit = unit_of_key(k)
        if unit in SHOWN_LENGTH_MM and twin_unit in SHOWN_LENGTH_MM:  # both lengths: in one unit
            a, b = a * SHOWN_LENGTH_MM[unit], b * SHOWN_LENGTH_MM[twin_unit]
        elif unit:  # a bare key with a unit of its own other than the twin's
            return False
        return math.isclose(a, b, rel_tol=1e-12, abs_tol=0.0)

    hidden = set()
    for k in report:
        if not isinstance(k, str) or any(k.endswith(suffix) for suffix, _ in KEY_UNITS):
            continue
        if any(k + suffix in report and same(k, k + suffix, unit) for suffix, unit in KEY_UNITS):
            hidden.add(k)
    return {k: v for k, v in report.items() if k not in hidden} if hidden else report


class ReportPanel(QtWidgets.QWidget):
    def __init__(self, parent=None):
        super().__init__(parent)
        outer = QtWidgets.QVBoxLayout(self)
        outer.setContentsMargins(2, 2, 2, 2)
        # said when what is shown is no longer the recipe's result (a review: after a failed run or a
        # deletion the old RMS and PV stood as if current)
        self.stale = QtWidgets.QLabel()
        self.stale.setWordWrap(True)
        self.stale.setStyleSheet("background:#fff3cd;color:#6b4e00;padding:3px")
        self.stale.hide()
        outer.addWidget(self.stale)
        lay = QtWidgets.QHBoxLayout()
        outer.addLayout(lay)
        # a splitter, the list narrow: at the window's default size the dock is ~430 px wide, and a
        # 230 px list left the tables ~170 px — values off to the right or wrapped a letter a line
        split = QtWidgets.QSplitter(QtCore.Qt.Horizontal)
        self.list = QtWidgets.QListWidget()
        self.list.setMinimumWidth(60)
        self.list.setTextElideMode(QtCore.Qt.ElideRight)
        split.addWidget(self.list)
        self.view = QtWidgets.QTextBrowser()
        self.view.setOpenExternalLinks(True)
        # sentences wrap at the panel's edge (the Summary's note ran off it, read by scrolling
        # sideways: a review); a table's cells never wrap (nowrap below) and scroll sideways instead
        self.view.setLineWrapMode(QtWidgets.QTextEdit.WidgetWidth)
        self.view.document().setDefaultStyleSheet(
            "th{text-align:left;padding-right:8px} td{white-space:nowrap;padding-right:8px}")
        split.addWidget(self.view)
        split.setStretchFactor(0, 1)  # a wider panel widens the list too (its names were cut at
        split.setStretchFactor(1, 4)  # 120 px on a 1000 px panel: a review)
        split.setSizes([120, 400])
        lay.addWidget(split)
        self.result = None
        self._dir = QtCore.QTemporaryDir()
        self._drawn: set = set()
        self._serial = 0
        self.worker = Worker(self)
        self.worker.done.connect(lambda _: self._select(self.list.currentRow()))
        self.worker.failed.connect(lambda msg: self.view.append(f"<p>figures: {html.escape(msg)}</p>"))
        self.list.currentRowChanged.connect(self._select)
        self.view.setHtml("<p style='color:#777'>Run the pipeline: each step's numbers and figures "
                          "appear here.</p>")

    def set_stale(self, why: str) -> None:
        """Mark the shown results as those of an earlier run (``why``: what changed since)."""
        if self.result is None:
            return
        self.stale.setText(f"These results are from the last completed run; since then {why}. "
                           "Run all to update them.")
        self.stale.show()

    def set_result(self, result) -> None:
        self.stale.hide()
        self.result = result
        self._serial += 1
        self._drawn.clear()
        self.list.blockSignals(True)
        self.list.clear()
        self.list.addItem("Summary")
        for i, rec in enumerate(result.steps, 1):
            self.list.addItem(f"{i}. {rec.title} — {rec.seconds:.2f} s — {rec.points_in:,} → "
                              f"{rec.points_out:,}")
        self.list.blockSignals(False)
        self.list.setCurrentRow(0)
        self._select(0)

    def html_for(self, row: int) -> str:
        """The panel's page for row 0 (summary) or a step (1…), figures as far as drawn."""
        from pointspro.core.report import table_html

        r = self.result
        if r is None:
            return ""
        if row <= 0:
            from pointspro.core.statement import (
                PVR_DEFINITION,
                figure_rows,
                pupil_text,
                verdict_banner_html,
                weighting_text,
            )

            s = r.summary()
            # in the unit their size asks for; with an uncertainty value ± U95, noise bias removed
            figures = figure_rows(s)
            page = verdict_banner_html(s.get("tolerance"))  # green / red / amber, ISO 14253-1
            page += "<h3>Form error after all steps</h3>"
            if s.get("figures_of"):  # what the figures are of, and PVr's pupil (as report.html)
                pupil = s.get("pupil") or {}
                page += (f"<p style='color:#555'>Figures of the {html.escape(s['figures_of'])}"
                         + html.escape(pupil_text(pupil))
                         + (html.escape(PVR_DEFINITION) if s.get("pvr_um") is not None else "")
                         + html.escape(weighting_text(s)) + ".</p>")
            page += table_html({"points in": s["points_in"], "points out": s["points_out"], **figures})
            if s.get("uncertainty"):
                from pointspro.core.report import uncertainty_html

                page += "".join(p for p in uncertainty_html(s["uncertainty"]) if p)
            return page
        rec = r.steps[row - 1]
        warn = "".join(f"<p style='color:#a45200'>⚠ {html.escape(str(w))}</p>"
                       for w in rec.report.get("warnings", []) or [])
        parts = [f"<h3>{html.escape(rec.title)} <small>({html.escape(rec.id)})</small></h3>", warn,
                 table_html(shown_report(rec.report))]
        for name in self.figures_of(row):
            p = self._path(name, row)
            if p.is_file():
                parts.append(f"<p><img src='{QtCore.QUrl.fromLocalFile(str(p)).toString()}' width='560'>"
                             f"<br><small>{html.escape(name)}</small></p>")
            else:
                parts.append(f"<p style='color:#777'>drawing {html.escape(name)}…</p>")
        return "".join(parts)

    def figures_of(self, row: int) -> list[str]:
        if self.result is None or row <= 0:
            return []
        return sorted(n for n in self.result.steps[row - 1].artifacts if n.endswith(".png"))

    def _path(self, name: str, row: int) -> Path:
        # per run and per step: two steps of one kind draw figures of the same name
        return Path(self._dir.path()) / f"{self._serial}_{row}_{name}"

    def _select(self, row: int) -> None:
        self._show(row)
        key = (self._serial, row)
        todo = [(self._path(n, row).name, self.result.steps[row - 1].artifacts[n])
                for n in self.figures_of(row) if not self._path(n, row).is_file()]
        if todo and not self.worker.busy and key not in self._drawn:
            from pointspro.core.batch import write_artifact

            self._drawn.add(key)  # tried once: a figure that fails is said, not retried forever
            folder = Path(self._dir.path())

            def draw(_progress):
                for name, art in todo:
                    write_artifact(folder, name, art)
            self.worker.start(draw)

    def _show(self, row: int) -> None:
        self.view.setHtml(self.html_for(row))
