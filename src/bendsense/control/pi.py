"""A PI controller of the contact normal force, with anti-windup and a slew limit.

A controller is a plain callable: ``controller(block) -> {line: pressure_pa}``, called
by :func:`bendsense.control.run` once per block of frames, with the block the processor
made of them (a :class:`~bendsense.pipeline.LiveBlock`, or a dict finger name → block for a
gripper). :class:`PIController` updates once per frame of the block, at the frames' own
times (the board's clock):

    e_k = N* − N_k,   u_k = u_ff + K_p e_k + I_k,   I_{k+1} = I_k + K_i e_k Δt_k,

with N_k the tracked contact normal force (:func:`bendsense.control.normal_force`). The
output is held inside ``[max(0, u_prev − r Δt), min(p_max, u_prev + r Δt)]`` (the pressure
limit and the slew limit ``r``); **anti-windup** by conditional integration (Åström &
Hägglund, *Advanced PID Control*, 2006, sec. 3.5): the integral grows only until the
unbounded output reaches ``[0, p_max]``'s bound in the direction the error pushes it,
and never beyond ``p_max`` itself, so the output leaves the limit as soon as the error
changes sign. The slew limit bounds the output only (a slewing output reaches its
target within ``p_max / r``, 0.24 s at the defaults).

The slew limit keeps the pressure changes between frames below what the tracker takes
for a pressure step (1 kPa per frame, ``bendsense.tracking.windows.PRESSURE_STEP_PA``,
which would restart its filter). A frame without a force (NaN) holds the integral.

**A loop that falls behind acts gently.** The set-point reaches the board only after the
whole block was processed: a block of many frames (the loop fell behind the board, on a
loaded machine) is a delay in the loop, and a PI tuned for a prompt loop overshoots
behind one. A block spanning more than :data:`MAX_BLOCK_S` (20 ms) therefore integrates
and slews as if only 20 ms had passed: the integral gain and the slew rate fall with the
delay, so a late loop approaches the object more slowly instead of overshooting. A loop
that keeps up (up to 20 frames per block at 1 kHz) is not affected.

Default gains, tuned on the simulated board (``benchmarks/bench_control.py``): against a
rigid object the paper's finger gains dN/dP ≈ 7 mN per kPa beyond first touch (contact
at 0.1 m), so K_i = 3e6 Pa/(N s) puts the loop's crossover near K_i · dN/dP ≈ 20 rad/s,
fast enough for a 0.3 s step and slow beside the regulator (τ = 25 ms); K_p = 5e4 Pa/N
damps the approach (a loop that keeps up overshoots by under 2 mN at touch pressures
35–50 kPa) while passing
the tracked force's noise (~0.1 mN at 1 kHz, 30 Hz bandwidth) to the pressure as ~5 Pa.
Before touch the force is 0 and the integral ramps the pressure at K_i N* (450 kPa/s for
0.15 N) up to the slew limit.
"""

from __future__ import annotations

import math

import numpy as np

from bendsense.control._kernels import warm as warm_kernels
from bendsense.control.force import normal_force
from bendsense.errors import ArgumentError

__all__ = ["FingerController", "PIController", "Grasp", "DEFAULT_KP_PA_PER_N", "DEFAULT_KI_PA_PER_N_S",
           "DEFAULT_MAX_RATE_PA_PER_S", "TRACK_BANDWIDTH_HZ", "MAX_BLOCK_S", "finger_block"]

#: proportional gain [Pa/N]
DEFAULT_KP_PA_PER_N = 5.0e4
#: integral gain [Pa/(N s)]
DEFAULT_KI_PA_PER_N_S = 3.0e6
#: slew limit of the set-point [Pa/s]: 0.5 kPa per frame at 1 kHz
DEFAULT_MAX_RATE_PA_PER_S = 5.0e5
#: bandwidth of the tracked force the loop closes on [Hz] (the processor's ``bandwidth_hz``): faster than the
#: live view's 5 Hz, whose lag the loop would have to wait out
TRACK_BANDWIDTH_HZ = 30.0
#: longest interval integrated at once [s]: a gap longer than this counts as this
MAX_DT_S = 0.05
#: a block spanning more than this [s] (the loop fell behind the board) integrates and slews as if only this had
#: passed: a loop that acts late acts gently (its gains fall with its delay)
MAX_BLOCK_S = 0.02


