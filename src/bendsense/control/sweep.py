"""A free pressure sweep through set-points: what ``identify free-bending --port`` drives.

:class:`Sweep` is a controller of :func:`bendsense.control.run` (so the loop's safety is
the sweep's: set-point 0 on every line whatever ends it, the stops of
:mod:`bendsense.control.safety`) that ignores the force: it walks one pressure line up a
staircase of ``levels`` equal steps from ``low_pa`` to ``high_pa`` and back down to
``low_pa``, each step a linear ramp over half its time and a hold over the other half, so
that the regulator settles and the frames cover the range both ways (a hysteresis shows
as two branches). The time is the board's clock (the frames' ``t_s``), from the first
block on; when the staircase has ended the sweep sets :attr:`Sweep.done`.
"""

from __future__ import annotations

import math
import threading

from bendsense.errors import ArgumentError

__all__ = ["Sweep", "DEFAULT_LEVELS"]

#: Steps of the staircase up (and as many down).
DEFAULT_LEVELS = 5


class Sweep:
    """The staircase sweep of one pressure line (module docstring); a controller of :func:`bendsense.control.run`.

    Parameters
    ----------
    low_pa, high_pa : float
        The lowest and highest set-point [Pa], ``0 <= low_pa < high_pa``.
    seconds : float
        Length of the whole staircase, up and down [s].
    levels : int
        Steps up (and as many down).
    line : int
        The pressure line driven.

    Attributes
    ----------
    done : threading.Event
        Set once the staircase has ended (pass it to ``run(stop=...)``).
    fingers : tuple
        Empty: the loop's safety watches no finger's force (a sweep acts on none).
    """

    fingers = ()

    def __init__(self, low_pa: float, high_pa: float, seconds: float, *, levels: int = DEFAULT_LEVELS, line: int = 0):
        for name, value in (("low_pa", low_pa), ("high_pa", high_pa), ("seconds", seconds)):
            if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
                raise ArgumentError(f"{name}: expected a finite number, got {value!r}")
        if not 0 <= low_pa < high_pa:
            raise ArgumentError(f"low_pa, high_pa: expected 0 <= low < high [Pa], got {low_pa:g}, {high_pa:g}")
        if not seconds > 0:
            raise ArgumentError(f"seconds: expected a time > 0 [s], got {seconds:g}")
        if isinstance(levels, bool) or not isinstance(levels, int) or levels < 1:
            raise ArgumentError(f"levels: expected an integer >= 1, got {levels!r}")
        self.low_pa, self.high_pa, self.seconds = float(low_pa), float(high_pa), float(seconds)
        self.levels, self.line = levels, int(line)
        self.done = threading.Event()
        self._t0 = None

    def setpoint(self, t_s: float) -> float:
        """The set-point ``t_s`` seconds into the sweep [Pa] (``low_pa`` before and after it).

        Parameters
        ----------
        t_s : float
            Time since the start of the sweep [s].
        """
        steps = 2 * self.levels
        x = min(max(t_s / self.seconds, 0.0), 1.0) * steps
        k = min(int(x), steps - 1)  # the step: from level a to level b
        a = k if k < self.levels else steps - k
        b = a + 1 if k < self.levels else a - 1
        frac = min((x - k) * 2.0, 1.0)  # ramp over the first half of the step, hold over the second
        level = a + (b - a) * frac
        return self.low_pa + (self.high_pa - self.low_pa) * level / self.levels

    def __call__(self, block) -> dict:
        """The set-point after the block's last frame, ``{line: pressure_pa}``.

        Parameters
        ----------
        block : LiveBlock or dict of str to LiveBlock
            The processor's block (a gripper's: the time of its first finger).
        """
        first = next(iter(block.values())) if isinstance(block, dict) else block
        t = float(first.t_s[-1])
        if self._t0 is None:
            self._t0 = float(first.t_s[0])
        if t - self._t0 >= self.seconds:
            self.done.set()
        return {self.line: self.setpoint(t - self._t0)}
