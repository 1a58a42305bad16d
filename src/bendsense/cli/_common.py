"""Pieces shared by the command modules: the command class, common options and checks."""

from __future__ import annotations

import contextlib
import re
from pathlib import Path

import click

from bendsense.choices import ANGLE_SOURCES, CONSTRAINTS, LOADS, METHODS, OBJECTIVES  # noqa: F401 (the CLI's choices)

__all__ = [
    "ANGLE_SOURCES",
    "CONSTRAINTS",
    "Directory",
    "Finite",
    "SEED",
    "METHODS",
    "InterspersedCommand",
    "check_figure_suffix",
    "CalibrationSpec",
    "make_calibration_option",
    "calibration_paths",
    "config_option",
    "make_config_option",
    "make_overwrite_option",
    "overwrite_option",
    "objective_option",
    "window_option",
    "load_option",
    "contact_option",
    "live_contact_option",
    "chain_contact_option",
    "live_contact",
    "ContactSpec",
    "contact_locations",
    "finger_contact",
    "check_load",
    "bandwidth_option",
    "live_bandwidth_option",
    "make_bandwidth_option",
    "quiet",
    "refuse_existing",
    "save_figure",
    "say",
    "step_io",
]



class Finite(click.ParamType):
    """A finite float option (NaN and inf refused), optionally bounded.

    ``click.FloatRange`` lets NaN through (every comparison with NaN is false), so
    ``--seconds nan`` would mean "forever".
    """

    name = "number"

    def __init__(self, min: float | None = None, max: float | None = None, *, min_open: bool = False):
        self.min, self.max, self.min_open = min, max, min_open

    def convert(self, value, param, ctx):
        """Parse and check one value."""
        number = click.FLOAT.convert(value, param, ctx)
        if number != number or number in (float("inf"), float("-inf")):
            self.fail(f"expected a finite number, got {value}", param, ctx)
        if self.min is not None and (number <= self.min if self.min_open else number < self.min):
            self.fail(f"expected {'>' if self.min_open else '>='} {self.min:g}, got {number:g}", param, ctx)
        if self.max is not None and number > self.max:
            self.fail(f"expected <= {self.max:g}, got {number:g}", param, ctx)
        return number


class ContactLocation(Finite):
    """An arc length along the actuator [m] (> 0), or ``along-body`` where a scenario takes a sequence of touches."""

    name = "s_c"

    def __init__(self, named: bool = True):
        super().__init__(min=0, min_open=True)
        self.named = named

    def convert(self, value, param, ctx):
        """Parse and check one value."""
        if self.named and value == "along-body":
            return value
        number = r"\s*[+-]?(\d+\.?\d*|\.\d+)([eE][+-]?\d+)?\s*|\s*[+-]?(nan|inf|infinity)\s*"
        if isinstance(value, str) and not re.fullmatch(number, value, re.IGNORECASE):
            self.fail(f"expected an arc length s_c [m]{' or along-body' if self.named else ''}, got {value!r}",
                      param, ctx)
        return super().convert(value, param, ctx)



class PressureKpa(Finite):
    """A gauge pressure option in kPa: finite, from ``min`` (default vacuum) to 1 MPa.

    Above, the message names the likely unit slip (pascals, bar, psi) and the value in
    kPa (:class:`bendsense.mechanics.bounds.Bound`).
    """

    def __init__(self, min: float = -101.325):
        super().__init__(min=min)

    def convert(self, value, param, ctx):
        """Parse and check one value."""
        from bendsense.mechanics.bounds import PRESSURE_MAX_PA, Bound

        number = super().convert(value, param, ctx)  # finite, >= min
        bound = Bound("gauge pressure of a soft pneumatic actuator", self.min, PRESSURE_MAX_PA / 1e3, "kPa",
                      slips=(("Pa", 1e-3), ("bar", 100.0), ("psi", 6.894757), ("MPa", 1e3)), typical=100.0)
        if not bound.contains(number):
            name = param.opts[0] if param is not None and param.opts else "value"
            self.fail(bound.message(name, number), param, ctx)
        return number


