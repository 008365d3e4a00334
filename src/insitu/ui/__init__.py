"""``insitu gui``, the operator's application (PySide6 + PyOpenGL): the only part of insitu
that imports Qt or OpenGL.

Models (no Qt): :mod:`session` (evented state, undo), :mod:`project_file`,
:mod:`operations` (actions in terms of the services), :mod:`scene_data` and
:mod:`orbit_camera` (what and how the 3-D view draws). Qt: :mod:`main_window` and its docks,
:mod:`view3d` with :mod:`gl_renderer`, :mod:`workers`. Forms, icons and the stylesheet are
in the top-level ``ui/`` folder (:mod:`forms`).
"""