def _positive(name, value, *, zero=False):
    ok = not isinstance(value, bool) and isinstance(value, (int, float, np.integer, np.floating)) and math.isfinite(
        value) and (value >= 0 if zero else value > 0)
    if not ok:
        raise ArgumentError(f"{name}: expected a finite number {'>= 0' if zero else '> 0'}, got {value!r}")
    return float(value)


def finger_block(block, finger):
    """The block of ``finger`` in what a processor returned (a LiveBlock, or a dict finger → LiveBlock).

    Parameters
    ----------
    block : LiveBlock or dict of str to LiveBlock
        A processor's result for a block of frames.
    finger : str or None
        The finger's name; None: the only finger (a single actuator's block).
    """
    if not isinstance(block, dict):
        if finger is not None:
            raise ArgumentError(f"finger: {finger!r} given, but the processor gives a single actuator's blocks")
        return block
    if finger is None:
        if len(block) != 1:
            raise ArgumentError(f"finger: the processor gives fingers {', '.join(block)}: name the one to control")
        return next(iter(block.values()))
    if finger not in block:
        raise ArgumentError(f"finger: no finger {finger!r} (the processor gives {', '.join(block)})")
    return block[finger]


class FingerController:
    """What a controller of one finger's contact normal force is: its line, its checked target, its latest force.

    Subclasses implement :meth:`step`; calling the controller with a processed block takes
    the finger's part, its normal force (:func:`bendsense.control.normal_force`) and its
    line's pressure, and returns ``{line: set-point}``.

    Parameters
    ----------
    target_force_n : float
        The normal force to hold, N* [N] (>= 0; settable: :attr:`target_force_n`).
    line : int, default 0
        The pressure line (0-based) the finger is on.
    finger : str, optional
        The finger (a gripper's blocks); None: a single actuator.
    max_pressure_pa : float
        Highest set-point [Pa].
    tip_s_m : float, optional
        The contact location logged for a tip load [m] (the actuator's length).
    max_force_n : float, optional
        The most force the finger can press with at ``max_pressure_pa`` [N]
        (:func:`~bendsense.control.force_limit_n` of its config): a target beyond it is
        refused (ArgumentError); None: no bound.

    Attributes
    ----------
    output_pa : float
        The latest set-point [Pa].
    last : NormalForce or None
        The normal force of the latest block's frames.
    """

    def __init__(self, target_force_n, *, line=0, finger=None, max_pressure_pa, tip_s_m=None, max_force_n=None):
        if isinstance(line, bool) or not isinstance(line, (int, np.integer)) or not 0 <= line <= 254:
            raise ArgumentError(f"line: expected a pressure line 0..254, got {line!r}")
        self.line = int(line)
        self.finger = finger
        self.max_pressure_pa = _positive("max_pressure_pa", max_pressure_pa)
        self.tip_s_m = None if tip_s_m is None else _positive("tip_s_m", tip_s_m)
        self.max_force_n = None if max_force_n is None else _positive("max_force_n", max_force_n)
        self.target_force_n = target_force_n
        self.reset()
        warm_kernels()  # the normal force's kernel, before the loop runs

    @property
    def target_force_n(self) -> float:
        """The normal force to hold, N* [N]; setting it checks it against ``max_force_n``."""
        return self._target

    @target_force_n.setter
    def target_force_n(self, value) -> None:
        self._target = self.checked_target(value)

    def checked_target(self, value) -> float:
        """``value`` as a target [N], or ArgumentError: not a number >= 0, or beyond ``max_force_n``.

        Parameters
        ----------
        value : float
            A target force [N].
        """
        target = _positive("target_force_n", value, zero=True)
        if self.max_force_n is not None and target > self.max_force_n:
            who = "the finger" if self.finger is None else f"finger {self.finger}"
            hint = ("a force in mN given in N?" if target >= 1.0 and target / 1e3 <= self.max_force_n
                    else "a higher pressure limit lets it press harder")
            raise ArgumentError(f"target_force_n: {target:g} N is beyond what {who} can press at the pressure limit "
                                f"{self.max_pressure_pa / 1e3:g} kPa (at most {self.max_force_n:.3g} N: twice its "
                                f"blocked force, bendsense.control.force_limit_n); {hint}")
        return target

    @property
    def fingers(self) -> tuple:
        """The fingers this controller watches (for the safety checks of :func:`~bendsense.control.run`)."""
        return (self.finger,)

    def reset(self) -> None:
        """Forget the state (a new grasp): the output is 0."""
        self.output_pa = 0.0
        self.last = None
        self._logged_target = math.nan  # the target of the latest block (its log column)

    def step(self, t_s, force_n, pressure_pa, contact_s_m=None) -> float:
        """Advance over a block's frames; returns the set-point [Pa].

        Parameters
        ----------
        t_s : array_like, shape (n,)
            Frame times [s], increasing.
        force_n : array_like, shape (n,)
            Measured normal force N [N]; NaN: none.
        pressure_pa : array_like, shape (n,)
            The line's measured pressure [Pa]; NaN: no reading.
        contact_s_m : array_like, shape (n,), optional
            The estimate's contact location per frame [m].
        """
        raise NotImplementedError

    def __call__(self, block) -> dict:
        """The set-point of the finger's line after a block of frames: ``{line: pressure_pa}``.

        Parameters
        ----------
        block : LiveBlock or dict of str to LiveBlock
            The processor's result for the block.
        """
        own = finger_block(block, self.finger)
        self.last = normal_force(own, tip_s_m=self.tip_s_m)
        self._logged_target = self.target_force_n
        return {self.line: self.step(own.t_s, self.last.force_n, own.pressure_pa, self.last.contact_s_m)}

    def columns(self, prefix: str = "") -> dict:
        """The latest block's per-frame columns for the control log: normal force, σ, location, target, status.

        Parameters
        ----------
        prefix : str
            Put before each name (``"thumb_"`` for a gripper's finger).
        """
        nf = self.last
        if nf is None:
            return {}
        return {f"{prefix}normal_force_n": nf.force_n, f"{prefix}normal_force_std_n": nf.std_n,
                f"{prefix}contact_s_m": nf.contact_s_m,
                f"{prefix}target_force_n": np.full(nf.force_n.shape, self._logged_target),
                f"{prefix}status": nf.status}