class Relative(Finite):
    """A relative error option (0.1: 10 %): finite, above -1 and at most 1 (a model 100 % off).

    Beyond, the message names the likely slip (percent) and the fraction.
    """

    def convert(self, value, param, ctx):
        """Parse and check one value."""
        from bendsense.mechanics.bounds import Bound

        number = super().convert(value, param, ctx)
        bound = Bound("relative error", -0.99, 1.0, "", "a fraction: 0.1 is 10 %", (("percent", 0.01),))
        if not bound.contains(number):
            name = param.opts[0] if param is not None and param.opts else "value"
            self.fail(bound.message(name, number), param, ctx)
        return number


FILE_SUFFIXES = (".csv", ".png", ".pdf", ".svg", ".jpg", ".jpeg", ".yaml", ".yml", ".json", ".md", ".txt", ".npz",
                 ".mcap", ".bin", ".html")
"""Suffixes of the files bendsense reads and writes: a directory output named with one is a slip."""


class Directory(click.Path):
    """A directory the command writes (created): a name ending in a file's suffix (``.csv``, ``.png``, ...) is refused.

    ``record -o new.csv`` made a directory named ``new.csv``, ``demo -o demo.png`` one holding
    ``demo.png/demo.png``: such a name is a slip for a file (:data:`FILE_SUFFIXES`).
    """

    def __init__(self):
        super().__init__(file_okay=False, path_type=Path)

    def convert(self, value, param, ctx):
        """Check one path."""
        path = super().convert(value, param, ctx)
        suffix = Path(path).suffix
        if suffix.lower() in FILE_SUFFIXES:
            self.fail(f"{click.format_filename(value)!r} is a file's name ({suffix}), but this writes a directory of "
                      "files: give a directory's name", param, ctx)
        return path


SEED = click.IntRange(0, 2**32 - 1)
"""Seeds of numpy's generators: 0..2^32-1 (a negative seed is refused before any work)."""


class InterspersedCommand(click.Command):
    """A command whose options may follow its arguments, also inside a chained group.

    click parses the subcommands of a chained group with
    ``allow_interspersed_args=False``, so ``calibrate MANIFEST.yaml -o cal.yaml`` would
    stop at ``MANIFEST.yaml``. Here the arguments are cut at the first sibling command
    name (the next step of the chain) and everything before it is parsed with options
    allowed anywhere.
    """

    def make_context(self, info_name, args, parent=None, **extra):
        """Make the context with interspersed options allowed."""
        extra["allow_interspersed_args"] = True
        return super().make_context(info_name, args, parent=parent, **extra)

    def parse_args(self, ctx, args):
        """Parse up to the next chained command; leave the rest for the group."""
        group = ctx.parent.command if ctx.parent is not None else None
        siblings = set(group.commands) if isinstance(group, click.Group) else set()
        takes_value = {name for p in self.params if isinstance(p, click.Option) and not p.is_flag for name in p.opts}
        cut = len(args)
        for i, token in enumerate(args):
            if token in siblings and (i == 0 or args[i - 1] not in takes_value):
                cut = i
                break
        super().parse_args(ctx, args[:cut])
        ctx.args = [*ctx.args, *args[cut:]]
        return ctx.args


def make_config_option(help_text: str):
    """``--config`` (an existing YAML file, passed as ``config_path``) with the command's own help."""
    return click.option(
        "--config",
        "config_path",
        type=click.Path(exists=True, dir_okay=False, path_type=Path),
        help=help_text,
    )


class CalibrationSpec(click.ParamType):
    """``--calibration [NAME=]CAL.yaml``: an existing calibration file, for one finger (``NAME=``) or every one.

    The value is ``(name or None, Path)``. A value that is an existing file is a path
    even if it holds ``=``; ``NAME=`` is a finger's name (``[A-Za-z][A-Za-z0-9_-]*``).
    """

    name = "[NAME=]CAL.yaml"
    _file = click.Path(exists=True, dir_okay=False, path_type=Path)

    def convert(self, value, param, ctx):
        """Parse and check one value."""
        from bendsense.config.gripper import FINGER_NAME

        if isinstance(value, tuple):  # already converted (a default)
            return value
        found = re.fullmatch(rf"({FINGER_NAME})=(.+)", value)
        if found and not Path(value).exists():
            return found.group(1), self._file.convert(found.group(2), param, ctx)
        return None, self._file.convert(value, param, ctx)


