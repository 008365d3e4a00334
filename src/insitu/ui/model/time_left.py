"""The time left while marking, from the job's planned time and the progress the board
reports: the planned time of the paths not yet marked, scaled by how fast the board really
goes (actual over planned time, averaged over the last tenth or so of the job, starting at
the board's own pace on its earlier jobs — :func:`insitu.services.mark.board_seconds` — or
1: the plan), smoothed, and counting down steadily — it rises only on a real slowdown."""

from __future__ import annotations

import numpy as np

SMOOTHING = 0.3
"""Weight of a new estimate against the one shown (exponential smoothing)."""
SLOWDOWN = 1.25
"""A new estimate this many times the count-down's value is a real slowdown: shown."""
MEMORY = 0.1
"""The speed ratio forgets with this fraction of the run's planned time."""


class TimeLeft:
    """``path_s``: (N,) planned seconds of each path of the job, in order
    (:func:`insitu.marking.path_seconds`: passes, jumps and delays);
    ``start_done``: paths already done when this run started (a resume); ``pace``: the
    board's actual over planned seconds before this run tells. Call :meth:`update`
    with the paths done (of the whole job) and the seconds since the run started; it returns
    the seconds left."""

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
        """Planned time left × the recent speed ratio (updated by this call)."""
        done = int(np.clip(done, self.start_done, len(self.cum_s) - 1))
        planned = float(self.cum_s[done] - self.cum_s[self._at[0]])
        run_s = self.planned_s - float(self.cum_s[self.start_done])
        if planned > 0 and run_s > 0:
            w = 1.0 - np.exp(-planned / (MEMORY * run_s))
            self.ratio += w * ((elapsed_s - self._at[1]) / planned - self.ratio)
        return (self.planned_s - float(self.cum_s[done])) * self.ratio

    def update(self, done: int, elapsed_s: float) -> float:
        new = 0.0 if done >= len(self.cum_s) - 1 else self.raw(done, elapsed_s)
        if self._shown is None:
            shown = new
        else:
            countdown = max(self._shown - (elapsed_s - self._at[1]), 0.0)
            if new > SLOWDOWN * countdown and new > countdown + 0.5:
                shown = new                                   # a real slowdown
            else:
                shown = min(countdown, SMOOTHING * new + (1 - SMOOTHING) * countdown)
        self._shown = max(shown, 0.0)
        self._at = (max(int(done), self._at[0]), elapsed_s)
        return self._shown

