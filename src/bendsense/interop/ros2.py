"""Sessions and their results as ROS 2 messages in an MCAP file (optional extra ``ros``).

One message per frame on each topic, all in the frame ``bendsense_base`` (DESIGN.md
section 2: base at the origin, ``+y`` along the actuator at its base, ``+x`` toward the
centre of curvature; SI units, metres and newtons):

================================ ======================================= ==============================================
topic                            type                                    content
================================ ======================================= ==============================================
``/bendsense/wrench``            ``geometry_msgs/msg/WrenchStamped``     tip force ``(fx_n, fy_n, 0)`` [N], torque 0
``/bendsense/force_std``         ``geometry_msgs/msg/Vector3Stamped``    its standard deviation ``(fx_std_n, fy_std_n,
                                                                         0)`` [N] (NaN: no noise model)
``/bendsense/wrench_tracked``    ``geometry_msgs/msg/WrenchStamped``     the tracked tip force ``(fx_track_n,
                                                                         fy_track_n, 0)`` [N] (``track`` step,
                                                                         :func:`bendsense.track`), torque 0
``/bendsense/force_tracked_std`` ``geometry_msgs/msg/Vector3Stamped``    its standard deviation ``(fx_track_std_n,
                                                                         fy_track_std_n, 0)`` [N]
``/bendsense/status``            ``diagnostic_msgs/msg/DiagnosticArray`` one ``DiagnosticStatus`` named
                                                                         ``bendsense/force``: level OK (``ok``), WARN
                                                                         (``extrapolated``, ``model_misfit``) or ERROR
                                                                         (``not converged``); message = the status of
                                                                         ``results.csv``; values ``fx_std_n``,
                                                                         ``fy_std_n``, ``residual_m``, ``status``, and
                                                                         ``contact_s_m``, ``contact_std_m``,
                                                                         ``track_status``, ``window_p_value`` where
                                                                         results.csv has them
``/bendsense/contact``           ``geometry_msgs/msg/PointStamped``      a contact load's point (``load="contact"``):
                                                                         the reconstructed shape's point at
                                                                         ``contact_s_m``, ``(x, y, 0)`` [m]; a frame
                                                                         whose contact is not resolved
                                                                         (``contact_std_m`` inf, or no location) is
                                                                         not written
``/bendsense/shape``             ``nav_msgs/msg/Path``                   the reconstructed shape: one pose per
                                                                         arc-length sample, position ``(x, y, 0)`` [m],
                                                                         orientation the tangent (a rotation about
                                                                         ``z``)
``/bendsense/pressure``          ``sensor_msgs/msg/FluidPressure``       actuation pressure [Pa], variance 0 (unknown);
                                                                         frames without a reading are not written
================================ ======================================= ==============================================

The force topics are written when the results hold a force estimate, the tracked ones
when they hold a track (a ``track`` step earlier in the chain), the contact point when the
estimate is of a contact load (``estimate --load contact``; its schema is registered only
then). Time stamps (the
header stamp and the MCAP log time) are the session's: ``meta["start_time_utc"]`` of a
recorded session plus the frame's time ``t_s`` from the first frame; a session CSV without
that key is stamped with ``t_s`` itself (seconds after 1970-01-01, which viewers show as
such). The message definitions are the standard ones of ROS 2 (Humble and later), so
``mcap_ros2.reader.read_ros2_messages``, ``ros2 bag`` and Foxglove read the file
without bendsense.
"""

from __future__ import annotations

import datetime as _dt
import math
from pathlib import Path

import numpy as np

from bendsense import output
from bendsense.errors import SessionError, require_extra
from bendsense.status import Status

__all__ = ["write_mcap", "write_mcap_fingers", "finger_topic", "require_ros", "FRAME_ID", "TOPICS"]

FRAME_ID = "bendsense_base"
MCAP = (".mcap",)
TOPICS = {
    "wrench": "/bendsense/wrench",
    "force_std": "/bendsense/force_std",
    "wrench_tracked": "/bendsense/wrench_tracked",
    "force_tracked_std": "/bendsense/force_tracked_std",
    "status": "/bendsense/status",
    "contact": "/bendsense/contact",
    "shape": "/bendsense/shape",
    "pressure": "/bendsense/pressure",
}