class ContactSpec(click.ParamType):
    """``--contact-s-m [NAME=]S_C``: a contact location [m] (> 0), for one finger (``NAME=``) or every one.

    The value is ``(name or None, float)``; :func:`contact_locations` checks it against the config.
    """

    name = "[NAME=]S_C"
    _number = Finite(min=0, min_open=True)

    def convert(self, value, param, ctx):
        """Parse and check one value."""
        from bendsense.config.gripper import FINGER_NAME

        if isinstance(value, tuple):  # already converted (a default)
            return value
        found = re.fullmatch(rf"({FINGER_NAME})=(.*)", str(value))
        if found:
            if not found.group(2).strip():
                self.fail(f"{value}: no location after the finger's name (give {found.group(1)}=S_C, an arc length "
                          f"[m])", param, ctx)
            return found.group(1), self._number.convert(found.group(2), param, ctx)
        return None, self._number.convert(value, param, ctx)


def make_calibration_option(help_text: str = "Calibration YAML written by 'bendsense calibrate'", *,
                            required: bool = False):
    """``--calibration [NAME=]CAL.yaml`` (repeatable, passed as ``calibration_paths``), with the command's help.

    One plain ``--calibration CAL.yaml`` calibrates a single actuator, or every finger of
    a gripper; ``--calibration NAME=CAL.yaml`` (repeated) one finger each.
    :func:`calibration_paths` turns the values into what the config needs.

    Parameters
    ----------
    help_text : str
        The option's help, before the part on fingers.
    required : bool, default False
        Whether the command needs one.
    """
    return click.option(
        "--calibration", "calibration_paths", type=CalibrationSpec(), multiple=True, required=required,
        metavar="[NAME=]CAL.yaml",
        help=f"{help_text.rstrip('.')}. A gripper (config with fingers:): NAME=CAL.yaml per finger (repeatable), or "
             f"one CAL.yaml for every finger.")


def calibration_paths(values, config, option: str = "--calibration"):
    """The calibration file(s) of ``--calibration`` for ``config``: one path, or ``{finger or None: path}``.

    Parameters
    ----------
    values : tuple of (str or None, Path)
        The option's values (:class:`CalibrationSpec`).
    config : Config or GripperConfig
        A single actuator takes one plain path (or none: None); a gripper a mapping
        from finger name (None: every finger not named) to path, checked by
        :func:`bendsense.session.fingers.calibrations`.
    option : str
        The option, for messages.

    Returns
    -------
    Path or None or dict
    """
    from bendsense.config import GripperConfig

    values = list(values or ())
    if not isinstance(config, GripperConfig):
        named = [f"{n}={p}" for n, p in values if n is not None]
        if named:
            raise click.BadParameter(f"{named[0]} names a finger, but the config is a single actuator (no fingers:); "
                                     f"give {option} CAL.yaml", param_hint=f"'{option}'")
        if len(values) > 1:
            raise click.BadParameter(f"given {len(values)} times; a single actuator takes one calibration",
                                     param_hint=f"'{option}'")
        return values[0][1] if values else None
    out = {}
    for name, path in values:
        if name in out:
            which = f"finger {name}" if name is not None else "every finger (a plain CAL.yaml)"
            raise click.BadParameter(f"two calibrations for {which}: {out[name]} and {path}",
                                     param_hint=f"'{option}'")
        out[name] = path
    return out


def make_overwrite_option(help_text: str):
    """``--overwrite`` (a flag) with the command's own help."""
    return click.option("--overwrite", is_flag=True, help=help_text)


config_option = make_config_option("Config YAML (default: the paper's prototype, built in).")
overwrite_option = make_overwrite_option("Replace existing output.")
objective_option = click.option(
    "--objective", type=click.Choice(OBJECTIVES),
    help="Fit the coil angles S/d the sensor measures ('angles') or the PCC positions of paper eq. 18 "
         "('positions'); default: from the config (angles).")

