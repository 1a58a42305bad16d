"""Commands of the sim area: ``simulate`` writes the paper's experiments as simulated recordings.

Also the options of ``sim-device``'s simulated grasp (``--fingers``, ``--object...``, the
regulators) and the board they build (:func:`grasp_board`).
"""

from __future__ import annotations

import click

from bendsense import output
from bendsense.cli._common import (
    SEED,
    ContactLocation,
    Directory,
    Finite,
    InterspersedCommand,
    PressureKpa,
    Relative,
    config_option,
    overwrite_option,
    say,
    step_io,
)

# kept in sync with bendsense.sim.scenarios.SCENARIOS (imported lazily for a fast --help)
_SCENARIOS = ("calibration", "validation", "tip-loads", "contact", "time-varying", "free-sweep", "all", "gripper")


class _Numbers(Finite):
    """One number or a comma-separated list of them (one per finger), each checked as :class:`Finite`."""

    name = "number[,number...]"

    def convert(self, value, param, ctx):
        """Parse and check each value."""
        if isinstance(value, tuple):
            return value
        return tuple(super(_Numbers, self).convert(v.strip(), param, ctx) for v in str(value).split(","))


_MODEL_ERROR_OPTIONS = [
    click.option("--ei-error", type=Relative(), help="Model mismatch: relative error of the true EI."),
    click.option("--k0-error", type=Relative(), help="Model mismatch: relative error of the true K0."),
    click.option("--base-rotation", type=Relative(),
                 help="Model mismatch: base rotation per radian of bending [rad/rad]."),
    click.option("--hysteresis-kpa", type=PressureKpa(min=0), help="Model mismatch: pressure play [kPa]."),
]


def _decorated(command, options):
    """``command`` with the click ``options`` added, in their order in ``--help``."""
    for option in reversed(options):
        command = option(command)
    return command


noise_option = click.option("--noise-counts", type=Finite(min=0), help="Sensor noise std [counts] (default 1.5).")
"""``--noise-counts`` of ``simulate`` and ``sim-device``: the virtual sensor's noise."""


def model_error_options(command):
    """Add the model-error options (``--ei-error``, ``--k0-error``, ``--base-rotation``, ``--hysteresis-kpa``).

    ``simulate`` and ``sim-device`` take them: the simulated actuator departs from the
    config by these (:class:`bendsense.sim.actuator.SimulatedActuator`).

    Parameters
    ----------
    command : callable
        The command function being decorated.
    """
    return _decorated(command, _MODEL_ERROR_OPTIONS)


def model_errors(ei_error=None, k0_error=None, base_rotation=None, hysteresis_kpa=None) -> dict:
    """The model-error options as :class:`~bendsense.sim.actuator.SimulatedActuator`'s keywords (those given).

    Parameters
    ----------
    ei_error, k0_error, base_rotation, hysteresis_kpa : float or None
        The options' values (None: not given).
    """
    values = {"ei_error": ei_error, "k0_error": k0_error, "base_rotation_rad_per_rad": base_rotation,
              "hysteresis_pa": None if hysteresis_kpa is None else hysteresis_kpa * 1e3}
    return {k: v for k, v in values.items() if v is not None}


@click.command("simulate", cls=InterspersedCommand)
@click.argument("scenario", metavar="SCENARIO", type=click.Choice(_SCENARIOS))
@click.option(
    "-o",
    "--output",
    "out_dir",
    required=True,
    type=Directory(),
    help="Directory to write (created; with 'all', one subdirectory per scenario).",
)
@click.option("--seed", type=SEED, default=0, show_default=True, help="Seed of the sensor hardware and the noise.")
@config_option
@noise_option
@click.option("--frames", type=click.IntRange(min=1),
              help="Frames per strip or configuration (default 50 / 5; free-sweep: frames of the sweep, "
                   "default 200). A scenario is simulated in memory, "
                   "one recording at a time (tip-loads: 44 configurations, ~10 kB a frame): a number whose "
                   "frames would not fit the free memory is refused before any work.")
@model_error_options
@click.option("--max-pressure-kpa", type=PressureKpa(min=0),
              help="free-sweep: peak pressure [kPa] (default 120); gripper: the regulators' limit (default 120).")
@click.option("--contact-n", type=Finite(min=0),
              help="free-sweep: a contact force [N] over the middle fifth of the way down (default 0); "
                   "time-varying: the contact force while on (default 0.15).")
@click.option("--contact-s-m", "contact_s_m", type=ContactLocation(),
              help="contact, time-varying: the contact force acts at this arc length s_c [m] along the body "
                   "(0 < s_c <= L), normal to the loaded tangent there; truth column contact_s_m. time-varying "
                   "also takes 'along-body': each touch lands somewhere else along the body.")
