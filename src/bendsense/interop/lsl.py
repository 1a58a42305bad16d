"""Live shape and force on Lab Streaming Layer (optional extra ``lsl``, pylsl).

:class:`LslOutlets` publishes two streams, one sample per frame:

- ``bendsense-force``, type ``Force``: ``fx_n, fy_n, fx_std_n, fy_std_n`` [N] (NaN where a
  frame has no estimate), then, when the processor tracks the force (the default of
  ``record --estimate`` and ``live``), the causally tracked force ``fx_track_n,
  fy_track_n, fx_track_std_n, fy_track_std_n`` [N] (:class:`bendsense.tracking.Tracker`: a
  Kalman filter, so each sample's tracked value uses that frame and the frames before),
  then, for a contact load (``record --estimate --load contact --contact-s-m X``), the
  contact's arc length and its standard deviation ``contact_s_m, contact_std_m`` [m];
- ``bendsense-shape``, type ``Shape``: ``kappa1 … kappaN`` [1/m], ``tip_x_m``, ``tip_y_m``
  [m], ``tip_angle_rad`` [rad].

Both are ``double64`` streams whose nominal rate is the board's frame rate (its HELLO);
each channel's ``label``, ``unit`` and ``type`` are in the stream's XML description
(``<desc><channels><channel>``), with the frame (``bendsense_base``) and the estimator
options beside them. A sample's time stamp is the frame's arrival at the host (when its
bytes were read), on the LSL clock (``pylsl.local_clock()``), so streams of other
devices recorded with LabRecorder line up with it.

A gripper (a config with ``fingers:``) has the two streams per finger,
``bendsense-force-<finger>`` and ``bendsense-shape-<finger>``, with the channels of the
single streams (the finger's own ``kappa1 … kappaN``) and the finger's name in the
description (:class:`GripperOutlets`).
"""

from __future__ import annotations

import time

import numpy as np

from bendsense.errors import require_extra

__all__ = ["LslOutlets", "GripperOutlets", "FORCE_CHANNELS", "TRACK_CHANNELS", "CONTACT_CHANNELS", "shape_channels"]

FORCE_CHANNELS = (("fx_n", "N"), ("fy_n", "N"), ("fx_std_n", "N"), ("fy_std_n", "N"))
#: the tracked force after the per-frame one (the columns of results.csv of the same names)
TRACK_CHANNELS = (("fx_track_n", "N"), ("fy_track_n", "N"), ("fx_track_std_n", "N"), ("fy_track_std_n", "N"))
#: a contact load's location after the force channels (the columns of results.csv of the same names)
CONTACT_CHANNELS = (("contact_s_m", "m"), ("contact_std_m", "m"))


def shape_channels(n_segments: int) -> list:
    """``(label, unit)`` of the channels of ``bendsense-shape`` for a sensor of N segments.

    Parameters
    ----------
    n_segments : int
        Number of sensor segments N.
    """
    return [*((f"kappa{i + 1}", "1/m") for i in range(n_segments)), ("tip_x_m", "m"), ("tip_y_m", "m"),
            ("tip_angle_rad", "rad")]


def _info(pylsl, name, kind, channels, rate_hz, source_id, meta):
    info = pylsl.StreamInfo(name, kind, len(channels), float(rate_hz or 0.0), pylsl.cf_double64, source_id)
    desc = info.desc()
    chans = desc.append_child("channels")
    for label, unit in channels:
        ch = chans.append_child("channel")
        ch.append_child_value("label", label)
        ch.append_child_value("unit", unit)
        ch.append_child_value("type", kind)
    desc.append_child_value("manufacturer", "bendsense")
    for key, value in meta.items():
        desc.append_child_value(key, str(value))
    return info


