"""The load model of a force estimate as the chain, ``process`` and the live path ask for it.

``estimate --load tip|contact [--contact-s-m X] [--window-s W]`` (DESIGN.md section 2b):
the tip force of every frame, the force of a contact at a known arc length ``X`` of every
frame (:func:`bendsense.estimate_force` with ``load="contact"``), or, without ``X``, a
contact located once per quasi-static window and a force per frame
(:func:`bendsense.estimate_contact`).
"""

from __future__ import annotations

from bendsense.choices import LOADS  # the load models of ``estimate --load``, declared once
from bendsense.errors import ArgumentError

__all__ = ["LOADS", "check_contact_s_m", "estimate_load"]


def check_contact_s_m(value, config, name: str = "contact_s_m") -> float:
    """A known contact location: a finite number with 0 < s_c <= L (``config.actuator.length_m``).

    Parameters
    ----------
    value : object
        The location given [m].
    config : Config
        The actuator's length L bounds it.
    name : str, default "contact_s_m"
        The argument or option, for the message (``"--contact-s-m"``).

    Raises
    ------
    ArgumentError
        Naming ``name``, for anything else.
    """
    from bendsense import validation as check

    s = check.number(name, value)
    length = float(config.actuator.length_m)
    if not 0.0 < s <= length:
        raise ArgumentError(f"{name}: expected 0 < s_c <= L = {length:g} m (actuator.length_m, arc length from the "
                            f"base), got {s:g}")
    return s


def estimate_load(shape, pressure_pa, config, *, load: str = "tip", contact_s_m=None, t_s=None,
                  window_s: float = 0.05, **options):
    """The force estimate of a load model: at the tip, at a known contact, or at a contact located per window.

    Parameters
    ----------
    shape : Shape
        Reconstructed shapes, batch axis over frames.
    pressure_pa : array_like
        Pressure of each frame [Pa].
    config : Config
        Sensor, actuator and estimation settings.
    load : {"tip", "contact"}, default "tip"
        The load model (DESIGN.md section 2b).
    contact_s_m : float, optional
        A known contact location [m] (0 < s_c <= L), with ``load="contact"``: every
        frame's force at it (:func:`bendsense.estimate_force`). None with
        ``load="contact"``: the location is estimated, one per quasi-static window of
        ``window_s`` (:func:`bendsense.estimate_contact`), which needs ``t_s``.
    t_s : array_like, shape (frames,), optional
        Frame times [s] (the windows of an unknown location).
    window_s : float, default 0.05
        The window of an unknown location [s].
    **options
        Further options of :func:`bendsense.estimate_force` (``constraint``, ``method``,
        ``calibration``, ...); an unknown location takes ``method="fast"`` only.

    Returns
    -------
    ForceEstimate
        With ``load``; for a contact ``contact_s_m`` and ``contact_std_m`` per frame.
    """
    from bendsense.estimation import estimate_force

    if load not in LOADS:
        raise ArgumentError(f"load: expected one of {', '.join(LOADS)}, got {load!r}")
    if load == "tip":
        if contact_s_m is not None:
            raise ArgumentError("contact_s_m: a contact location needs load='contact' (a tip load acts at s = L)")
        return estimate_force(shape, pressure_pa, config, **options)
    if contact_s_m is not None:
        s_c = check_contact_s_m(contact_s_m, config)
        return estimate_force(shape, pressure_pa, config, load="contact", contact_s_m=s_c, **options)
    import bendsense

    if t_s is None:
        raise ArgumentError("t_s: an unknown contact location is estimated over windows of frames: give the frame "
                            "times (or a known contact_s_m)")
    method = options.pop("method", None)
    if method not in (None, "fast"):  # the location's fit needs the fast estimator's sensitivities
        raise ArgumentError(f"method: an unknown contact location is estimated with method 'fast' only, got "
                            f"{method!r} (with a known contact_s_m any method)")
    return bendsense.estimate_contact(shape, pressure_pa, config, t_s=t_s, window_s=window_s, **options)