window_option = click.option(
    "--window-s", type=Finite(min=0, min_open=True), default=None,
    help="Window of the model check over frames [s] (a mean residual per window tested against its covariance; "
         "p < 0.001 flags its frames model_misfit), and of an unknown contact location (--load contact without "
         "--contact-s-m: one s_c per window); default 0.05.")
constraint_option = click.option("--constraint", type=click.Choice(CONSTRAINTS),
                                 help="Force constraint (default: from the config).")
load_option = click.option(
    "--load", type=click.Choice(LOADS), default="tip", show_default=True,
    help="Load model: a force at the tip, or one point force at arc length s_c along the actuator (contact).")
contact_option = click.option(
    "--contact-s-m", type=Finite(min=0, min_open=True), default=None,
    help="With --load contact: the known contact location, arc length s_c from the base [m] (0 < s_c <= L); "
         "without it the location is estimated over windows of --window-s.")
#: ``--contact-s-m`` of ``estimate``: a known location (a gripper: per finger, NAME=S_C), else estimated
chain_contact_option = click.option(
    "--contact-s-m", "contact_s_m", type=ContactSpec(), multiple=True, metavar="[NAME=]S_C",
    help="With --load contact: the known contact location, arc length s_c from the base [m] (0 < s_c <= L); "
         "without it the location is estimated over windows of --window-s. A gripper: NAME=S_C per finger "
         "(repeatable), a plain S_C for every finger not named.")
#: ``--contact-s-m`` of ``record --estimate``, ``live`` and ``control``: frames arrive one by one, the location is given
live_contact_option = click.option(
    "--contact-s-m", "contact_s_m", type=ContactSpec(), multiple=True, metavar="[NAME=]S_C",
    help="With --load contact (needed then): the known contact location, arc length s_c from the base [m] "
         "(0 < s_c <= L). A gripper: NAME=S_C per finger (repeatable), a plain S_C for every finger not named.")


def check_load(load: str, contact_s_m, config) -> None:
    """``--load``/``--contact-s-m`` of ``estimate`` and ``process``: a location only with a contact, within L.

    Parameters
    ----------
    load : str
        ``--load``.
    contact_s_m : float or None
        ``--contact-s-m`` [m].
    config : Config
        The actuator's length bounds it.
    """
    from bendsense.errors import BendsenseError
    from bendsense.estimation.load_models import check_contact_s_m

    if contact_s_m is not None:
        if load != "contact":
            raise click.BadParameter("a contact location needs --load contact", param_hint="'--contact-s-m'")
        try:
            check_contact_s_m(contact_s_m, config, "--contact-s-m")
        except BendsenseError as err:
            raise click.BadParameter(str(err).removeprefix("--contact-s-m: "), param_hint="'--contact-s-m'") from None


def live_contact(load: str, contact_s_m, config) -> dict:
    """The load options of ``record --estimate`` and ``live``: a known location only (frames arrive one by one).

    Parameters
    ----------
    load : str
        ``--load``.
    contact_s_m : float or None
        ``--contact-s-m`` [m].
    config : Config
        The actuator's length bounds it.

    Returns
    -------
    dict
        ``{}`` for a tip load, else ``{"load": "contact", "contact_s_m": s_c}`` (the
        options of :class:`~bendsense.pipeline.LiveProcessor`).
    """
    if load == "contact" and contact_s_m is None:
        raise click.BadParameter("--load contact as frames arrive needs the known location --contact-s-m (a location "
                                 "estimated over windows is offline: 'estimate --load contact')",
                                 param_hint="'--contact-s-m'")
    check_load(load, contact_s_m, config)
    return {} if load == "tip" else {"load": "contact", "contact_s_m": float(contact_s_m)}