class PIController(FingerController):
    """PI control of one finger's contact normal force through one pressure line (module docstring).

    Parameters
    ----------
    target_force_n : float
        The normal force to hold, N* [N] (>= 0; settable: :attr:`target_force_n`).
    line : int, default 0
        The pressure line (0-based) the finger is on.
    finger : str, optional
        The finger (a gripper's blocks); None: a single actuator.
    kp_pa_per_n : float, default :data:`DEFAULT_KP_PA_PER_N`
        Proportional gain [Pa/N].
    ki_pa_per_n_s : float, default :data:`DEFAULT_KI_PA_PER_N_S`
        Integral gain [Pa/(N s)].
    max_pressure_pa : float
        Highest set-point [Pa] (the anti-windup bound).
    feedforward_pa : float, default 0
        Constant added to the output [Pa] (e.g. the pressure of first touch).
    max_rate_pa_per_s : float, default :data:`DEFAULT_MAX_RATE_PA_PER_S`
        Slew limit of the set-point [Pa/s].
    tip_s_m : float, optional
        The contact location logged for a tip load [m] (the actuator's length).
    max_force_n : float, optional
        The most force the finger can press with at ``max_pressure_pa`` [N]
        (:func:`~bendsense.control.force_limit_n` of its config): a target beyond it is
        refused (ArgumentError); None: no bound.

    Attributes
    ----------
    integral_pa : float
        The integral term I [Pa] (and :class:`FingerController`'s ``output_pa``, ``last``).
    """

    def __init__(self, target_force_n, *, line=0, finger=None, kp_pa_per_n=DEFAULT_KP_PA_PER_N,
                 ki_pa_per_n_s=DEFAULT_KI_PA_PER_N_S, max_pressure_pa, feedforward_pa=0.0,
                 max_rate_pa_per_s=DEFAULT_MAX_RATE_PA_PER_S, tip_s_m=None, max_force_n=None):
        self.kp = _positive("kp_pa_per_n", kp_pa_per_n, zero=True)
        self.ki = _positive("ki_pa_per_n_s", ki_pa_per_n_s, zero=True)
        self.feedforward_pa = _positive("feedforward_pa", feedforward_pa, zero=True)
        self.max_rate = _positive("max_rate_pa_per_s", max_rate_pa_per_s)
        super().__init__(target_force_n, line=line, finger=finger, max_pressure_pa=max_pressure_pa, tip_s_m=tip_s_m,
                         max_force_n=max_force_n)

    def reset(self) -> None:
        """Forget the integral, the output and the time (a new grasp)."""
        super().reset()
        self.integral_pa = 0.0
        self._t = math.nan

    def step(self, t_s, force_n, pressure_pa=None, contact_s_m=None) -> float:
        """Advance over frames at times ``t_s`` with normal forces ``force_n``; returns the set-point [Pa].

        Parameters
        ----------
        t_s : array_like, shape (n,)
            Frame times [s], increasing.
        force_n : array_like, shape (n,)
            Measured normal force N [N]; NaN holds the integral.
        pressure_pa, contact_s_m : array_like, shape (n,), optional
            The line's pressure, the contact location (not used: the PI knows no model).
        """
        kp, ki, ff, pmax, rate = self.kp, self.ki, self.feedforward_pa, self.max_pressure_pa, self.max_rate
        target = self.target_force_n
        integral, out, last_t = self.integral_pa, self.output_pa, self._t
        times = np.asarray(t_s, dtype=float).tolist()
        span = times[-1] - last_t if times and math.isfinite(last_t) else 0.0
        scale = MAX_BLOCK_S / span if span > MAX_BLOCK_S else 1.0  # a late block acts as a short one
        for t, f in zip(times, np.asarray(force_n, dtype=float).tolist()):
            dt = t - last_t
            dt = scale * min(dt, MAX_DT_S) if dt > 0 else 0.0  # the first frame, or a clock going back: no time
            if math.isfinite(t):
                last_t = t
            lo, hi = max(0.0, out - rate * dt), min(pmax, out + rate * dt)
            if not math.isfinite(f):
                out = min(max(ff + integral, lo), hi)
                continue
            e = target - f
            grown = integral + ki * e * dt
            if e > 0 and ff + kp * e + grown > pmax:  # grow only up to where the output reaches the limit
                grown = min(grown, max(integral, pmax - ff - kp * e))
            elif e < 0 and ff + kp * e + grown < 0.0:
                grown = max(grown, min(integral, -ff - kp * e))
            integral = min(max(grown, -ff), pmax)  # never a term that alone passes a bound
            out = min(max(ff + kp * e + integral, lo), hi)
        self.integral_pa, self.output_pa, self._t = integral, out, last_t
        return out