@click.option("--rate", "rate_hz", type=Finite(min=0, min_open=True),
              help="Frame rate [Hz] of the recordings (default 35; time-varying 100; gripper 200).")
@click.option("--seconds", type=Finite(min=0, min_open=True), help="gripper: length of the session [s] (default 8).")
@click.option("--fingers", type=click.IntRange(1, 4), help="gripper: fingers K (default 3).")
@click.option("--object", "object_kind", type=click.Choice(["rigid", "compliant"]),
              help="gripper: the object the fingers press (default rigid).")
@click.option("--object-stiffness", type=Finite(min=0, min_open=True),
              help="gripper, compliant object: contact stiffness [N/m] (default 20).")
@click.option("--object-s-m", type=_Numbers(min=0, min_open=True),
              help="gripper: where the object touches each finger [m], one value or one per finger.")
@click.option("--object-touch-kpa", type=_Numbers(min=0),
              help="gripper: the pressure at which each free finger reaches the object [kPa].")
@click.option("--close-kpa", type=PressureKpa(min=0), help="gripper: the closing set-point [kPa] (default 70).")
@click.option("--tau-ms", type=Finite(min=0, min_open=True),
              help="gripper: the regulators' time constant [ms] (default 25).")
@overwrite_option
def simulate(
    scenario,
    out_dir,
    seed,
    config_path,
    noise_counts,
    frames,
    ei_error,
    k0_error,
    base_rotation,
    hysteresis_kpa,
    max_pressure_kpa,
    contact_n,
    contact_s_m,
    rate_hz,
    overwrite,
    seconds,
    **grasp,
):
    """Write SCENARIO as simulated session CSVs with ground-truth columns.

    SCENARIO is one of the paper's experiments: calibration (flat + strips, with a
    manifest for 'bendsense calibrate'), validation (strips of known curvature),
    tip-loads (20-120 kPa x 0-0.3 N), contact (12 random normal contact forces, at the
    tip or, with --contact-s-m, along the body),
    time-varying (10 s at 100 Hz), free-sweep (a free pressure ramp 0 -> max -> 0, for
    'bendsense identify free-bending --session'), or all.

    gripper writes the simulated gripper of 'sim-device --fingers K' (default 3):
    gripper.yaml (its config), calibration.yaml (fitted from the simulated calibration
    recordings in calibration/, for every finger) and session.csv (the board closing
    on the object, with each finger's true force and contact and each line's set-point).
    """
    if scenario == "gripper" or seconds is not None or any(v is not None for v in grasp.values()):
        return _gripper_step(click.get_current_context().params, grasp)
    options = {
        "noise_counts": noise_counts,
        **model_errors(ei_error, k0_error, base_rotation, hysteresis_kpa),
        "pressure_max_pa": None if max_pressure_kpa is None else max_pressure_kpa * 1e3,
        "contact_n": contact_n,
        "contact_s_m": contact_s_m,
        "rate_hz": rate_hz,
    }
    for flag, value, allowed in (("--max-pressure-kpa", max_pressure_kpa, ("free-sweep", "all")),
                                 ("--contact-n", contact_n, ("free-sweep", "time-varying", "all")),
                                 ("--contact-s-m", contact_s_m, ("contact", "time-varying", "all"))):
        if value is not None and scenario not in allowed:
            raise click.BadParameter(f"applies to {', '.join(allowed[:-1])} only, not {scenario}", param_hint=flag)
    if contact_s_m == "along-body" and scenario != "time-varying":
        raise click.BadParameter(f"'along-body' applies to time-varying only, not {scenario}; give s_c [m]",
                                 param_hint="--contact-s-m")
    if frames is not None:
        if scenario in ("calibration", "validation", "all"):
            options["frames_per_strip"] = frames
        if scenario in ("tip-loads", "contact", "all"):
            options["frames_per_config"] = frames
        if scenario in ("free-sweep", "all"):
            options["n_frames"] = max(frames, 2)
    options = {k: v for k, v in options.items() if v is not None}
    if frames is not None or rate_hz is not None:
        from bendsense.sim.scenarios import check_memory

        # before any work (the group makes it one line)
        check_memory(scenario, options, field="--frames" if frames is not None else "--rate")

    def step(state):
        from bendsense.sim.scenarios import _simulate

        _, summaries = _simulate(scenario, out_dir, config_path, seed, overwrite=overwrite, **options)
        for name, summary in summaries.items():
            excluded = summary["excluded_frames"]
            note = f", {excluded} excluded (beam solve failed)" if excluded else ""
            say(
                f"{name}: wrote {len(summary['files'])} files, {summary['frames']} frames{note} to {summary['path']}"
            )
        return state

    return step_io(step, outputs=[output.directory(out_dir, overwrite=overwrite)], inputs=[config_path])