def contact_locations(values, config, load: str, option: str = "--contact-s-m"):
    """The locations of ``--contact-s-m [NAME=]S_C`` for ``config``: one, or one per finger.

    Parameters
    ----------
    values : tuple of (str or None, float)
        The option's values (:class:`ContactSpec`); a plain S_C applies to every finger
        not named.
    config : Config or GripperConfig
        A single actuator takes one plain location; a gripper's fingers each one (or none).
    load : str
        ``--load``: a location needs ``contact``.
    option : str
        The option, for messages.

    Returns
    -------
    float or None or dict
        A single actuator's location (None: not given); a gripper's ``{finger: s_c or None}``,
        each checked against its finger's length (:func:`check_load`).
    """
    from bendsense.config import GripperConfig

    values = list(values or ())
    hint = f"'{option}'"
    if not isinstance(config, GripperConfig):
        named = [f"{n}={s:g}" for n, s in values if n is not None]
        if named:
            raise click.BadParameter(f"{named[0]} names a finger, but the config is a single actuator (no fingers:); "
                                     f"give {option} S_C", param_hint=hint)
        if len(values) > 1:
            raise click.BadParameter(f"given {len(values)} times; a single actuator takes one location",
                                     param_hint=hint)
        location = values[0][1] if values else None
        check_load(load, location, config)
        return location
    given = {}
    for name, location in values:
        if name in given:
            which = f"finger {name}" if name is not None else "every finger (a plain S_C)"
            raise click.BadParameter(f"two locations for {which}: {given[name]:g} and {location:g}", param_hint=hint)
        if name is not None and name not in config.names:
            raise click.BadParameter(f"{name}={location:g}: {name} is not a finger of this gripper; its fingers: "
                                     f"{', '.join(config.names)}", param_hint=hint)
        given[name] = location
    out = {}
    for finger in config.fingers:
        out[finger.name] = given.get(finger.name, given.get(None))
        try:
            check_load(load, out[finger.name], finger.config)
        except click.BadParameter as err:
            raise click.BadParameter(f"finger {finger.name}: {err.message}", param_hint=hint) from None
    return out


def finger_contact(values, state: dict, load: str):
    """The known contact location of one state of the chain: a single actuator's, or one finger's.

    Parameters
    ----------
    values : tuple of (str or None, float)
        ``--contact-s-m`` (:class:`ContactSpec`).
    state : dict
        The chain's state of a single actuator, or of one finger of a gripper (its
        ``finger`` key; the names were checked against the gripper by :func:`contact_locations`).
    load : str
        ``--load``.

    Returns
    -------
    float or None
    """
    finger = state.get("finger")
    if finger is None:
        return contact_locations(values, state["config"], load)
    given = dict(values or ())
    location = given.get(finger, given.get(None))
    check_load(load, location, state["config"])
    return location


def make_bandwidth_option(default_text: str, minimum_hz: float = 0.0):
    """``--bandwidth-hz`` of the tracked force (> ``minimum_hz``), with its default told in ``default_text``."""
    return click.option("--bandwidth-hz", type=Finite(min=minimum_hz, min_open=True), default=None,
                        help=f"Bandwidth of the tracked force [Hz]: the -3 dB bandwidth of the steady-state filter; "
                             f"default: {default_text}.")


bandwidth_option = make_bandwidth_option("chosen from the session by maximum likelihood")
#: ``--bandwidth-hz`` of ``record --estimate`` and ``live``, which cannot look ahead to choose one
live_bandwidth_option = make_bandwidth_option("5 Hz (bendsense.tracking.DEFAULT_BANDWIDTH_HZ)")


def refuse_existing(path: Path, overwrite: bool) -> None:
    """Stop with one line when the output ``path`` exists and ``--overwrite`` was not given."""
    if path.exists() and not overwrite:
        raise click.ClickException(f"{path}: exists (use --overwrite to replace it)")


def step_io(step, outputs=(), inputs=()):
    """Attach a chain step's outputs (``bendsense.output`` targets) and input paths to it.

    The group checks and locks every output of the whole command line before the
    first step runs (:func:`bendsense.cli.pipeline.run_steps`).
    """
    step.outputs = list(outputs)
    step.inputs = [p for p in inputs if p is not None]
    ctx = click.get_current_context(silent=True)
    step.step_name = ctx.info_name if ctx is not None else None  # for messages naming the step
    return step


