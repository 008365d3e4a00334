"""The application without Qt: :mod:`session` (evented state, undo), :mod:`operations`
(actions in terms of the services), :mod:`scene_data` and :mod:`orbit_camera` (what and how
the 3-D view draws)."""