class LslOutlets:
    """The two LSL outlets of a live run.

    Parameters
    ----------
    n_segments : int
        Sensor segments N (channels ``kappa1..kappaN`` of the shape stream).
    rate_hz : float
        Nominal rate [Hz]: the board's frame rate (0: irregular).
    source_id : str
        LSL source id (e.g. the port), so that a restarted run is recognised.
    meta : dict, optional
        Further ``key: value`` pairs for both streams' description (constraint, ...).
    tracked : bool, default False
        The force stream also carries the tracked force (:data:`TRACK_CHANNELS`, after
        :data:`FORCE_CHANNELS`); the blocks pushed then have a ``track``.
    contact : bool, default False
        The force stream also carries the contact location (:data:`CONTACT_CHANNELS`,
        after the others): the processor estimates a contact load.
    finger : str, optional
        A gripper's finger: the streams are ``bendsense-force-<finger>`` and
        ``bendsense-shape-<finger>`` (source ids ``<source_id>-force-<finger>``, ...), and
        the description names the finger.

    Raises
    ------
    MissingExtraError
        If pylsl is not installed (extra ``lsl``).
    """

    def __init__(self, n_segments: int, rate_hz: float, source_id: str = "bendsense", meta: dict | None = None,
                 tracked: bool = False, contact: bool = False, finger: str | None = None):
        pylsl = require_extra("pylsl", "lsl", "--lsl")
        meta = {"frame": "bendsense_base (+y along the actuator at its base, +x toward the centre of curvature)",
                **({} if finger is None else {"finger": finger}), **(meta or {})}
        self.tracked, self.contact = bool(tracked), bool(contact)
        channels = FORCE_CHANNELS + (TRACK_CHANNELS if self.tracked else ()) + (CONTACT_CHANNELS if contact else ())
        tail = "" if finger is None else f"-{finger}"
        self.force = pylsl.StreamOutlet(_info(pylsl, f"bendsense-force{tail}", "Force", channels, rate_hz,
                                              f"{source_id}-force{tail}", meta))
        self.shape = pylsl.StreamOutlet(_info(pylsl, f"bendsense-shape{tail}", "Shape", shape_channels(n_segments),
                                              rate_hz, f"{source_id}-shape{tail}", meta))
        # time.monotonic_ns() (the arrival time of a frame) on the LSL clock
        self._offset_s = pylsl.local_clock() - time.monotonic()
        self.pushed = 0

    def push(self, block) -> None:
        """Publish the frames of a :class:`~bendsense.pipeline.LiveBlock`.

        Parameters
        ----------
        block : LiveBlock
            The processed frames to publish.
        """
        n = len(block)
        if not n:
            return
        stamps = (np.asarray(block.host_ns, dtype=float) * 1e-9 + self._offset_s).tolist()
        force = np.column_stack([block.force_n, block.std_n, *((block.track_force_n, block.track_std_n)
                                                                if self.tracked else ())])
        if self.contact:  # NaN where a frame has no estimate
            from bendsense.results.contact import contact_columns

            where = contact_columns(n, block.estimate) or {name: np.full(n, np.nan) for name, _ in CONTACT_CHANNELS}
            force = np.column_stack([force, *(where[name] for name, _ in CONTACT_CHANNELS)])
        shape = block.shape
        kappa = np.asarray(shape.curvature_per_m, dtype=float).reshape(n, -1)
        tip = np.asarray(shape.tip_position_m, dtype=float).reshape(n, 2)
        angle = np.asarray(shape.tip_angle_rad, dtype=float).reshape(n, 1)
        self.force.push_chunk(force, stamps)
        self.shape.push_chunk(np.hstack([kappa, tip, angle]), stamps)
        self.pushed += n

    def close(self) -> None:
        """Drop the outlets (consumers see the streams end)."""
        self.force = self.shape = None

    def have_consumers(self) -> bool:
        """True when an inlet is connected to the force stream."""
        return self.force is not None and self.force.have_consumers()


class GripperOutlets:
    """The LSL outlets of a gripper: ``bendsense-force-<finger>`` and ``bendsense-shape-<finger>`` per finger.

    Parameters
    ----------
    n_segments : mapping of str to int
        Each finger's sensor segments N, in the fingers' order.
    rate_hz : float
        Nominal rate [Hz]: the board's frame rate (0: irregular).
    source_id : str
        LSL source id of the board (e.g. the port).
    meta : dict, optional
        Further ``key: value`` pairs for every stream's description.
    tracked, contact : bool, default False
        As :class:`LslOutlets`, for every finger.
    finger_meta : dict of str to dict, optional
        A finger's own ``key: value`` pairs over ``meta`` (e.g. its known ``contact_s_m``).

    Attributes
    ----------
    outlets : dict of str to LslOutlets
        Each finger's outlets.
    """

    def __init__(self, n_segments, rate_hz: float, source_id: str = "bendsense", meta: dict | None = None,
                 tracked: bool = False, contact: bool = False, finger_meta: dict | None = None):
        self.outlets = {name: LslOutlets(n, rate_hz, source_id=source_id,
                                         meta={**(meta or {}), **(finger_meta or {}).get(name, {})},
                                         tracked=tracked, contact=contact, finger=name)
                        for name, n in n_segments.items()}

    @property
    def pushed(self) -> int:
        """Board frames published (those of the first finger)."""
        return next(iter(self.outlets.values())).pushed if self.outlets else 0

    def push(self, blocks) -> None:
        """Publish each finger's :class:`~bendsense.pipeline.LiveBlock` on its streams.

        Parameters
        ----------
        blocks : dict of str to LiveBlock
            The processed frames per finger (:meth:`bendsense.pipeline.gripper.GripperProcessor.process_readings`).
        """
        for name, block in blocks.items():
            self.outlets[name].push(block)

    def close(self) -> None:
        """Drop every outlet."""
        for outlet in self.outlets.values():
            outlet.close()

    def have_consumers(self) -> bool:
        """True when every finger's force stream has an inlet connected."""
        return all(outlet.have_consumers() for outlet in self.outlets.values())