_SEP = "=" * 80 + "\n"
_TIME = "MSG: builtin_interfaces/Time\nint32 sec\nuint32 nanosec\n"
_HEADER = "MSG: std_msgs/Header\nbuiltin_interfaces/Time stamp\nstring frame_id\n"
_VECTOR3 = "MSG: geometry_msgs/Vector3\nfloat64 x\nfloat64 y\nfloat64 z\n"
_POINT = "MSG: geometry_msgs/Point\nfloat64 x\nfloat64 y\nfloat64 z\n"
POINT_STAMPED = "geometry_msgs/msg/PointStamped"  # the contact point: registered only for a contact load


def _definition(fields: str, *dependencies: str) -> str:
    """A ROS 2 message definition with its dependencies, as ``ros2 bag`` stores it."""
    return fields + "".join(_SEP + dep for dep in dependencies)


SCHEMAS = {
    "geometry_msgs/msg/WrenchStamped": _definition(
        "std_msgs/Header header\ngeometry_msgs/Wrench wrench\n",
        _HEADER,
        _TIME,
        "MSG: geometry_msgs/Wrench\ngeometry_msgs/Vector3 force\ngeometry_msgs/Vector3 torque\n",
        _VECTOR3,
    ),
    "geometry_msgs/msg/Vector3Stamped": _definition(
        "std_msgs/Header header\ngeometry_msgs/Vector3 vector\n", _HEADER, _TIME, _VECTOR3
    ),
    "diagnostic_msgs/msg/DiagnosticArray": _definition(
        "std_msgs/Header header\ndiagnostic_msgs/DiagnosticStatus[] status\n",
        _HEADER,
        _TIME,
        "MSG: diagnostic_msgs/DiagnosticStatus\nbyte OK=0\nbyte WARN=1\nbyte ERROR=2\nbyte STALE=3\n"
        "byte level\nstring name\nstring message\nstring hardware_id\ndiagnostic_msgs/KeyValue[] values\n",
        "MSG: diagnostic_msgs/KeyValue\nstring key\nstring value\n",
    ),
    "nav_msgs/msg/Path": _definition(
        "std_msgs/Header header\ngeometry_msgs/PoseStamped[] poses\n",
        _HEADER,
        _TIME,
        "MSG: geometry_msgs/PoseStamped\nstd_msgs/Header header\ngeometry_msgs/Pose pose\n",
        "MSG: geometry_msgs/Pose\ngeometry_msgs/Point position\ngeometry_msgs/Quaternion orientation\n",
        _POINT,
        "MSG: geometry_msgs/Quaternion\nfloat64 x 0\nfloat64 y 0\nfloat64 z 0\nfloat64 w 1\n",
    ),
    "sensor_msgs/msg/FluidPressure": _definition(
        "std_msgs/Header header\nfloat64 fluid_pressure\nfloat64 variance\n", _HEADER, _TIME
    ),
    POINT_STAMPED: _definition("std_msgs/Header header\ngeometry_msgs/Point point\n", _HEADER, _TIME, _POINT),
}
_LEVEL = {Status.OK.word: 0, Status.EXTRAPOLATED.word: 1, Status.MODEL_MISFIT.word: 1,
          Status.NOT_IDENTIFIABLE.word: 1, Status.CONTACT_UNRESOLVED.word: 1,
          Status.NOT_CONVERGED.word: 2}  # diagnostic levels of the status words of results.csv


def require_ros():
    """Import the MCAP writer of ROS 2 messages, or say which extra installs it.

    Returns
    -------
    module
        ``mcap_ros2.writer``.

    Raises
    ------
    MissingExtraError
        If ``mcap`` or ``mcap-ros2-support`` is not installed (extra ``ros``).
    """
    require_extra("mcap", "ros", "the mcap step")
    return require_extra("mcap_ros2.writer", "ros", "the mcap step")


def session_epoch_ns(session) -> int:
    """Wall-clock time of the session's first frame [ns since 1970]; 0 when unknown.

    Parameters
    ----------
    session : Session
        A session; ``meta["start_time_utc"]`` (ISO 8601, µs) gives the time.
    """
    start = session.meta.get("start_time_utc")
    if not start:
        return 0
    try:
        t = _dt.datetime.strptime(str(start).rstrip("Z"), "%Y-%m-%dT%H:%M:%S.%f")
    except ValueError:
        return 0
    # integer arithmetic: a float of seconds since 1970 resolves only about 0.2 µs
    since = t.replace(tzinfo=_dt.timezone.utc) - _dt.datetime(1970, 1, 1, tzinfo=_dt.timezone.utc)
    return ((since.days * 86_400 + since.seconds) * 1_000_000 + since.microseconds) * 1_000