class Grasp:
    """Several controllers as one: each finger its own (on its own line); their set-points merged.

    Parameters
    ----------
    controllers : sequence of FingerController
        One per controlled finger; two may not drive the same line.
    """

    def __init__(self, controllers):
        self.controllers = tuple(controllers)
        if not self.controllers:
            raise ArgumentError("controllers: expected at least one")
        lines = {}
        for c in self.controllers:
            if c.line in lines:
                raise ArgumentError(f"controllers: fingers {lines[c.line]} and {c.finger} both drive pressure line "
                                    f"{c.line}: control one of them")
            lines[c.line] = c.finger

    @property
    def fingers(self) -> tuple:
        """The controlled fingers."""
        return tuple(c.finger for c in self.controllers)

    @property
    def target_force_n(self) -> float:
        """The target of the first finger (all are set together) [N]."""
        return self.controllers[0].target_force_n

    @target_force_n.setter
    def target_force_n(self, value) -> None:
        targets = [c.checked_target(value) for c in self.controllers]  # every finger's check before any changes
        for c, target in zip(self.controllers, targets, strict=True):
            c.target_force_n = target

    def reset(self) -> None:
        """Reset every controller."""
        for c in self.controllers:
            c.reset()

    def __call__(self, block) -> dict:
        """Every controller's set-point after a block: ``{line: pressure_pa}``.

        Parameters
        ----------
        block : dict of str to LiveBlock
            The gripper processor's result for the block.
        """
        out = {}
        for c in self.controllers:
            out.update(c(block))
        return out

    def columns(self) -> dict:
        """The controllers' per-frame columns, each prefixed with its finger's name."""
        out = {}
        for c in self.controllers:
            out.update(c.columns(f"{c.finger}_"))
        return out