def _gripper_step(given: dict, grasp: dict):
    """``simulate gripper``: check its options (``given``: the command's, by name), then the step that writes it."""
    scenario, seconds, rate_hz = given["scenario"], given["seconds"], given["rate_hz"]
    out_dir, seed, overwrite, noise_counts = given["out_dir"], given["seed"], given["overwrite"], given["noise_counts"]
    if scenario != "gripper":
        flag = "--seconds" if seconds is not None else "--" + next(
            k for k, v in grasp.items() if v is not None).replace("_", "-").replace("object-kind", "object")
        raise click.BadParameter(f"applies to gripper only, not {scenario}", param_hint=flag)
    for name in ("config_path", "frames", "ei_error", "k0_error", "base_rotation", "hysteresis_kpa", "contact_n",
                 "contact_s_m"):
        if given[name] is not None:
            flag = "--config" if name == "config_path" else "--" + name.replace("_", "-")
            raise click.BadParameter("does not apply to gripper (its fingers are the paper's)", param_hint=flag)
    arguments = grasp_arguments({**grasp, "max_pressure_kpa": given["max_pressure_kpa"]}, gripper=True)
    fingers = arguments.pop("fingers")
    if noise_counts is not None:
        arguments["noise_counts"] = noise_counts
    if rate_hz is not None:
        arguments["rate_hz"] = rate_hz
    if seconds is not None:
        arguments["duration_s"] = seconds
    from bendsense.sim.gripping import DEFAULT_DURATION_S, DEFAULT_RATE_HZ, check_memory

    # before any work (the group makes it one line); the library's defaults where an option is not given
    rate = arguments.get("rate_hz", DEFAULT_RATE_HZ)
    check_memory(round(arguments.get("duration_s", DEFAULT_DURATION_S) * rate), fingers, rate,
                 "--seconds" if seconds is not None or rate_hz is None else "--rate")

    def step(state):
        from bendsense.sim.gripping import simulate_gripper

        summary = simulate_gripper(out_dir, fingers, seed=seed, overwrite=overwrite, **arguments)
        say(f"gripper: wrote {', '.join(summary['files'])} ({fingers} fingers, {summary['frames']} frames) to "
            f"{summary['path']}")
        return state

    return step_io(step, outputs=[output.directory(out_dir, overwrite=overwrite)])


_GRASP_OPTIONS = [
    click.option("--fingers", type=click.IntRange(1, 4),
                 help="Simulate a gripper of 1..4 paper fingers (thumb, index, middle, ring; finger i on channels "
                      "16 i + 1..16 i + 16 and pressure line i; 'bendsense.sim.gripper_config(K)'), closing on an "
                      "object; SAMPLE version 2, one pressure line per finger."),
    click.option("--object", "object_kind", type=click.Choice(["rigid", "compliant"]),
                 help="The object the fingers press (default rigid with --fingers); without --fingers the single "
                      "actuator presses it (version-1 frames, SETPOINT line 0)."),
    click.option("--object-stiffness", type=Finite(min=0, min_open=True),
                 help=f"Compliant object: contact stiffness [N/m] (default {20:g})."),
    click.option("--object-s-m", type=_Numbers(min=0, min_open=True),
                 help="Where the object touches each finger: s_c [m] along the body, one value or one per finger "
                      "(default 0.10, 0.11, 0.095, 0.12)."),
    click.option("--object-touch-kpa", type=_Numbers(min=0),
                 help="The pressure at which each free finger reaches the object [kPa], one value or one per "
                      "finger (default 40, 45, 35, 50)."),
    click.option("--close-kpa", type=PressureKpa(min=0),
                 help="The scenario's set-point while the fingers close (every 8 s: close over 2 s, hold 3 s, open "
                      "over 1 s, rest 2 s) [kPa] (default 70); a SETPOINT hands its line to the host for good."),
    click.option("--max-pressure-kpa", type=PressureKpa(min=0),
                 help="The regulators' limit: set-points and pressures stay in [0, P] [kPa] (default 120)."),
    click.option("--tau-ms", type=Finite(min=0, min_open=True),
                 help="The regulators' time constant [ms] (default 25): a first-order lag."),
]


def grasp_options(command):
    """Add the simulated grasp's options to ``sim-device``.

    Parameters
    ----------
    command : callable
        The command function being decorated.
    """
    return _decorated(command, _GRASP_OPTIONS)


