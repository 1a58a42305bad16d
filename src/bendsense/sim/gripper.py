"""The simulated gripper: K paper fingers on one board, pressure regulators, an object they press.

:func:`gripper_config` is the gripper's configuration (the fingers ``thumb, index, middle,
ring``, each the paper's prototype, finger ``i`` on board channels ``16 i + 1 .. 16 i +
16`` and pressure line ``i``). :class:`GraspBoard` is its board, frame by frame: each
line's pressure regulator (:mod:`bendsense.sim.regulator`) follows the scenario's closing
profile or the host's SETPOINTs; each finger at its line's pressure presses its object
(:mod:`bendsense.sim.grasp`: the force from the static equilibrium of the beam model,
tabulated over pressure at the start); its sensor reports ADC counts with noise. The
fingers share one sensor design and hardware (the simulator's seed), so one calibration
(``bendsense simulate calibration`` with the same seed) serves every finger; their noise
is independent.

The same board with one finger and no prefixes is the single actuator pressing an object
(``sim-device --object rigid``): version-1 frames, SETPOINT line 0; with no object it is
the free actuator, which :class:`ScriptedBoard` hands the line to once the host drives it
(``sim-device`` without ``--object``). Every finger may depart from its config by
``simulate``'s model errors (``ei_error``, ``k0_error``, ``base_rotation_rad_per_rad``,
``hysteresis_pa``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from bendsense.errors import ConfigError
from bendsense.sim.actuator import play_operator
from bendsense.sim.grasp import FingerGrasp, GraspObject
from bendsense.sim.regulator import DEFAULT_MAX_PRESSURE_PA, DEFAULT_TAU_S, PressureRegulators, _closing

__all__ = [
    "FINGER_NAMES",
    "DEFAULT_CONTACT_S_M",
    "DEFAULT_TOUCH_PRESSURE_PA",
    "DEFAULT_CLOSE_PA",
    "DEFAULT_COMPLIANT_N_PER_M",
    "GraspBoard",
    "Regulation",
    "ScriptedBoard",
    "gripper_config",
    "default_objects",
]

#: Names of the simulated gripper's fingers, in board order.
FINGER_NAMES = ("thumb", "index", "middle", "ring")
#: Where the object touches each finger, s_c [m] (the paper's actuator is 134 mm long).
DEFAULT_CONTACT_S_M = (0.10, 0.11, 0.095, 0.12)
#: The pressure at which each free finger reaches the object [Pa].
DEFAULT_TOUCH_PRESSURE_PA = (40e3, 45e3, 35e3, 50e3)
#: The scenario's closing set-point [Pa].
DEFAULT_CLOSE_PA = 70e3
#: Contact stiffness of the compliant object [N/m] (a soft foam ball: 7.5 mm at 0.15 N).
DEFAULT_COMPLIANT_N_PER_M = 20.0
_CHANNELS_PER_FINGER = 16
_NOISE_KEY = 2000  # the board's noise stream: SeedSequence(seed, spawn_key=(2000,)), apart from the scenarios'


def gripper_config(k: int = 3, config=None):
    """The simulated gripper's configuration: ``k`` paper fingers on one board.

    Parameters
    ----------
    k : int
        Fingers, 1..4: ``thumb, index, middle, ring`` in that order; finger ``i``
        (0-based) reads board channels ``16 i + 1 .. 16 i + 16`` and pressure line ``i``.
    config : Config, optional
        Every finger's actuator and sensor; default the paper's prototype.

    Returns
    -------
    GripperConfig
    """
    from bendsense.config import Finger, GripperConfig, load_config

    if isinstance(k, bool) or not isinstance(k, (int, np.integer)) or not 1 <= k <= len(FINGER_NAMES):
        raise ConfigError(f"fingers: must be an integer in 1..{len(FINGER_NAMES)}, got {k!r}")
    config = load_config() if config is None else config
    fingers = tuple(
        Finger(name=FINGER_NAMES[i], channels=tuple(range(16 * i + 1, 16 * i + 17)), pressure_line=i,
               config=config.replace(name=FINGER_NAMES[i]))  # a finger's config is named after it (as loaded)
        for i in range(int(k))
    )
    return GripperConfig(name=f"simulated gripper ({int(k)} fingers)", fingers=fingers)


def default_objects(k: int, stiffness_n_per_m: float = math.inf, contact_s_m=None, touch_pressure_pa=None) -> list:
    """The object as each of ``k`` fingers meets it (:class:`~bendsense.sim.grasp.GraspObject`).

    Parameters
    ----------
    k : int
        Fingers.
    stiffness_n_per_m : float
        Contact stiffness [N/m]; ``math.inf``: rigid.
    contact_s_m : float or sequence of float, optional
        s_c per finger [m] (one value: every finger); default :data:`DEFAULT_CONTACT_S_M`.
    touch_pressure_pa : float or sequence of float, optional
        Touch pressure per finger [Pa] (one value: every finger); default
        :data:`DEFAULT_TOUCH_PRESSURE_PA`.

    Returns
    -------
    list of GraspObject
    """
    s = _per_finger("contact_s_m", DEFAULT_CONTACT_S_M[:k] if contact_s_m is None else contact_s_m, k)
    p = _per_finger("touch_pressure_pa", DEFAULT_TOUCH_PRESSURE_PA[:k] if touch_pressure_pa is None
                    else touch_pressure_pa, k)
    return [GraspObject(s[i], p[i], stiffness_n_per_m) for i in range(k)]


def _per_finger(name, value, k) -> list:
    values = [value] if np.isscalar(value) else list(value)
    if len(values) == 1:
        values = values * k
    if len(values) != k:
        raise ConfigError(f"{name}: expected one value or one per finger ({k}), got {len(values)}")
    return values


@dataclass(frozen=True, kw_only=True)
class Regulation:
    """How a simulated board drives its pressure lines: the regulators and the profile they follow.

    Every line's regulator (:class:`~bendsense.sim.regulator.PressureRegulators`) lags
    its set-point by ``tau_s`` and holds it in ``[0, max_pressure_pa]``; a line the host
    does not drive follows the scenario's closing profile
    (:func:`~bendsense.sim.regulator.closing_profile`). ``scenario.yaml`` of ``simulate
    gripper`` writes these four under ``regulators``. :class:`GraspBoard` checks them.

    Attributes
    ----------
    tau_s : float
        The regulators' time constant [s].
    max_pressure_pa : float
        Their supply limit [Pa] (also the top of the fingers' pressure tables).
    close_pa : float
        The closing profile's set-point while closed [Pa].
    period_s : float
        The closing profile's period [s].
    """

    tau_s: float = DEFAULT_TAU_S
    max_pressure_pa: float = DEFAULT_MAX_PRESSURE_PA
    close_pa: float = DEFAULT_CLOSE_PA
    period_s: float = 8.0


@dataclass(frozen=True, eq=False)
class _Finger:
    name: str
    index: np.ndarray  # 0-based board channels
    line: int
    grasp: FingerGrasp
    keys: tuple  # truth keys: fx, fy, contact


class GraspBoard:
    """The simulated board of a gripper (or of one actuator) pressing an object, frame by frame.

    Call it with the frame index ``k = 0, 1, 2, ...`` in order (each call advances the
    regulators one frame period); it returns the frame's pressures, counts and truth.
    :meth:`setpoint` takes a host SETPOINT; :meth:`release` is the board's host-silence
    watchdog letting go.

    Parameters
    ----------
    config : GripperConfig or Config
        A gripper (:func:`gripper_config`) or a single actuator (one line, no prefixes).
    objects : sequence of GraspObject or None
        The object as each finger meets it, in the fingers' order (one for an actuator);
        None: a free finger (no object).
    rate_hz : float
        Frame rate [Hz].
    seed : int, optional
        Seed of the sensor hardware (shared by the fingers) and of the noise; None: 0.
    regulation : Regulation, optional
        The regulators' time constant and limit, and the scenario's closing set-point and
        period; default ``Regulation()``.
    noise_counts : float
        Sensor noise [counts].
    adc_bits : int
        ADC resolution [bit].
    step_pa : float
        Node spacing of the pressure tables [Pa].
    **mismatch
        How every finger departs from its config: ``ei_error``, ``k0_error``,
        ``base_rotation_rad_per_rad``, ``hysteresis_pa``
        (:class:`~bendsense.sim.actuator.SimulatedActuator`, as ``bendsense simulate``'s
        model errors). The hysteresis acts frame by frame between a line's pressure
        reading and the pressure that bends its finger.

    Attributes
    ----------
    n_channels, n_lines : int
        Board channels (the highest mapped) and pressure lines.
    truth_fingers : list of str or None
        The fingers' names for the truth columns; None for a single actuator.
    regulation : Regulation
        How the lines are driven (as given).
    regulators : PressureRegulators
        The lines' regulators (replaced by :meth:`reset`).
    profile : object
        The scenario's set-point profile: ``profile(t_s)`` [Pa], ``close_pa``, ``period_s``.
    fingers : dict
        Name → :class:`~bendsense.sim.grasp.FingerGrasp`.
    """

    def __init__(self, config, objects, *, rate_hz: float, seed: int | None = 0, regulation: Regulation | None = None,
                 noise_counts: float = 1.5, adc_bits: int = 12, step_pa: float = 500.0, **mismatch):
        from bendsense.sim.actuator import SimulatedActuator
        from bendsense.sim.sensor import VirtualSensor

        seed = 0 if seed is None else seed
        if regulation is None:
            regulation = Regulation()
        elif not isinstance(regulation, Regulation):
            raise ConfigError(f"regulation: expected a Regulation, got {type(regulation).__name__}")
        self.regulation = regulation
        max_pressure_pa = regulation.max_pressure_pa
        single = not hasattr(config, "fingers")
        members = [(None, config, tuple(range(1, config.sensor.n_segments + 1)), 0)] if single else [
            (f.name, f.config, tuple(f.channels), int(f.pressure_line)) for f in config.fingers]
        objects = list(objects)
        if len(objects) != len(members):
            raise ConfigError(f"objects: expected one per finger ({len(members)}), got {len(objects)}")
        self.truth_fingers = None if single else [m[0] for m in members]
        self.n_channels = max(max(m[2]) for m in members)
        self.n_lines = max(m[3] for m in members) + 1
        self.single = single
        self.rate_hz = float(rate_hz)
        profile = self.profile = _Profile(float(regulation.close_pa), float(regulation.period_s))
        self._seed = seed
        self._regulator_options = {"tau_s": regulation.tau_s, "max_pressure_pa": max_pressure_pa, "profile": profile}
        self.reset()  # checks the regulators' options before the slow tables
        self._fingers = []
        sensors = {}
        for (name, cfg, channels, line), obj in zip(members, objects, strict=True):
            key = id(cfg.sensor)
            if key not in sensors:  # one hardware per sensor design: the seed's
                sensors[key] = VirtualSensor.from_config(cfg, noise_counts=noise_counts, adc_bits=adc_bits, seed=seed)
            sim = SimulatedActuator.from_config(cfg, sensor=sensors[key], **mismatch)
            grasp = FingerGrasp(sim, obj, max_pressure_pa=max_pressure_pa, step_pa=step_pa)
            prefix = "" if name is None else f"{name}_"
            keys = (f"{prefix}fx_n", f"{prefix}fy_n", f"{prefix}contact_s_m")
            self._fingers.append(_Finger(name, np.asarray(channels) - 1, line, grasp, keys))
        self.fingers = {f.name: f.grasp for f in self._fingers}
        self.hysteresis_pa = self._fingers[0].grasp.actuator.hysteresis_pa
        self.noise_counts = float(noise_counts)
        self._full_scale = 2 ** int(adc_bits) - 1
        self._line_keys = [("setpoint_pa", "pressure_pa")] if single else [
            (f"line{k}_setpoint_pa", f"line{k}_pressure_pa") for k in range(self.n_lines)]

    def reset(self, initial_pa: float = 0.0) -> None:
        """Start over: regulators at ``initial_pa`` following the scenario, the noise stream from its seed.

        The tables are kept; the fingers' hysteresis starts at ``initial_pa`` too.

        Parameters
        ----------
        initial_pa : float
            Every line's pressure at the start [Pa].
        """
        self.regulators = PressureRegulators(self.n_lines, self.rate_hz, initial_pa=initial_pa,
                                             **self._regulator_options)
        self._effective = self.regulators.pressure_pa.copy()  # the pressure that bends each line's finger
        self._rng = np.random.default_rng(np.random.SeedSequence(self._seed, spawn_key=(_NOISE_KEY,)))

    def setpoint(self, line: int, pressure_pa: float) -> bool:
        """Take a SETPOINT: the line's regulator follows ``pressure_pa`` from the next frame on.

        Parameters
        ----------
        line : int
            0-based pressure line.
        pressure_pa : float
            Set-point [Pa]; clipped to ``[0, max_pressure_pa]``.

        Returns
        -------
        bool
            False when the board has no such line.
        """
        return self.regulators.set(int(line), float(pressure_pa))

    def release(self) -> None:
        """Set-point 0 on every line from the next frame on, held until the host sets the line again.

        :class:`~bendsense.device.simdevice.SimulatedDevice` calls it when the host that
        drove a line falls silent (its watchdog;
        :meth:`~bendsense.sim.regulator.PressureRegulators.release`).
        """
        self.regulators.release()

    def __call__(self, k: int):
        """Frame ``k``: ``(pressure, counts, truth)``.

        ``pressure`` is a float for a single actuator and a tuple (one per line) for a
        gripper; ``counts`` an int array of ``n_channels``; ``truth`` a dict keyed by the
        truth file's columns (:func:`bendsense.sim.truth.truth_columns`).
        """
        p = self.regulators.step(k / self.rate_hz)
        if self.hysteresis_pa:
            self._effective = play_operator(p[None], self.hysteresis_pa, self._effective)[0]
        bending = self._effective if self.hysteresis_pa else p
        values = np.zeros(self.n_channels)
        truth = {}
        for f in self._fingers:
            fx, fy, values[f.index] = f.grasp.lookup_one(bending[f.line])
            truth[f.keys[0]], truth[f.keys[1]] = fx + 0.0, fy + 0.0  # no -0.0
            truth[f.keys[2]] = f.grasp.contact_s_m
        for (set_key, p_key), sp, pp in zip(self._line_keys, self.regulators.setpoint_pa, p, strict=True):
            truth[set_key], truth[p_key] = float(sp), float(pp)
        if self.noise_counts > 0:
            values += self._rng.normal(0.0, self.noise_counts, values.shape)
        counts = np.clip(np.rint(values), 0, self._full_scale).astype(np.int64)
        pressure = float(p[0]) if self.single else tuple(float(x) for x in p)
        return pressure, counts, truth


class _Profile:
    """The closing profile (:func:`~bendsense.sim.regulator.closing_profile`) with fixed options."""

    def __init__(self, close_pa, period_s):
        self.close_pa, self.period_s = close_pa, period_s

    def __call__(self, t_s):
        return _closing(t_s, self.close_pa, self.period_s)


class ScriptedBoard:
    """The single actuator's scripted scenario until the host drives its line; then its regulator.

    The board of ``sim-device`` without ``--object`` or ``--fingers``: frame by frame the
    ``script`` (the time-varying scenario, :func:`bendsense.device.simdevice.default_source`)
    until the first SETPOINT on line 0 (or the watchdog's :meth:`release`); from then on
    ``board``, a :class:`GraspBoard` of the same actuator free (no object, no scripted
    touches), whose regulator starts at the script's last pressure and follows the host.
    A host that sends no SETPOINT gets the scripted scenario frame for frame.

    Parameters
    ----------
    script : iterable
        Of ``(pressure_pa, counts)`` or ``(pressure_pa, counts, truth)``.
    board : GraspBoard
        The free single actuator (``objects=[None]``) on the script's sensor hardware.

    Attributes
    ----------
    scripted : bool
        The script still runs (no SETPOINT yet).
    """

    def __init__(self, script, board: GraspBoard):
        if not board.single:
            raise ConfigError("board: expected the single actuator's GraspBoard, got a gripper's")
        self.script, self.board = iter(script), board
        self.scripted = True
        self._pressure = 0.0

    def setpoint(self, line: int, pressure_pa: float) -> bool:
        """Take a SETPOINT (:meth:`GraspBoard.setpoint`); the first on line 0 ends the script.

        Parameters
        ----------
        line : int
            0-based pressure line (the board has line 0 only).
        pressure_pa : float
            Set-point [Pa].

        Returns
        -------
        bool
            False when the board has no such line or the value is not finite.
        """
        if line != 0 or not math.isfinite(pressure_pa):
            return False
        self._take_over()
        return self.board.setpoint(line, pressure_pa)

    def release(self) -> None:
        """Set-point 0 on the line (the board's watchdog, :meth:`GraspBoard.release`); ends the script."""
        self._take_over()
        self.board.release()

    def _take_over(self) -> None:
        if self.scripted:
            self.board.reset(self._pressure)
            self.scripted = False

    def __call__(self, k: int):
        """Frame ``k``: the script's next frame, or the board's (:meth:`GraspBoard.__call__`)."""
        if not self.scripted:
            return self.board(k)
        values = next(self.script)
        self._pressure = float(values[0])
        return values
