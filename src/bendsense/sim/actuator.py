"""The simulated actuator: pressure and tip force → true shape → strip shifts → ADC counts.

The "true" actuator is the model of the paper run forwards: the free-bending model gives
the natural curvature ``K0(P)`` (paper eq. 8–12), the stiffness model ``EI(P)`` (eq. 15),
the config the gravity load ``w``, and the curved-beam solver the shape under a tip force
(eq. 13–17, DESIGN section 2). The beam is solved over the actuator length ``L`` and its
shape sampled on ``[0, L_sensor]``, since the sensor is glued under the actuator from the
base and is a little shorter (paper: 132 mm vs 134 mm). The sensor then sees the shifts
``S_i = d (φ(L_i) − φ(0))`` (:func:`~bendsense.sim.sensor.shifts_from_shape`) and
reports ADC counts (:class:`~bendsense.sim.sensor.VirtualSensor`).

Evaluating bendsense against the very models it uses would be circular, so the true
actuator can deviate from them. Every deviation is off by default:

``ei_error``
    Relative error of the true flexural rigidity: ``EI_true = (1 + ei_error) EI(P)``.
``k0_error``
    Relative error of the true natural curvature: ``K0_true = (1 + k0_error) K0(P)``.
``base_rotation_rad_per_rad``
    The base tangent turns by ``β θ_true(P)`` toward ``+x`` (``θ_true = K0_true L``), the
    deformation of the clamped cross-section under large bending that the paper blames
    for its errors at 0.3 N (section V-C). The strips are pinned at the base, so the
    sensor does not see it; a reconstruction that assumes ``φ(0) = 0`` does.
``hysteresis_pa``
    Play (backlash) of width ``h`` between the pressure reading and the pressure that
    bends the actuator (:func:`play_operator`); it only acts along a time series.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from bendsense.config import Config
from bendsense.errors import ConfigError
from bendsense.sim.sensor import VirtualSensor, shifts_from_shape

__all__ = ["SimulatedActuator", "ActuatorFrames", "play_operator", "MODEL_ERRORS"]

#: The model errors of the true actuator (module docstring): its keywords, all 0 by default.
MODEL_ERRORS = ("ei_error", "k0_error", "base_rotation_rad_per_rad", "hysteresis_pa")
#: Points of the default true-shape grid over the sensor length.
DEFAULT_SHAPE_POINTS = 133


def play_operator(pressure_pa, width_pa: float, initial_pa: float | None = None) -> np.ndarray:
    """Backlash (play) hysteresis along the first axis of a pressure time series.

    ``y_k = min(max(y_{k−1}, x_k − h/2), x_k + h/2)``: the output follows the input only
    after the input has moved by more than the play ``h`` against the last direction.

    Parameters
    ----------
    pressure_pa : array_like, shape (frames, ...)
        Input pressures x_k in time order [Pa].
    width_pa : float
        Play h >= 0 [Pa]; 0 returns the input.
    initial_pa : float or array_like, optional
        Output before the first frame, y_{−1} [Pa]; default the first input.

    Returns
    -------
    ndarray, same shape as ``pressure_pa``
        Output pressures y_k [Pa].
    """
    x = np.asarray(pressure_pa, dtype=float)
    h = float(width_pa)
    if not (math.isfinite(h) and h >= 0):
        raise ConfigError(f"hysteresis_pa: must be >= 0, got {width_pa!r}")
    if h == 0 or x.ndim == 0 or x.shape[0] == 0:
        return x.copy()
    y = np.empty_like(x)
    prev = x[0] if initial_pa is None else np.broadcast_to(np.asarray(initial_pa, dtype=float), x.shape[1:])
    half = 0.5 * h
    # inherently sequential; cheap scalar work per frame
    for k in range(x.shape[0]):
        prev = np.minimum(np.maximum(prev, x[k] - half), x[k] + half)
        y[k] = prev
    return y


def contact_number(contact_s_m, length_m: float, alternatives: str = "") -> float:
    """A contact location given as a number: finite, in ``(0, L]`` [m]; else a ConfigError naming it.

    Parameters
    ----------
    contact_s_m : object
        The location given [m].
    length_m : float
        The actuator length L [m].
    alternatives : str
        What else the caller accepts, for the message (``" or 'along-body'"``).
    """
    ok = not isinstance(contact_s_m, bool) and isinstance(contact_s_m, (int, float, np.floating, np.integer))
    if not ok or not (math.isfinite(contact_s_m) and 0.0 < contact_s_m <= length_m):
        raise ConfigError(f"contact_s_m: must be a number in (0, L = {length_m:g} m]{alternatives}, "
                          f"got {contact_s_m!r}")
    return float(contact_s_m)


@dataclass(frozen=True, eq=False)
class ActuatorFrames:
    """True shapes and sensor readings of simulated frames, batched over leading axes ``...``.

    Attributes
    ----------
    pressure_pa : ndarray, shape (...)
        Pressure reading [Pa] (what the pressure sensor reports).
    effective_pressure_pa : ndarray, shape (...)
        Pressure that bends the actuator, after hysteresis [Pa].
    force_n : ndarray, shape (..., 2)
        Point force in the base frame [N], at the tip or at ``contact_s_m``.
    contact_s_m : float
        Arc length s_c where the force acts [m] (the actuator length L for a tip load).
    tip_curvature_per_m : ndarray, shape (...)
        True natural curvature K0 [1/m].
    ei_nm2 : ndarray, shape (...)
        True flexural rigidity EI [N·m²].
    base_angle_rad : ndarray, shape (...)
        True base tangent angle φ(0) [rad].
    s_m : ndarray, shape (M,)
        Arc lengths of the true shape on ``[0, L_sensor]`` [m].
    angle_rad : ndarray, shape (..., M)
        True tangent angle φ(s) [rad].
    positions_m : ndarray, shape (..., M, 2)
        True points r(s) of the sensor line in the base frame [m].
    tip_position_m : ndarray, shape (..., 2)
        True actuator tip r(L) [m] (``L`` the actuator length).
    tip_angle_rad : ndarray, shape (...)
        True actuator tip angle φ(L) [rad].
    shifts_m : ndarray, shape (..., N)
        Strip shifts S_i [m].
    curvature_per_m : ndarray, shape (..., N)
        Mean true curvature of each sensor segment, (φ(L_i) − φ(L_{i−1})) / l_i [1/m]:
        what an ideal sensor would report (paper eq. 3).
    counts : ndarray of int, shape (..., N)
        ADC counts (with noise unless the sensor has none).
    saturated : ndarray of bool, shape (..., N)
        Clipped ADC values.
    valid : ndarray of bool, shape (...)
        The beam solve converged to a stable equilibrium; other frames are not physical.
    """

    pressure_pa: np.ndarray
    effective_pressure_pa: np.ndarray
    force_n: np.ndarray
    tip_curvature_per_m: np.ndarray
    ei_nm2: np.ndarray
    base_angle_rad: np.ndarray
    s_m: np.ndarray
    angle_rad: np.ndarray
    positions_m: np.ndarray
    tip_position_m: np.ndarray
    tip_angle_rad: np.ndarray
    shifts_m: np.ndarray
    curvature_per_m: np.ndarray
    counts: np.ndarray
    saturated: np.ndarray
    valid: np.ndarray
    contact_s_m: float = math.nan

    @property
    def n_invalid(self) -> int:
        """Number of frames whose beam solve failed."""
        return int(np.size(self.valid) - np.count_nonzero(self.valid))

    def select(self, index) -> ActuatorFrames:
        """Pick the frames given by ``index`` along the first axis (slice, mask or indices).

        Parameters
        ----------
        index : slice, array_like of bool or of int
            The frames to keep.
        """
        whole = ("s_m", "contact_s_m")
        values = {name: getattr(self, name)[index] for name in self.__dataclass_fields__ if name not in whole}
        return ActuatorFrames(s_m=self.s_m, contact_s_m=self.contact_s_m, **values)


@dataclass(frozen=True, kw_only=True, eq=False)
class SimulatedActuator:
    """The true actuator with its sensor: (pressure, tip force) → shape → ADC counts.

    Build with :meth:`from_config`. Every method is vectorised over leading batch axes
    (one batched beam solve, no loop over frames).

    Attributes
    ----------
    config : Config
        The configuration whose models define the true actuator.
    sensor : VirtualSensor
        The sensor hardware (offsets, gains, noise stream).
    ei_error, k0_error : float
        Relative deviations of the true EI and K0 from the config's models.
    base_rotation_rad_per_rad : float
        Base-angle deviation per radian of true free bending angle [rad/rad].
    hysteresis_pa : float
        Play of the pressure hysteresis [Pa] (time series only).
    n_points : int
        Points of the true shape on ``[0, L_sensor]``.
    """

    config: Config
    sensor: VirtualSensor
    ei_error: float = 0.0
    k0_error: float = 0.0
    base_rotation_rad_per_rad: float = 0.0
    hysteresis_pa: float = 0.0
    n_points: int = DEFAULT_SHAPE_POINTS
    _bending: object = field(init=False, repr=False)
    _s_beam: np.ndarray = field(init=False, repr=False)

    def __post_init__(self):
        for name in MODEL_ERRORS:
            value = getattr(self, name)
            low = {"ei_error": -1.0, "k0_error": -1.0, "hysteresis_pa": 0.0}.get(name)
            ok = not isinstance(value, bool) and isinstance(value, (int, float)) and math.isfinite(value)
            if not ok or (low is not None and (value < low or (low < 0 and value == low))):
                bound = "" if low is None else (f" > {low:g}" if low < 0 else " >= 0")
                raise ConfigError(f"{name}: must be a finite number{bound}, got {value!r}")
            object.__setattr__(self, name, float(value))
        if isinstance(self.n_points, bool) or not isinstance(self.n_points, int) or self.n_points < 2:
            raise ConfigError(f"n_points: must be an integer >= 2, got {self.n_points!r}")
        if self.sensor.n_channels != self.config.sensor.n_segments:
            raise ConfigError(
                f"sensor: expected {self.config.sensor.n_segments} channels to match the config, "
                f"got {self.sensor.n_channels}"
            )
        length = self.config.actuator.length_m
        sensor_length = float(np.sum(self.sensor.lengths_m))
        if sensor_length > length * (1 + 1e-12):
            raise ConfigError(
                f"sensor.segment_lengths_m: the sensor ({sensor_length:.6g} m) is longer than "
                f"actuator.length_m ({length:.6g} m)"
            )
        s = np.linspace(0.0, min(sensor_length, length), self.n_points)
        # the actuator tip rides along as the last output point
        s_beam = np.append(s, length) if length > s[-1] * (1 + 1e-12) else s
        from bendsense.mechanics.actuator import FreeBendingModel

        object.__setattr__(self, "_bending", FreeBendingModel.from_config(self.config))
        object.__setattr__(self, "_s_beam", s_beam)

    @classmethod
    def from_config(
        cls,
        config: Config | None = None,
        *,
        sensor: VirtualSensor | None = None,
        noise_counts: float = 1.5,
        seed: int | None = 0,
        ei_error: float = 0.0,
        k0_error: float = 0.0,
        base_rotation_rad_per_rad: float = 0.0,
        hysteresis_pa: float = 0.0,
        n_points: int = DEFAULT_SHAPE_POINTS,
    ) -> SimulatedActuator:
        """Build the simulated actuator of ``config`` (default: the paper's prototype).

        Parameters
        ----------
        config : Config, optional
            Actuator, material, stiffness, gravity and sensor.
        sensor : VirtualSensor, optional
            Sensor hardware; default ``VirtualSensor.from_config(config,
            noise_counts=noise_counts, seed=seed)``.
        noise_counts : float
            Sensor noise standard deviation [counts] (when ``sensor`` is not given).
        seed : int or None
            Seed of the sensor's offsets and noise (when ``sensor`` is not given).
        ei_error, k0_error, base_rotation_rad_per_rad, hysteresis_pa : float
            Model mismatch (module docstring); all 0 by default.
        n_points : int
            Points of the true shape on ``[0, L_sensor]``.
        """
        if config is None:
            from bendsense.config import load_config

            config = load_config()
        if sensor is None:
            sensor = VirtualSensor.from_config(config, noise_counts=noise_counts, seed=seed)
        return cls(
            config=config,
            sensor=sensor,
            ei_error=ei_error,
            k0_error=k0_error,
            base_rotation_rad_per_rad=base_rotation_rad_per_rad,
            hysteresis_pa=hysteresis_pa,
            n_points=n_points,
        )

    @property
    def s_m(self) -> np.ndarray:
        """Arc lengths of the true shape on ``[0, L_sensor]`` [m], shape (M,)."""
        return self._s_beam[: self.n_points]

    def tip_curvature_per_m(self, pressure_pa) -> np.ndarray:
        """Return the true natural curvature K0_true(P) = (1 + k0_error) K0(P) [1/m].

        Parameters
        ----------
        pressure_pa : float or array_like
            Actuation pressure P [Pa].
        """
        return (1.0 + self.k0_error) * self._bending.tip_curvature_per_m(np.asarray(pressure_pa, dtype=float))

    def ei_nm2(self, pressure_pa) -> np.ndarray:
        """Return the true flexural rigidity EI_true(P) = (1 + ei_error) EI(P) [N·m²].

        Parameters
        ----------
        pressure_pa : float or array_like
            Actuation pressure P [Pa].
        """
        return (1.0 + self.ei_error) * self.config.stiffness.ei_nm2(pressure_pa)

    def base_angle_rad(self, pressure_pa) -> np.ndarray:
        """Return the true base angle β θ_true(P) [rad], toward ``+x``.

        Parameters
        ----------
        pressure_pa : float or array_like
            Actuation pressure P [Pa].
        """
        return self.base_rotation_rad_per_rad * self.tip_curvature_per_m(pressure_pa) * self.config.actuator.length_m

    def effective_pressure_pa(self, pressure_pa, initial_pa=None) -> np.ndarray:
        """Return the pressure that bends the actuator, for a time series of readings (first axis = time) [Pa].

        Parameters
        ----------
        pressure_pa : array_like, shape (frames, ...)
            Pressure readings, first axis time [Pa].
        initial_pa : float or array_like, optional
            The effective pressure before the first reading [Pa]; default the first reading.
        """
        return play_operator(pressure_pa, self.hysteresis_pa, initial_pa)

    def contact_location(self, contact_s_m) -> float | None:
        """Check a contact location: None (the tip) or a number in ``(0, L]`` [m]; return it as a float.

        Parameters
        ----------
        contact_s_m : float or None
            Arc length s_c of the point force [m].
        """
        return None if contact_s_m is None else contact_number(contact_s_m, self.config.actuator.length_m)

    def solve(self, pressure_pa, force_n=(0.0, 0.0), *, initial=None, sensitivities=False, contact_s_m=None,
              s_m=None):
        """Solve the true beam (over the actuator length) for the pressures acting on it.

        Parameters
        ----------
        pressure_pa : array_like, shape (...)
            Pressure acting on the actuator [Pa] (after any hysteresis).
        force_n : array_like, shape (..., 2)
            Point force in the base frame [N], at the tip or at ``contact_s_m``.
        initial : BeamSolution, optional
            Warm start.
        sensitivities : bool
            Also compute ∂φ/∂F and ∂r/∂F (and ∂φ/∂s_c, ∂r/∂s_c with a contact location).
        contact_s_m : float, optional
            Arc length s_c of the point force [m] (:meth:`contact_location`); None: the tip.
            Beyond s_c the actuator bends freely under its weight.
        s_m : array_like, shape (M,), optional
            Output arc lengths [m]; default the true-shape grid on ``[0, L_sensor]``
            followed by the tip ``L``.

        Returns
        -------
        bendsense.mechanics.beam.BeamSolution
            At ``s_m``: by default the points on ``[0, L_sensor]`` followed by the tip ``L``.
        """
        from bendsense.mechanics.beam import solve_beam

        p = np.asarray(pressure_pa, dtype=float)
        sc = self.contact_location(contact_s_m)
        extra = {} if sc is None else {"contact_s_m": sc}
        return solve_beam(
            self.config.actuator.length_m,
            self.ei_nm2(p),
            self.tip_curvature_per_m(p),
            force_n,
            self.config.weight_per_length_n_per_m,
            self.base_angle_rad(p),
            s_m=self._s_beam if s_m is None else s_m,
            warn=False,
            initial=initial,
            sensitivities=sensitivities,
            **extra,
        )

    def solve_contact(self, pressure_pa, contact_n, force_n=(0.0, 0.0), *, contact_s_m=None, ramp_steps=4,
                      tol_rad=1e-10, max_iter=20, s_m=None):
        """Solve for a contact force normal to the true loaded tangent at the contact point (paper eq. 21).

        The contact force ``F_c = f_c (−cos φ_c, sin φ_c)`` is normal to the tangent
        ``t = (sin φ_c, cos φ_c)`` at the contact point ``s_c`` (the tip by default) and
        pushes against the bending (toward ``−x`` for a straight finger, ``+y`` for a
        horizontal one: the paper's fingertip, Fig. 7(d); an object touching the finger's
        body with ``contact_s_m``: a frictionless contact). Since ``φ_c`` must equal the
        angle of the loaded beam at ``s_c``, Newton's method solves ``φ(s_c; F_fixed +
        F_c(φ_c)) = φ_c`` per frame, with ∂φ(s_c)/∂F from the beam solver. ``f_c`` is
        ramped up from 0 in ``ramp_steps`` steps (quasi-static loading), so the answer is
        the equilibrium connected to the unloaded shape.

        Parameters
        ----------
        pressure_pa : array_like, shape (...)
            Pressure acting on the actuator [Pa].
        contact_n : array_like, shape (...)
            Contact force magnitude f_c >= 0 [N].
        force_n : array_like, shape (..., 2)
            Further, fixed force at the same point [N].
        contact_s_m : float, optional
            Arc length s_c of the contact [m] (:meth:`contact_location`); None: the tip.
        ramp_steps : int
            Load steps of the ramp of f_c.
        tol_rad : float
            Newton stops when |φ(s_c) − φ_c| < ``tol_rad`` [rad].
        max_iter : int
            Newton iterations per load step.
        s_m : array_like, shape (M,), optional
            Output arc lengths of the solution [m]; default the true-shape grid on
            ``[0, L_sensor]`` followed by the tip ``L`` (as :meth:`solve`).

        Returns
        -------
        force_n : ndarray, shape (..., 2)
            Total force F_fixed + F_c at s_c [N].
        solution : BeamSolution
            The beam under that force; ``success`` is also false where Newton did not
            converge.
        """
        from bendsense.mechanics.beam import BeamSolution

        p = np.asarray(pressure_pa, dtype=float)
        fc = np.asarray(contact_n, dtype=float)
        fixed = np.asarray(force_n, dtype=float)
        sc = self.contact_location(contact_s_m)
        if not np.all(fc >= 0):
            raise ConfigError(f"contact_n: must be >= 0, got {contact_n!r}")
        shape = np.broadcast_shapes(p.shape, fc.shape, fixed.shape[:-1])
        B = math.prod(shape)
        p = np.broadcast_to(p, shape).reshape(B)
        fc = np.broadcast_to(fc, shape).reshape(B)
        fixed = np.broadcast_to(fixed, (*shape, 2)).reshape(B, 2)
        # the contact point rides along as one more output point (the last)
        grid = np.append(self._s_beam if s_m is None else np.asarray(s_m, dtype=float),
                         self.config.actuator.length_m if sc is None else sc)

        def solve(pp, f, **kw):
            return self.solve(pp, f, contact_s_m=sc, s_m=grid, **kw)

        sol = solve(p, fixed)
        angle = np.array(sol.angle_rad)
        positions = np.array(sol.positions_m)
        tip = np.array(sol.tip_position_m)
        tip_angle = np.array(sol.tip_angle_rad)
        phi = angle[:, -1].copy()
        state = np.array(sol.state)
        ok = np.array(sol.success)
        force = fixed.copy()
        # only frames with a contact force need the iteration
        active = np.flatnonzero(ok & (fc > 0))
        for step in range(1, ramp_steps + 1):
            if active.size == 0:
                break
            fraction = step / ramp_steps
            tol = tol_rad if step == ramp_steps else max(tol_rad, 1e-6)
            todo = active
            for _ in range(max_iter):
                mag = fraction * fc[todo]
                c, s_ = np.cos(phi[todo]), np.sin(phi[todo])
                f = fixed[todo] + mag[:, None] * np.stack([-c, s_], axis=-1)
                sub = solve(p[todo], f, initial=state[todo], sensitivities=True)
                residual = sub.angle_rad[:, -1] - phi[todo]
                done = np.abs(residual) < tol
                angle[todo], positions[todo], tip[todo] = sub.angle_rad, sub.positions_m, sub.tip_position_m
                tip_angle[todo], state[todo], force[todo] = sub.tip_angle_rad, sub.state, f
                lost = ~np.asarray(sub.success)
                ok[todo[lost]] = False
                slope = np.sum(sub.dangle_dforce[:, -1, :] * (mag[:, None] * np.stack([s_, c], axis=-1)), axis=-1)
                phi[todo] = np.where(done, sub.angle_rad[:, -1], phi[todo] - residual / (slope - 1.0))
                todo = todo[~done & ~lost]
                if todo.size == 0:
                    break
            ok[todo] = False
            active = active[ok[active]]
        where = "the tip" if sc is None else f"s_c = {sc:g} m"
        message = np.where(ok, "converged", f"contact: no stable equilibrium normal to {where} found").reshape(shape)
        solution = BeamSolution(
            s_m=sol.s_m[:-1],
            angle_rad=angle[:, :-1].reshape(*shape, -1),
            positions_m=positions[:, :-1].reshape(*shape, -1, 2),
            tip_position_m=tip.reshape(*shape, 2),
            tip_angle_rad=tip_angle.reshape(shape),
            success=ok.reshape(shape),
            message=message if shape else str(message),
            iterations=np.zeros(shape, dtype=int),
            method="fast",
            state=state.reshape(*shape, -1),
        )
        return force.reshape(*shape, 2), solution

    def frames(
        self,
        pressure_pa,
        force_n=(0.0, 0.0),
        *,
        contact_n=None,
        contact_s_m=None,
        time_series: bool = False,
        initial_pa=None,
        noise: bool = True,
        rng: np.random.Generator | None = None,
        solution=None,
    ) -> ActuatorFrames:
        """Simulate frames: true shape, shifts and ADC counts.

        Parameters
        ----------
        pressure_pa : array_like, shape (...)
            Pressure readings [Pa].
        force_n : array_like, shape (..., 2)
            Point force in the base frame [N], at the tip or at ``contact_s_m``;
            broadcasts against ``pressure_pa``.
        contact_n : array_like, shape (...), optional
            Magnitude of a contact force normal to the true loaded tangent at the
            contact point, added to ``force_n`` [N] (:meth:`solve_contact`);
            ``frames.force_n`` is the total.
        contact_s_m : float, optional
            Arc length s_c where the force acts [m]; None: the tip. Beyond s_c the
            actuator bends freely under its weight.
        time_series : bool
            The first axis is time: apply the pressure hysteresis along it.
        initial_pa : float, optional
            Hysteresis state before the first frame [Pa] (``time_series`` only).
        noise : bool
            Add the sensor's noise; False gives the quantised noise-free counts.
        rng : numpy.random.Generator, optional
            Noise source; default the sensor's own stream.
        solution : BeamSolution, optional
            A solution already computed by :meth:`solve` for these frames (skips the solve).

        Returns
        -------
        ActuatorFrames
        """
        p = np.asarray(pressure_pa, dtype=float)
        F = np.asarray(force_n, dtype=float)
        if F.ndim == 0 or F.shape[-1] != 2:
            raise ConfigError(f"force_n: expected shape (..., 2), got {F.shape}")
        fc = None if contact_n is None else np.asarray(contact_n, dtype=float)
        shape = np.broadcast_shapes(p.shape, F.shape[:-1], () if fc is None else fc.shape)
        p = np.broadcast_to(p, shape)
        F = np.broadcast_to(F, (*shape, 2))
        p_eff = self.effective_pressure_pa(p, initial_pa) if time_series else p.copy()
        if solution is not None:
            sol = solution
        elif fc is None:
            sol = self.solve(p_eff, F, contact_s_m=contact_s_m)
        else:
            F, sol = self.solve_contact(p_eff, fc, F, contact_s_m=contact_s_m)
        M = self.n_points
        angle = sol.angle_rad[..., :M]
        lengths = np.asarray(self.sensor.lengths_m, dtype=float)
        shifts = shifts_from_shape(self.s_m, angle, lengths, self.sensor.strip_gap_m)
        if noise:
            reading = self.sensor.measure(shifts, rng=rng)
        else:
            reading = self.sensor.quantize(self.sensor.signal(shifts))
        return ActuatorFrames(
            pressure_pa=p.copy(),
            effective_pressure_pa=p_eff,
            force_n=F.copy(),
            tip_curvature_per_m=np.broadcast_to(self.tip_curvature_per_m(p_eff), shape).copy(),
            ei_nm2=np.broadcast_to(self.ei_nm2(p_eff), shape).copy(),
            base_angle_rad=np.broadcast_to(self.base_angle_rad(p_eff), shape).copy(),
            s_m=self.s_m.copy(),
            angle_rad=angle,
            positions_m=sol.positions_m[..., :M, :],
            tip_position_m=sol.tip_position_m,
            tip_angle_rad=sol.tip_angle_rad,
            shifts_m=shifts,
            curvature_per_m=np.diff(shifts, axis=-1, prepend=0.0) / (self.sensor.strip_gap_m * lengths),
            counts=reading.counts,
            saturated=reading.saturated,
            valid=np.broadcast_to(sol.success, shape).copy(),
            contact_s_m=self.config.actuator.length_m if contact_s_m is None else float(contact_s_m),
        )
