"""The time left while marking, from what the board reports: the planned time of the paths
not yet marked, scaled by how fast the board goes — its own pace at first (measured on its
earlier jobs, :func:`insitu.services.mark.board_seconds`), then the pace of this run (actual
over planned time of the paths it reported done, the recent ones weighing most). The figure
shown never climbs: when the board falls behind, it holds until the board catches up."""

from __future__ import annotations

import numpy as np

MEMORY = 0.1
"""The pace forgets with this fraction of the run's planned time."""


class TimeLeft:
    """``path_s``: (N,) planned seconds of each path of the job, in order
    (:func:`insitu.marking.path_seconds`: passes, jumps and delays); ``start_done``: paths
    already done when this run started (a resume); ``pace``: the board's wall seconds per
    planned second before this run tells. Call :meth:`update` with the paths done (of the
    whole job) and the seconds since the run started; it returns the seconds left."""

    def __init__(self, path_s, start_done: int = 0, pace: float = 1.0):
        self.cum_s = np.concatenate([[0.0], np.cumsum(np.asarray(path_s, float))])
        self.start_done = int(np.clip(start_done, 0, len(self.cum_s) - 1))
        self.ratio = float(pace)                # actual / planned seconds, recent
        self._shown: float | None = None
        self._at = (self.start_done, 0.0)       # (done, elapsed) at the last update

    @property
    def planned_s(self) -> float:
        return float(self.cum_s[-1])

    def raw(self, done: int, elapsed_s: float) -> float:
        """Planned time left × the recent pace (updated by this call)."""
        done = int(np.clip(done, self.start_done, len(self.cum_s) - 1))
        planned = float(self.cum_s[done] - self.cum_s[self._at[0]])
        run_s = self.planned_s - float(self.cum_s[self.start_done])
        if planned > 0 and run_s > 0:
            w = 1.0 - np.exp(-planned / (MEMORY * run_s))
            self.ratio += w * ((elapsed_s - self._at[1]) / planned - self.ratio)
        return (self.planned_s - float(self.cum_s[done])) * self.ratio

    def update(self, done: int, elapsed_s: float) -> float:
        new = 0.0 if done >= len(self.cum_s) - 1 else self.raw(done, elapsed_s)
        shown = new if self._shown is None else min(self._shown, new)
        self._shown = max(shown, 0.0)
        self._at = (max(int(done), self._at[0]), elapsed_s)
        return self._shown