def grasp_arguments(options: dict, *, gripper: bool = False) -> dict | None:
    """The simulated grasp's arguments from the grasp options, checked; None without ``--fingers``/``--object``.

    Parameters
    ----------
    options : dict
        The values of the grasp options (by parameter name).
    gripper : bool
        ``simulate gripper``: the fingers default to 3 and ``--object`` is optional.

    Returns
    -------
    dict or None
        ``fingers`` (None: the single actuator), ``stiffness_n_per_m``, ``contact_s_m``,
        ``touch_pressure_pa`` and the ``regulation``
        (:class:`~bendsense.sim.gripper.Regulation`: ``max_pressure_pa``, and ``tau_s`` and
        ``close_pa`` when given).
    """
    import math

    fingers, kind = options.get("fingers"), options.get("object_kind")
    if fingers is None and kind is None and not gripper:
        for name in ("object_stiffness", "object_s_m", "object_touch_kpa", "close_kpa", "max_pressure_kpa", "tau_ms"):
            if options.get(name) is not None:
                raise click.BadParameter("applies to a simulated grasp only: give --fingers K or --object",
                                         param_hint="--" + name.replace("_", "-"))
        return None
    kind = kind or "rigid"
    if kind == "rigid" and options.get("object_stiffness") is not None:
        raise click.BadParameter("applies to --object compliant only", param_hint="--object-stiffness")
    from bendsense.config import load_config
    from bendsense.sim.gripper import DEFAULT_COMPLIANT_N_PER_M, DEFAULT_TOUCH_PRESSURE_PA, Regulation
    from bendsense.sim.regulator import DEFAULT_MAX_PRESSURE_PA

    if gripper and fingers is None:
        fingers = 3
    k = 1 if fingers is None else fingers
    max_pa = DEFAULT_MAX_PRESSURE_PA if options.get("max_pressure_kpa") is None else options["max_pressure_kpa"] * 1e3
    s_c, touch = options.get("object_s_m"), options.get("object_touch_kpa")
    length = load_config().actuator.length_m
    for flag, values in (("--object-s-m", s_c), ("--object-touch-kpa", touch)):
        if values is not None and len(values) not in (1, k):
            raise click.BadParameter(f"expected one value or one per finger ({k}), got {len(values)}", param_hint=flag)
    if s_c is not None and max(s_c) > length:
        raise click.BadParameter(f"expected s_c in (0, L = {length:g} m], got {max(s_c):g}", param_hint="--object-s-m")
    touch_pa = DEFAULT_TOUCH_PRESSURE_PA[:k] if touch is None else tuple(v * 1e3 for v in touch)
    close_pa = None if options.get("close_kpa") is None else options["close_kpa"] * 1e3
    for flag, value in (("--object-touch-kpa", max(touch_pa)), ("--close-kpa", close_pa)):
        if value is not None and value > max_pa:
            raise click.BadParameter(f"expected at most the regulators' limit {max_pa / 1e3:g} kPa, got "
                                     f"{value / 1e3:g}", param_hint=flag)
    arguments = {
        "fingers": fingers,
        "stiffness_n_per_m": math.inf if kind == "rigid" else (options.get("object_stiffness")
                                                                or DEFAULT_COMPLIANT_N_PER_M),
        "contact_s_m": s_c,
        "touch_pressure_pa": touch_pa,
    }
    regulation = {"max_pressure_pa": max_pa}
    if options.get("tau_ms") is not None:
        regulation["tau_s"] = options["tau_ms"] / 1e3
    if close_pa is not None:
        regulation["close_pa"] = close_pa
    arguments["regulation"] = Regulation(**regulation)
    return arguments


def grasp_board(options: dict, *, rate_hz: float, seed, adc_bits: int, errors=None):
    """The simulated grasp's board from ``sim-device``'s options, or None without ``--fingers``/``--object``.

    Parameters
    ----------
    options : dict
        The values of the grasp options (by parameter name).
    rate_hz, seed, adc_bits
        The board's frame rate [Hz], seed and ADC resolution.
    errors : dict, optional
        How every finger departs from the config (:func:`model_errors`), and ``noise_counts``.

    Returns
    -------
    GraspBoard or None
    """
    arguments = grasp_arguments(options)
    if arguments is None:
        return None
    from bendsense.config import load_config
    from bendsense.sim.gripper import GraspBoard, default_objects, gripper_config

    fingers = arguments.pop("fingers")
    objects = default_objects(fingers or 1, arguments.pop("stiffness_n_per_m"), arguments.pop("contact_s_m"),
                              arguments.pop("touch_pressure_pa"))
    paper = load_config()
    config = paper if fingers is None else gripper_config(fingers, paper)
    return GraspBoard(config, objects, rate_hz=rate_hz, seed=seed, adc_bits=adc_bits, **arguments, **(errors or {}))


COMMANDS = [simulate]
