"""The simulated board's pressure regulators: one first-order lag with limits per pressure line.

A proportional pressure regulator (a valve with its own inner loop) follows its set-point
with a lag: ``τ dp/dt = p_set − p``, the set-point clipped to ``[0, p_max]`` (a regulator
neither sucks nor exceeds its supply), so the pressure stays in ``[0, p_max]`` too. The set
-point is held between frames (zero-order hold) and the lag is integrated exactly, so
after a step the pressure of frame ``k`` is ``p_set + (p_0 − p_set) exp(−k Δt / τ)``
whatever the frame rate.

Each line follows the scenario's set-point profile (:func:`closing_profile`: the fingers
close on the object, hold, open) until the host sends it a SETPOINT; from then on the host
drives that line alone. :meth:`PressureRegulators.release` (the board's host-silence
watchdog) puts every line at set-point 0, where it stays until the host sets it again.
"""

from __future__ import annotations

import math

import numpy as np

from bendsense.errors import ConfigError

__all__ = ["PressureRegulators", "closing_profile", "DEFAULT_TAU_S", "DEFAULT_MAX_PRESSURE_PA"]

#: Time constant of the simulated regulators [s].
DEFAULT_TAU_S = 0.025
#: Supply limit of the simulated regulators [Pa].
DEFAULT_MAX_PRESSURE_PA = 120e3


def closing_profile(t_s, *, close_pa: float = 90e3, period_s: float = 8.0):
    """The scenario's set-point over time: close on the object, hold, open, rest; repeat.

    Over each period ``T``: a ramp from 0 to ``close_pa`` over ``0.25 T``, a hold at
    ``close_pa`` until ``0.625 T``, a ramp back to 0 until ``0.75 T``, and 0 until ``T``.

    Parameters
    ----------
    t_s : float or array_like
        Time [s].
    close_pa : float
        Set-point while closed [Pa].
    period_s : float
        Period T [s].

    Returns
    -------
    ndarray
        Set-points [Pa], the shape of ``t_s``.
    """
    t = np.asarray(t_s, dtype=float)
    if t.ndim:
        return np.array([_closing(float(x), close_pa, period_s) for x in t.ravel()]).reshape(t.shape)
    return np.asarray(_closing(float(t), close_pa, period_s))


def _closing(t_s: float, close_pa: float, period_s: float) -> float:
    """:func:`closing_profile` at one time, in plain floats (the board calls it every frame)."""
    phase = (t_s % period_s) / period_s
    if phase < 0.625:
        return close_pa * min(phase / 0.25, 1.0)
    return close_pa * min(max((0.75 - phase) / 0.125, 0.0), 1.0)


def _number(name, value, *, low=0.0, open_low=True, high=math.inf) -> float:
    ok = not isinstance(value, bool) and isinstance(value, (int, float, np.integer, np.floating))
    if not ok or not math.isfinite(value) or value < low or (open_low and value == low) or value > high:
        bound = f"> {low:g}" if open_low else f">= {low:g}"
        raise ConfigError(f"{name}: must be a finite number {bound}" + (f" and <= {high:g}" if high < math.inf else "")
                          + f", got {value!r}")
    return float(value)


class PressureRegulators:
    """First-order pressure regulators with limits, one per line.

    Parameters
    ----------
    n_lines : int
        Pressure lines (1..255).
    rate_hz : float
        Frame rate [Hz]: :meth:`step` advances one frame period ``Δt = 1 / rate_hz``.
    tau_s : float
        Time constant τ of the lag [s].
    max_pressure_pa : float
        Supply limit p_max [Pa]: set-points and pressures stay in ``[0, p_max]``.
    profile : callable, optional
        ``profile(t_s) -> set-point [Pa]`` of the lines the host does not drive; default
        :func:`closing_profile` (clipped to p_max).
    initial_pa : float
        Pressure of every line at the start [Pa].

    Attributes
    ----------
    pressure_pa : ndarray, shape (n_lines,)
        The lines' pressures now [Pa].
    setpoint_pa : ndarray, shape (n_lines,)
        The set-points in force now [Pa] (after clipping): a host's from when it arrives (a
        board applies a SETPOINT on receipt, between frames too), the profile's from the
        frame it is read at.
    host : ndarray of bool, shape (n_lines,)
        Lines under host control (they got a SETPOINT).
    """

    def __init__(self, n_lines: int, rate_hz: float, *, tau_s: float = DEFAULT_TAU_S,
                 max_pressure_pa: float = DEFAULT_MAX_PRESSURE_PA, profile=None, initial_pa: float = 0.0):
        if isinstance(n_lines, bool) or not isinstance(n_lines, (int, np.integer)) or not 1 <= n_lines <= 255:
            raise ConfigError(f"n_lines: must be an integer in 1..255, got {n_lines!r}")
        self.rate_hz = _number("rate_hz", rate_hz)
        self.tau_s = _number("tau_s", tau_s)
        self.max_pressure_pa = _number("max_pressure_pa", max_pressure_pa)
        p0 = _number("initial_pa", initial_pa, open_low=False, high=self.max_pressure_pa)
        self._profile = closing_profile if profile is None else profile
        self._alpha = -math.expm1(-1.0 / (self.rate_hz * self.tau_s))  # 1 − exp(−Δt/τ)
        self.pressure_pa = np.full(int(n_lines), p0)
        self.setpoint_pa = np.zeros(int(n_lines))
        self._host = np.zeros(int(n_lines), dtype=bool)
        self._host_setpoint = np.zeros(int(n_lines))

    @property
    def n_lines(self) -> int:
        """Number of lines."""
        return self.pressure_pa.size

    @property
    def host(self) -> np.ndarray:
        """Lines under host control (a copy)."""
        return self._host.copy()

    def set(self, line: int, pressure_pa: float) -> bool:
        """Take a host set-point for a line (a SETPOINT frame); the line stays under host control.

        Parameters
        ----------
        line : int
            0-based line index.
        pressure_pa : float
            Requested pressure [Pa]; clipped to ``[0, p_max]``.

        Returns
        -------
        bool
            False (and nothing changed) when the line does not exist or the value is not finite.
        """
        if not 0 <= line < self.n_lines or not math.isfinite(pressure_pa):
            return False
        self._host[line] = True
        self._host_setpoint[line] = self.setpoint_pa[line] = min(max(float(pressure_pa), 0.0), self.max_pressure_pa)
        return True

    def release(self) -> None:
        """Set-point 0 on every line, held until the host sets the line again (the board's watchdog).

        Lines that followed the profile stop following it: a board that lost its host
        lets go of everything.
        """
        self._host[:] = True
        self._host_setpoint[:] = self.setpoint_pa[:] = 0.0

    def step(self, t_s: float) -> np.ndarray:
        """Advance one frame period, to the frame at time ``t_s``; return the pressures [Pa].

        The set-point in force over the period is the host's (lines under host control) or
        the profile's at ``t_s``.

        Parameters
        ----------
        t_s : float
            Time of the frame [s] (for the profile).

        Returns
        -------
        ndarray, shape (n_lines,)
            The lines' pressures at the frame [Pa] (a view: copy to keep).
        """
        scenario = min(max(float(self._profile(t_s)), 0.0), self.max_pressure_pa)
        np.copyto(self.setpoint_pa, np.where(self._host, self._host_setpoint, scenario))
        # a convex combination of the pressure and a set-point in [0, p_max]: stays in [0, p_max]
        self.pressure_pa += self._alpha * (self.setpoint_pa - self.pressure_pa)
        return self.pressure_pa
