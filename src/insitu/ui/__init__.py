"""``insitu gui``, the operator's application (``pip install 'insitu[gui]'``: PySide6 +
PyOpenGL).

:mod:`insitu.ui.model` holds what has no Qt (the contract in pyproject keeps it so): the
evented session with undo, the actions beyond the services, what and how the 3-D view draws.
:mod:`insitu.ui.qt` holds the widgets: the main window and its docks, the 3-D view with its
OpenGL renderer, the worker threads, the forms. Forms, icons and the stylesheet are in the
top-level ``ui/`` folder, shipped as ``insitu/ui/assets``.
"""