def frame_stamps_ns(session) -> np.ndarray:
    """Time stamp of every frame [ns since 1970] (see the module docstring).

    Parameters
    ----------
    session : Session
        The session whose frames are stamped.
    """
    t = np.asarray(session.t_s, dtype=float)
    epoch = session_epoch_ns(session)
    rel = t - t[0] if epoch and t.size else t
    stamps = epoch + np.round(rel * 1e9).astype(np.int64)
    if stamps.size and stamps.min() < 0:
        raise SessionError(f"{session.source or 'session'}: t_s: negative times cannot be ROS time stamps")
    return stamps


def _header(stamp_ns: int) -> dict:
    sec, nanosec = divmod(int(stamp_ns), 1_000_000_000)
    return {"stamp": {"sec": sec, "nanosec": nanosec}, "frame_id": FRAME_ID}


def _vec(x: float, y: float) -> dict:
    return {"x": float(x), "y": float(y), "z": 0.0}


def _tangent_quaternions(positions_m: np.ndarray) -> np.ndarray:
    """Orientation of every point of a shape, ``(M, 4)`` quaternions ``(x, y, z, w)``.

    The tangent angle φ is measured from ``+y`` toward ``+x`` (DESIGN.md), so in ROS's
    convention (yaw from ``+x`` counter-clockwise) the yaw is ``π/2 − φ``.
    """
    d = np.gradient(positions_m, axis=0)
    yaw = np.arctan2(d[:, 1], d[:, 0])
    q = np.zeros((len(yaw), 4))
    q[:, 2] = np.sin(yaw / 2)
    q[:, 3] = np.cos(yaw / 2)
    return q


def write_mcap(path, session, shape, estimate=None, *, track=None, overwrite: bool = False) -> Path:
    """Write a processed session as ROS 2 messages to an MCAP file.

    Parameters
    ----------
    path : path
        Output ``.mcap`` file; written atomically (complete or not at all).
    session : Session
        The input session (time, pressure).
    shape : Shape
        Reconstructed shapes, batch axis over the session's frames.
    estimate : ForceEstimate, optional
        Force estimates of the same frames; without it no force topics are written. Of a
        contact load: the contact point on ``/bendsense/contact`` too.
    track : Track, optional
        Tracked forces of the same frames (:func:`bendsense.track`); without it no
        tracked topics are written.
    overwrite : bool
        Replace an existing file; otherwise :class:`~bendsense.errors.OutputExistsError`.

    Returns
    -------
    Path
        ``path``.

    Raises
    ------
    MissingExtraError
        If ``mcap`` or ``mcap-ros2-support`` is not installed (extra ``ros``).
    """
    return write_mcap_fingers(path, {None: (session, shape, estimate, track)}, overwrite=overwrite)


def finger_topic(finger: str | None, topic: str) -> str:
    """The topic ``topic`` (a key of :data:`TOPICS`) of ``finger``: ``/bendsense/<finger>/<topic>`` (None: TOPICS).

    Parameters
    ----------
    finger : str or None
        A gripper finger's name, or None for a single actuator.
    topic : str
        ``wrench``, ``shape``, ``pressure``, ``contact``, ...
    """
    return TOPICS[topic] if finger is None else f"/bendsense/{finger}/{topic}"


class _Part:
    """One actuator's messages: its results, topics and contact points."""

    def __init__(self, finger, session, shape, estimate, track):
        from bendsense.results import Results
        from bendsense.results.contact import point_on_shape, resolved

        self.results = Results.from_state(session, shape, estimate, track)
        self.cols = self.results.columns
        self.positions = self.results.positions_m
        self.topics = {key: finger_topic(finger, key) for key in TOPICS}
        self.status_name = "bendsense/force" if finger is None else f"bendsense/{finger}/force"
        self.contact = None
        if self.results.has_contact:  # the point at s_c on the drawn shape; a frame without a resolved location: none
            cols = self.cols
            self.contact = point_on_shape(self.results.s_m, self.positions, cols["contact_s_m"])
            self.contact[~resolved(cols["contact_s_m"], cols["contact_std_m"])] = np.nan