def check_figure_suffix(path: Path | None, param_hint: str) -> None:
    """Refuse a figure path whose suffix matplotlib cannot write, before any work starts."""
    if path is None:
        return
    from matplotlib.backend_bases import FigureCanvasBase

    formats = FigureCanvasBase.get_supported_filetypes()
    if path.suffix[1:].lower() not in formats:
        what = f"unknown figure format {path.suffix!r}" if path.suffix else "no figure format (a file name suffix)"
        # exit status 1, as for the output layer's own checks of output paths
        raise click.ClickException(
            f"{path}: {what} ({param_hint}); use one of {', '.join('.' + f for f in sorted(formats))}"
        )


def quiet() -> bool:
    """Whether ``bendsense -q`` was given (False outside the ``bendsense`` group)."""
    ctx = click.get_current_context(silent=True)
    obj = ctx.find_root().obj if ctx is not None else None
    return bool(isinstance(obj, dict) and obj.get("quiet"))


def say(text: str, *, err: bool = False) -> None:
    """Print ``text`` (a report, a ``wrote ...`` line; to stderr with ``err``) unless ``bendsense -q`` was given."""
    if not quiet():
        click.echo(text, err=err)


def checked_calibration(path, config):
    """The calibration at ``path`` for one actuator's ``config``; a channel count of another sensor names the file."""
    from bendsense.calibration import Calibration
    from bendsense.errors import ConfigError

    calibration = Calibration.load(path)
    if calibration.n_channels != config.sensor.n_segments:
        raise ConfigError(f"{path}: the calibration has {calibration.n_channels} channels, but the config's sensor "
                          f"has {config.sensor.n_segments} segments (sensor.n_segments)")
    return calibration


def require_prior(config, config_path) -> None:
    """The prior that ``--adapt`` (and the chain's ``adapt``) updates; a config without one is named by its file.

    Its ``name:`` would not do: a copy of the shipped config keeps the shipped one's name.
    """
    from bendsense.errors import ConfigError
    from bendsense.identify.sessions import NO_PRIOR

    if config.parameter_covariance is None:
        raise ConfigError(f"{config_path or 'the config'}: {NO_PRIOR}")


@contextlib.contextmanager
def data_warnings_logged(said=None):
    """The library's :class:`~bendsense.errors.DataWarning` inside the block as one ``WARNING:`` line each.

    A Python warning prints its source line too; each distinct message is said once (once per
    chain with the chain's set ``said``). Other warnings pass on as they were.
    """
    import logging
    import warnings

    from bendsense.errors import DataWarning

    said = set() if said is None else said
    caught = []
    try:
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always", DataWarning)
            yield
    finally:  # also before the error that ends the block: the warning is often its cause (kPa given as Pa)
        for w in caught:
            if not issubclass(w.category, DataWarning):
                warnings.warn_explicit(w.message, w.category, w.filename, w.lineno)
            elif str(w.message) not in said:
                said.add(str(w.message))
                logging.getLogger("bendsense").warning("%s", w.message)


def log_no_parameter_covariance(config) -> None:
    """One ``WARNING:`` line when ``config`` declares no ``parameter_covariance`` (σ without the model's part).

    The CLI's form of :class:`~bendsense.errors.NoParameterCovarianceWarning`: said once per
    command that estimates (the library's warning is silenced there, it would repeat it).
    """
    import logging

    from bendsense.estimation.uncertainty import no_parameter_covariance_message

    if config is not None and config.parameter_covariance is None:
        logging.getLogger("bendsense").warning("%s", no_parameter_covariance_message(config))


def save_figure(figure, path: Path, overwrite: bool = False) -> None:
    """Write a matplotlib figure to ``path`` at 120 dpi (atomically), close it and say so."""
    import matplotlib.pyplot as plt

    from bendsense import output

    try:
        with output.write_file(path, overwrite=overwrite, suffixes=output.FIGURE) as tmp:
            fmt = path.suffix[1:].lower()
            figure.savefig(tmp, dpi=120, format=fmt, metadata=output.figure_metadata(fmt))
    finally:
        plt.close(figure)
    say(f"wrote {path}")
