"""Exceptions raised by bendsense.

Every error derives from :class:`BendsenseError` and from the matching built-in
exception, so ``except ValueError`` keeps working for callers that do not know
bendsense. All of them pickle, so batch workers can send them back.
"""

__all__ = [
    "BendsenseError",
    "ArgumentError",
    "ConfigError",
    "FrameError",
    "DeviceError",
    "ConvergenceError",
    "SessionError",
    "OutputError",
    "OutputExistsError",
    "MissingExtraError",
    "BendsenseWarning",
    "ConvergenceWarning",
    "NoNoiseModelWarning",
    "NoParameterCovarianceWarning",
    "DataWarning",
]


class BendsenseError(Exception):
    """Base class of all bendsense errors."""


class ArgumentError(BendsenseError, ValueError):
    """An argument of a function or a command is invalid; the message names it.

    Raised for user input (options, array shapes, out-of-range values) by the checks
    of :mod:`bendsense.validation`; a plain ``ValueError`` from bendsense is a bug.
    """


class ConfigError(BendsenseError, ValueError):
    """A configuration value or file is invalid; the message names the field."""


class SessionError(BendsenseError, ValueError):
    """A session file (CSV or native directory) is malformed; the message names where."""


class FrameError(BendsenseError, ValueError):
    """A wire frame cannot be encoded or decoded."""


class DeviceError(BendsenseError, OSError):
    """The sensor device cannot be opened, was disconnected or misbehaves."""


class OutputError(BendsenseError, OSError):
    """An output cannot be written (or not without destroying something); the message names the path.

    ``errno`` is that of the file system's refusal behind it (``errno.ENOSPC`` for a
    full disk, ...), None for a refusal of bendsense's own; it survives pickling.
    """

    def __init__(self, message, *, errno=None):
        super().__init__(message)
        self.errno = errno

    def __reduce__(self):
        return _output_error, (type(self), str(self), self.errno)


def _output_error(cls, message, errno):
    return cls(message, errno=errno)


class OutputExistsError(OutputError, FileExistsError):
    """An output exists and ``overwrite`` was not given."""


class ConvergenceError(BendsenseError, RuntimeError):
    """A solver did not converge and ``strict=True`` was requested."""


class MissingExtraError(BendsenseError, ImportError):
    """A feature needs an optional extra that is not installed; the message names it."""


def require_extra(module: str, extra: str, feature: str):
    """Import ``module`` or raise :class:`MissingExtraError` naming the extra to install.

    Parameters
    ----------
    module : str
        Module to import, e.g. ``"pylsl"``.
    extra : str
        The optional extra of bendsense that installs it, e.g. ``"lsl"``.
    feature : str
        What needs it, for the message, e.g. ``"--lsl"``.

    Returns
    -------
    module
    """
    import importlib

    try:
        return importlib.import_module(module)
    except ImportError as err:
        raise MissingExtraError(
            f"{feature} needs the optional extra '{extra}' ({module} is not installed): "
            f"pip install '.[{extra}]' in bendsense's source directory (from a package index: 'bendsense[{extra}]')"
        ) from err


class BendsenseWarning(UserWarning):
    """Base class of all bendsense warnings."""


class ConvergenceWarning(BendsenseWarning, RuntimeWarning):
    """Some frames of a batch did not converge; they are flagged with ``success=False``."""


class NoNoiseModelWarning(BendsenseWarning):
    """An estimate without a noise model: its σ is NaN (``uncertainty="none"``)."""


class NoParameterCovarianceWarning(BendsenseWarning):
    """An estimate with a config that declares no ``parameter_covariance``.

    Its σ holds sensor noise and calibration error only, as if the model parameters
    (μ̄, μ_s, prebend, γ0, γ1) were exact; the shipped paper config states a prior for
    an actuator nobody identified, ``bendsense identify`` writes the covariance of a fit.
    Warned once per process by :func:`bendsense.estimate_force`.
    """


class DataWarning(BendsenseWarning):
    """The data cannot carry what was asked of them, or do not look like what they claim to be.

    A track whose likelihood does not choose a bandwidth, windows too short for the model
    check, pressures that look like kPa given as Pa. The command line says each in one line.
    """
