"""Force control that knows the finger: approach, touch, and the model's pressing curve as feed-forward.

A PI on the force overshoots at the touch, and no tuning cures it: before the touch the
force is 0 and tells the loop nothing, so the pressure ramps; the regulator (τ ≈ 25 ms)
and the tracked force (30 Hz) lag the set-point, so when the force appears the set-point
is already several kPa ahead of the line's pressure, and 7–12 mN per kPa beyond the touch
turn that lead into tens of mN (the PI: 35–190 mN at 0.15–0.3 N on the simulated board).
:class:`ModelController` acts on what the config knows instead (internal model control):

1. **Approach**: the set-point ramps until the finger's normal force reaches
   ``touch_force_n`` (at most half the target), by default at
   :data:`APPROACH_GAIN_PA_PER_N_S` times the target, between
   :data:`MIN_APPROACH_RATE_PA_PER_S` and the slew limit: the force with which the finger
   meets the object before the loop sees it grows with the ramp, so a small target is
   approached gently, a large one fast. A track slower than
   :data:`~bendsense.control.TRACK_BANDWIDTH_HZ` sees the touch later: the ramp slows by the
   square root of the ratio (a 6 Hz track: to 45 %). A block spanning more than
   :data:`~bendsense.control.pi.MAX_BLOCK_S` (a loop behind its board) ramps as if only
   that had passed: a late loop approaches more slowly.
2. **Touch**: the pressure of first touch ``P_c`` is where the model's pressing curve from
   ``P_c`` reaches the tracked force at the line's measured pressure (lagged like the
   track, so that the two are of the same moment). The curve is
   :func:`bendsense.mechanics.pressing.pressing_force`: the config's finger against a
   rigid object at the contact location, tabulated over ``P_c`` and ``P − P_c`` once per
   location (every 5 kPa to the pressure limit, interpolated). The lag is the track's,
   ``1 / (2π f)`` of its bandwidth f (``track_bandwidth_hz``).
3. **Pressing**: a reference force rises from the force at the touch to the target as a
   first-order step (:data:`REFERENCE_TAU_S`), and the set-point is the pressure at which
   the model presses with the reference plus the model's mismatch:

       u = P_c + ΔP_model(N_ref + m),   m ← low-pass(N_model(P) − N)   (τ = :data:`OBSERVER_TAU_S`)

   with ``N_model(P)`` the curve at the line's measured pressure, lagged like the tracked
   force. With an exact model ``m = 0`` and the set-point never passes the target's
   pressure: the regulator follows a smooth reference and the force does not overshoot.
   A finger stiffer or softer than its config, an object that gives way, a touch pressure
   misjudged: ``m`` absorbs the difference (the loop's integral action: at rest
   ``N_model(P) = N_ref + m`` and ``m = N_model(P) − N``, so ``N = N_ref``).

**Anti-windup** holds by construction: ``m`` is a filtered difference of two measured
quantities, not an accumulated error, so a set-point held at the pressure limit stores
nothing; ``m`` does not grow while the output sits at a bound in the direction it pushes,
and the reference never runs beyond the force the model reaches at the limit, so a lower
target takes the output off the limit at once. A rising output
is slew-limited (:data:`~bendsense.control.DEFAULT_MAX_RATE_PA_PER_S`: below the tracker's
1 kPa per frame pressure step; at the touch it drops back at once), a frame without a
force or a pressure holds it, and a contact lost for :data:`LOST_S` (the force below half
the touch force: the object moved away) returns to the approach from the current set-point.
"""

from __future__ import annotations

import math

import numpy as np

from bendsense.config import Config
from bendsense.control.force import _limits
from bendsense.control.pi import (
    DEFAULT_MAX_RATE_PA_PER_S,
    MAX_BLOCK_S,
    MAX_DT_S,
    TRACK_BANDWIDTH_HZ,
    FingerController,
    _positive,
)
from bendsense.errors import ArgumentError

__all__ = ["ModelController", "APPROACH_GAIN_PA_PER_N_S", "MIN_APPROACH_RATE_PA_PER_S", "DEFAULT_TOUCH_FORCE_N",
           "REFERENCE_TAU_S", "OBSERVER_TAU_S", "LOST_S"]

