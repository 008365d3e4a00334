"""The widgets (PySide6, PyOpenGL): :mod:`app`, :mod:`main_window` and its docks, :mod:`view3d`
with :mod:`gl_renderer`, :mod:`workers`, :mod:`forms` (the assets of the top-level ``ui/``)."""