def write_mcap_fingers(path, parts: dict, *, overwrite: bool = False) -> Path:
    """Write several actuators of one board (a gripper's fingers) as ROS 2 messages to one MCAP file.

    Each finger's messages go to its own topics, ``/bendsense/<finger>/wrench``,
    ``/bendsense/<finger>/shape``, ``/bendsense/<finger>/pressure``,
    ``/bendsense/<finger>/contact``, ... (the topics of :data:`TOPICS` under the
    finger's name), with the same messages as :func:`write_mcap` writes for one
    actuator; the key ``None`` writes the single actuator's topics.

    Parameters
    ----------
    path : path
        Output ``.mcap`` file; written atomically.
    parts : dict
        ``{finger name or None: (session, shape, estimate or None, track or None)}``;
        the sessions share their frames (one board).
    overwrite : bool
        Replace an existing file.
    """
    writer_mod = require_ros()

    path = Path(path)
    items = [_Part(finger, *part) for finger, part in parts.items()]
    session = next(iter(parts.values()))[0]
    stamps = frame_stamps_ns(session)
    device = session.meta.get("device")
    hardware_id = str(device.get("firmware", "")) if isinstance(device, dict) else ""
    with output.write_file(path, overwrite=overwrite, suffixes=MCAP, writer="bendsense mcap") as tmp, \
            open(tmp, "wb") as fh:
        writer = writer_mod.Writer(fh)
        writer._writer.add_metadata("bendsense", {"written_by": "bendsense mcap"})  # the mark (output.MARK)
        contact = any(item.contact is not None for item in items)
        schemas = {name: writer.register_msgdef(name, text) for name, text in SCHEMAS.items()
                   if name != POINT_STAMPED or contact}
        for k, stamp in enumerate(stamps.tolist()):
            for item in items:
                _write_frame(writer, schemas, item, k, stamp, hardware_id)
        writer.finish()
    return path


def _write_frame(writer, schemas, item: _Part, k: int, stamp: int, hardware_id: str) -> None:
    """Frame ``k``'s messages of one actuator."""
    header = _header(stamp)
    results, cols, contact = item.results, item.cols, item.contact

    def write(topic, schema, message):
        writer.write_message(item.topics[topic], schemas[schema], message, log_time=stamp, publish_time=stamp,
                             sequence=k)

    if results.has_forces:
        write("wrench", "geometry_msgs/msg/WrenchStamped",
              {"header": header, "wrench": {"force": _vec(cols["fx_n"][k], cols["fy_n"][k]),
                                            "torque": _vec(0.0, 0.0)}})
        write("force_std", "geometry_msgs/msg/Vector3Stamped",
              {"header": header, "vector": _vec(cols["fx_std_n"][k], cols["fy_std_n"][k])})
    if results.has_track:
        write("wrench_tracked", "geometry_msgs/msg/WrenchStamped",
              {"header": header, "wrench": {"force": _vec(cols["fx_track_n"][k], cols["fy_track_n"][k]),
                                            "torque": _vec(0.0, 0.0)}})
        write("force_tracked_std", "geometry_msgs/msg/Vector3Stamped",
              {"header": header, "vector": _vec(cols["fx_track_std_n"][k], cols["fy_track_std_n"][k])})
    status = str(cols["status"][k])
    values = {"status": status}
    if results.has_forces:
        values.update({name: repr(float(cols[name][k])) for name in ("fx_std_n", "fy_std_n", "residual_m")})
    if contact is not None:
        values.update({name: repr(float(cols[name][k])) for name in ("contact_s_m", "contact_std_m")})
        if np.isfinite(contact[k]).all():
            write("contact", POINT_STAMPED, {"header": header, "point": _vec(*contact[k])})
    if results.has_track:
        values["track_status"] = str(cols["track_status"][k])
    if "window_p_value" in cols:
        values["window_p_value"] = repr(float(cols["window_p_value"][k]))
    write("status", "diagnostic_msgs/msg/DiagnosticArray", {"header": header, "status": [{
        "level": _LEVEL.get(status, 1), "name": item.status_name, "message": status,
        "hardware_id": hardware_id,
        "values": [{"key": key, "value": value} for key, value in values.items()],
    }]})
    positions = item.positions
    q = _tangent_quaternions(positions[k])
    poses = [
        {"header": header, "pose": {"position": _vec(x, y),
                                    "orientation": {"x": 0.0, "y": 0.0, "z": qz, "w": qw}}}
        for (x, y), qz, qw in zip(positions[k].tolist(), q[:, 2].tolist(), q[:, 3].tolist())
    ]
    write("shape", "nav_msgs/msg/Path", {"header": header, "poses": poses})
    p = float(cols["pressure_pa"][k])
    if math.isfinite(p):
        write("pressure", "sensor_msgs/msg/FluidPressure",
              {"header": header, "fluid_pressure": p, "variance": 0.0})
