"""PointsPro's window (PySide6 + pyvistaqt). Imports the core; the core never imports this."""