#: set-point ramp before the touch per newton of target [Pa/(N s)]: 450 kPa/s for 0.15 N (the PI's K_i N*)
APPROACH_GAIN_PA_PER_N_S = 3.0e6
#: slowest ramp before the touch [Pa/s]: a 0.05 N target near the base (12 mN/kPa) meets the object without
#: overshoot at 250 kPa/s, at 400 kPa/s with 28 mN (the simulated board)
MIN_APPROACH_RATE_PA_PER_S = 2.5e5
#: normal force that counts as the touch [N] (at most half the target): ~20× the tracked force's noise at 30 Hz
DEFAULT_TOUCH_FORCE_N = 0.008
#: time constant of the reference force's step from the touch to the target [s]
REFERENCE_TAU_S = 0.03
#: time constant of the model-mismatch observer [s]: slower than the regulator and the track, so it does not
#: chase their lag
OBSERVER_TAU_S = 0.04
#: a contact whose force stays below half the touch force this long [s] is lost: the approach resumes
LOST_S = 0.05
#: node spacing of the pressing tables [Pa]
TABLE_STEP_PA = 5e3

_APPROACH, _PRESSING = 0, 1


class _PressingTable:
    """The model's pressing force over (P_c, P − P_c) at one contact location, and its inverse."""

    def __init__(self, config, contact_s_m, max_pressure_pa):
        from bendsense.mechanics.pressing import pressing_force

        self.nodes = np.arange(0.0, max_pressure_pa + TABLE_STEP_PA / 2, TABLE_STEP_PA)
        self.force = pressing_force(config, contact_s_m, self.nodes, self.nodes[:, None] + self.nodes)

    def curve(self, touch_pa):
        """(ΔP nodes, force nodes) of the curve from ``touch_pa``, up to the first node without an equilibrium."""
        touch_pa = min(max(touch_pa, 0.0), self.nodes[-1])
        i = min(int(touch_pa // TABLE_STEP_PA), self.nodes.size - 2)
        w = (touch_pa - self.nodes[i]) / TABLE_STEP_PA
        force = (1.0 - w) * self.force[i] + w * self.force[i + 1]
        n = int(np.argmax(~np.isfinite(force))) if not np.isfinite(force).all() else force.size
        return self.nodes[:max(n, 2)], np.maximum.accumulate(np.nan_to_num(force[:max(n, 2)]))

    def touch_pressure(self, pressure_pa, force_n):
        """P_c such that the curve from P_c reaches ``force_n`` at ``pressure_pa`` (fixed-point steps)."""
        touch = pressure_pa
        for _ in range(4):
            dp, f = self.curve(touch)
            touch = pressure_pa - float(np.interp(force_n, f, dp))
        return touch


class ModelController(FingerController):
    """Control of one finger's contact normal force by its model's pressing curve (module docstring).

    Parameters
    ----------
    target_force_n : float
        The normal force to hold, N* [N] (>= 0; settable).
    config : Config
        The finger's config: its pressing curve.
    line : int, default 0
        The pressure line (0-based) the finger is on.
    finger : str, optional
        The finger (a gripper's blocks); None: a single actuator.
    max_pressure_pa : float
        Highest set-point [Pa].
    contact_s_m : float, optional
        Where the object touches the finger [m] (the processor's known contact location);
        None: where the estimate says at the touch (the tip for a tip load). The curve of
        this location (or the tip's) is tabulated here, before the loop runs (~0.3 s); one
        the estimate locates elsewhere is tabulated at its touch, once per millimetre.
    max_force_n : float, optional
        The most force the finger can press with at ``max_pressure_pa`` [N]; a target
        beyond it is refused; None: no bound.
    approach_rate_pa_per_s : float, optional
        Set-point ramp before the touch [Pa/s]; None: :data:`APPROACH_GAIN_PA_PER_N_S` × the
        target, within [:data:`MIN_APPROACH_RATE_PA_PER_S`, ``max_rate_pa_per_s``].
    touch_force_n : float, default :data:`DEFAULT_TOUCH_FORCE_N`
        Normal force that counts as the touch [N] (at most half the target is used).
    max_rate_pa_per_s : float, default :data:`~bendsense.control.DEFAULT_MAX_RATE_PA_PER_S`
        Slew limit of a rising set-point while pressing [Pa/s].
    track_bandwidth_hz : float, default :data:`~bendsense.control.TRACK_BANDWIDTH_HZ`
        The bandwidth of the track whose force the controller gets
        (:class:`~bendsense.pipeline.LiveProcessor`'s ``bandwidth_hz``): the model's force
        and the line's pressure are lagged by ``1 / (2π f)`` before they meet the tracked
        force, and a slower track than the default's approaches more slowly. With a 6 Hz
        track and the 30 Hz lag assumed, the simulated board overshot 0.15 N by 60 mN.

    Attributes
    ----------
    touch_pressure_pa : float
        P_c of the current contact [Pa]; NaN before the touch.
    reference_force_n : float
        N_ref [N].
    mismatch_n : float
        m, the model's force minus the tracked one [N].
    """

    def __init__(self, target_force_n, config, *, line=0, finger=None, max_pressure_pa, contact_s_m=None,
                 max_force_n=None, approach_rate_pa_per_s=None,
                 touch_force_n=DEFAULT_TOUCH_FORCE_N, max_rate_pa_per_s=DEFAULT_MAX_RATE_PA_PER_S,
                 track_bandwidth_hz=TRACK_BANDWIDTH_HZ):
        if not isinstance(config, Config):
            raise ArgumentError(f"config: expected a Config (bendsense.load_config(path)), got {type(config).__name__}")
        self.config = config
        length = config.actuator.length_m
        _limits(config, max_pressure_pa, contact_s_m)  # the pressing curve is tabulated up to the limit, at s_c
        self.contact_s_m = contact_s_m
        self.touch_force_n = _positive("touch_force_n", touch_force_n)
        self.max_rate = _positive("max_rate_pa_per_s", max_rate_pa_per_s)
        self.track_bandwidth_hz = _positive("track_bandwidth_hz", track_bandwidth_hz)
        self._lag_s = 1.0 / (2.0 * math.pi * self.track_bandwidth_hz)  # the track's lag behind the pressure
        self.approach_rate_pa_per_s = (None if approach_rate_pa_per_s is None
                                       else _positive("approach_rate_pa_per_s", approach_rate_pa_per_s))
        if self.approach_rate_pa_per_s is not None and self.approach_rate_pa_per_s > self.max_rate:
            raise ArgumentError(f"approach_rate_pa_per_s: {approach_rate_pa_per_s:g} Pa/s is faster than the slew "
                                f"limit max_rate_pa_per_s = {self.max_rate:g} Pa/s")
        self._tables = {}
        super().__init__(target_force_n, line=line, finger=finger, max_pressure_pa=max_pressure_pa, tip_s_m=length,
                         max_force_n=max_force_n)
        self._table(length if contact_s_m is None else contact_s_m)  # the known location's, before the loop runs

    def _table(self, contact_s_m) -> _PressingTable:
        key = round(float(contact_s_m), 3)  # one table per millimetre of contact location
        if key not in self._tables:
            self._tables[key] = _PressingTable(self.config, min(key, self.config.actuator.length_m),
                                               self.max_pressure_pa)
        return self._tables[key]

    def reset(self) -> None:
        """Back to the approach from set-point 0 (a new grasp)."""
        super().reset()
        self._mode, self._t, self._lost_s, self._lagged_pa = _APPROACH, math.nan, 0.0, math.nan
        self.touch_pressure_pa = self.reference_force_n = self.mismatch_n = math.nan
        self._curve, self._model_n, self._reachable_n = None, math.nan, math.nan

    def _touch(self, pressure_pa, force_n, contact_s_m):
        s_c = self.contact_s_m if self.contact_s_m is not None else contact_s_m
        table = self._table(s_c if math.isfinite(s_c) else self.tip_s_m)
        self.touch_pressure_pa = table.touch_pressure(pressure_pa, force_n)
        self._curve = dp, curve = table.curve(self.touch_pressure_pa)
        self._reachable_n = float(np.interp(self.max_pressure_pa - self.touch_pressure_pa, dp, curve))
        self.reference_force_n, self.mismatch_n, self._model_n = force_n, 0.0, force_n
        self._mode, self._lost_s = _PRESSING, 0.0

    def _press(self, dt, force_n, pressure_pa, out):
        dp, curve = self._curve
        model = float(np.interp(pressure_pa - self.touch_pressure_pa, dp, curve))
        self._model_n += (model - self._model_n) * -math.expm1(-dt / self._lag_s)
        m = self.mismatch_n + (self._model_n - force_n - self.mismatch_n) * -math.expm1(-dt / OBSERVER_TAU_S)
        at_top, at_bottom = out >= self.max_pressure_pa, out <= 0.0
        if not ((at_top and m < self.mismatch_n) or (at_bottom and m > self.mismatch_n)):  # anti-windup
            self.mismatch_n = m
        ref = self.reference_force_n
        ref += (self.target_force_n - ref) * -math.expm1(-dt / REFERENCE_TAU_S)
        self.reference_force_n = min(ref, self._reachable_n - self.mismatch_n)  # no reference beyond the limit
        u = self.touch_pressure_pa + float(np.interp(self.reference_force_n + self.mismatch_n, curve, dp))
        return min(max(u, 0.0), out + self.max_rate * dt, self.max_pressure_pa)  # slewing up only: letting go is safe

    def step(self, t_s, force_n, pressure_pa, contact_s_m=None) -> float:
        """Advance over a block's frames; returns the set-point [Pa].

        Parameters
        ----------
        t_s : array_like, shape (n,)
            Frame times [s], increasing.
        force_n : array_like, shape (n,)
            Measured (tracked) normal force N [N]; NaN holds the output.
        pressure_pa : array_like, shape (n,)
            The line's measured pressure [Pa]; NaN holds the output.
        contact_s_m : array_like, shape (n,), optional
            The estimate's contact location per frame [m] (used at the touch when the
            controller has no ``contact_s_m`` of its own).
        """
        out, last_t = self.output_pa, self._t
        times = np.asarray(t_s, dtype=float)
        span = times[-1] - last_t if times.size and math.isfinite(last_t) else 0.0
        late = MAX_BLOCK_S / span if span > MAX_BLOCK_S else 1.0  # a late block approaches as a short one (PI's rule)
        n = len(force_n)
        where = np.full(n, np.nan) if contact_s_m is None else np.asarray(contact_s_m, dtype=float)
        if where.shape != (n,):  # one location for every frame (a block's are per frame already)
            where = np.broadcast_to(where, (n,))
        touch_n = min(self.touch_force_n, 0.5 * self.target_force_n)
        rate = self.approach_rate_pa_per_s
        if rate is None:
            rate = min(max(APPROACH_GAIN_PA_PER_N_S * self.target_force_n, MIN_APPROACH_RATE_PA_PER_S), self.max_rate)
            rate *= min(1.0, self.track_bandwidth_hz / TRACK_BANDWIDTH_HZ) ** 0.5  # a slower track sees the touch later
        for t, f, p, s_c in zip(times.tolist(), np.asarray(force_n, dtype=float).tolist(),
                                np.asarray(pressure_pa, dtype=float).tolist(), where.tolist()):
            dt = min(t - last_t, MAX_DT_S) if t > last_t else 0.0  # the first frame, or a clock going back: no time
            if math.isfinite(t):
                last_t = t
            if not (math.isfinite(f) and math.isfinite(p)):
                continue
            lagged = self._lagged_pa
            self._lagged_pa = p if not math.isfinite(lagged) else lagged + (p - lagged) * -math.expm1(-dt / self._lag_s)
            if self._mode == _APPROACH:
                if self.target_force_n > 0.0 and f >= touch_n:
                    self._touch(self._lagged_pa, f, s_c)
                else:
                    out = min(out + rate * late * dt, self.max_pressure_pa) if self.target_force_n > 0 else 0.0
                    continue
            self._lost_s = self._lost_s + dt if f < 0.5 * touch_n else 0.0
            if self._lost_s > LOST_S and self.target_force_n > 0.0:
                self._mode = _APPROACH
                continue
            out = self._press(dt, f, p, out)
        self.output_pa, self._t = out, last_t
        return out
