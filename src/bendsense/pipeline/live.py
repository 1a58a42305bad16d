"""The live path: blocks of frames, as they arrive, through one compiled call per finger.

:class:`LiveProcessor` is the core of ``bendsense record --estimate``, ``live``,
``control`` and the ``--lsl`` streams. It turns a block of frames (raw signals and
pressure) into their shapes, tip forces, track and statuses, warm-started from the last
good estimate of the previous block, and returns a :class:`LiveBlock` whose
:meth:`~LiveBlock.columns` are those of ``results.csv``. A single frame is a block of
one; there is no second, one-frame code path.

A block goes through :func:`bendsense.pipeline._kernels.live_block`, one compiled call
on the processor's state (DESIGN.md section 2c), which strings together the offline
chain's own kernels; Python touches the block once. The block's ``shape``, ``estimate``
and ``track`` objects are made of its arrays only when asked for. Options the compiled
step does not run (the paper's method, a contact located per frame) go through
:func:`bendsense.estimation.estimate_force` and :class:`bendsense.tracking.Tracker`.
"""

from __future__ import annotations

import functools
import logging
import math
import time
import warnings
from dataclasses import dataclass

import numpy as np

from bendsense import _jit
from bendsense._batched import concat_frames, expand_frames, put_frames, take_frames
from bendsense.errors import ArgumentError, ConfigError, DataWarning
from bendsense.estimation import _kernels as est_kernels
from bendsense.estimation import estimation_options
from bendsense.pipeline._kernels import live_block
from bendsense.pipeline.readings import ReadingClock
from bendsense.results import WINDOW_MISFIT
from bendsense.status import MISFIT_P, WORDS, Status, words

log = logging.getLogger("bendsense")

__all__ = ["LIVE_MAX_ITER", "LiveBlock", "LiveFrame", "LiveProcessor"]

#: Iteration limit of a live force estimate. A warm-started frame converges in a few
#: iterations; one that cannot (an unconstrained axial force on the straight actuator
#: does not change its shape) must not stall the stream for 100 beam solves.
LIVE_MAX_ITER = 20


@dataclass(frozen=True, eq=False)
class LiveFrame:
    """One processed frame (a view of one frame of a :class:`LiveBlock`).

    Attributes
    ----------
    seq : int
        Device sequence number (raw, wraps at 65536); -1 if unknown.
    t_s : float
        Device clock [s] (from the first frame the processor saw, when given readings).
    host_ns : int
        Host clock when the frame's bytes were read (``time.monotonic_ns()``) [ns].
    pressure_pa : float
        Pressure [Pa]; NaN without a reading (no force estimate then).
    delta_a : ndarray, shape (N,)
        Offset-free signals ΔA = A − A0 (paper eq. 1) [signal units].
    shape : Shape
        Reconstructed shape of the frame (single frame, no batch axis).
    estimate : ForceEstimate or None
        Tip force of the frame; None without pressure or with estimation off.
    process_s : float
        Wall time of reconstruction and estimation of its block, per frame [s].
    status : str
        The frame's ``status`` in ``results.csv``.
    track_force_n, track_std_n : ndarray, shape (2,) or None
        The causally tracked force and its standard deviation [N] (``fx_track_n``, ...);
        None when the processor does not track.
    """

    seq: int
    t_s: float
    host_ns: int
    pressure_pa: float
    delta_a: np.ndarray
    shape: object
    estimate: object
    process_s: float
    status: str = "ok"
    track_force_n: np.ndarray | None = None
    track_std_n: np.ndarray | None = None

    @property
    def force_n(self) -> np.ndarray:
        """Tip force (Fx, Fy) [N]; NaN when not estimated or not converged."""
        if self.estimate is None:
            return np.full(2, np.nan)
        return np.asarray(self.estimate.force_n, dtype=float)

    @property
    def std_n(self) -> np.ndarray:
        """Standard deviation of (Fx, Fy) [N]; NaN when not estimated."""
        if self.estimate is None:
            return np.full(2, np.nan)
        return np.asarray(self.estimate.std_n, dtype=float)


class _Arrays:
    """A block's outputs of the compiled step (:func:`bendsense.pipeline._kernels.live_block`): its four buffers.

    Each output is a run of one buffer (:func:`_fields`); its array, a view, is made when asked for.
    """

    __slots__ = ("step", "buffers", "layout", "t", "has_estimate", "has_track")

    def __init__(self, step, buffers, layout, t):
        self.step = step  # the processor's _Step: the constants, and how to make objects of the arrays
        self.buffers = buffers  # float64, int64, bool, int8: live_block's f, ints, bools, codes
        self.layout = layout  # output group → ((buffer, start, stop, shape), ...), in the group's order
        self.t = t  # the frames' times [s]
        self.has_estimate = self.has_track = False  # whether the step estimated a frame, and tracked: counted()

    def counted(self):
        """Read the counts after the step's calls: whether it estimated a frame (and so tracked, if it tracks)."""
        self.has_estimate = bool(self.buffers[1][0] > 0)
        self.has_track = self.has_estimate and self.step.tracking

    def field(self, group, index):
        """Output ``index`` of ``group`` (``"shape"``, ``"estimate"``, ``"track"``, ``"status"``, ``"counts"``)."""
        b, start, stop, shape = self.layout[group][index]
        return self.buffers[b][start:stop].reshape(shape)

    def group(self, group):
        """The outputs of ``group``, as :func:`~bendsense.pipeline._kernels.live_block` has them."""
        return tuple(self.buffers[b][start:stop].reshape(shape) for b, start, stop, shape in self.layout[group])

    def put(self, piece, lo, hi):
        """The outputs of another call (``piece``, frames ``lo:hi`` of these) into these; its counts added."""
        for group, fields in self.layout.items():
            for index in range(len(fields)):
                if group == "counts":
                    self.field(group, index)[...] += piece.field(group, index)
                else:
                    self.field(group, index)[lo:hi] = piece.field(group, index)


class LiveBlock:
    """Shapes and force estimates of a block of consecutive frames.

    Attributes
    ----------
    t_s : ndarray, shape (n,)
        Frame time [s].
    seq : ndarray of int, shape (n,)
        Raw sequence numbers (-1 unknown).
    host_ns : ndarray of int, shape (n,)
        Arrival time of each frame on the host clock (``time.monotonic_ns()``) [ns].
    pressure_pa : ndarray, shape (n,)
        Pressure used [Pa] (the reading, else the processor's fallback); NaN: none.
    signals : ndarray, shape (n, N)
        Raw signals A [signal units].
    shape : Shape
        Shapes, batch axis n.
    estimate : ForceEstimate or None
        Forces, batch axis n; None when estimation is off or no frame has a pressure.
    estimated : bool
        Whether the processor estimates forces (the force columns are then present,
        NaN where there is no estimate).
    process_s : float
        Wall time of the block's reconstruction and estimation [s].
    offset : ndarray, shape (N,)
        The calibration's offsets A0 (for ΔA).
    track : Track or None
        The causally tracked forces of the block (:class:`bendsense.tracking.Tracker`); None when
        the processor does not track or no frame of the block has a force estimate.
    tracked : bool
        Whether the processor tracks the forces (the tracked columns are then present,
        NaN where there is no track).
    load : str
        The processor's load model (``"contact"``: the columns ``contact_s_m, contact_std_m``).
    extra : dict of str to ndarray, shape (n,)
        Per-frame columns the recorded session has beside its own (``Session.extra``:
        ``host_s``, ``status``, ``tx_drops`` of a recording), written after ``status``
        as ``save`` writes them.

    A block of the compiled live step (:mod:`bendsense.pipeline._kernels`) holds the
    step's arrays; its ``shape``, ``estimate`` and ``track`` objects are made from them
    when first asked for (a control loop reads the arrays only).
    """

    def __init__(self, t_s, seq, host_ns, pressure_pa, signals, shape, estimate, estimated, process_s, offset=None,
                 track=None, tracked=False, load="tip", extra=None):
        self.t_s, self.seq, self.host_ns, self.pressure_pa, self.signals = t_s, seq, host_ns, pressure_pa, signals
        self._shape, self._estimate, self._track = shape, estimate, track
        self.estimated, self.process_s, self.offset, self.tracked, self.load = (estimated, process_s, offset, tracked,
                                                                                load)
        self._extra, self._extra_given = {}, {} if extra is None else extra
        self._step = None  # the compiled step's outputs and how to make the objects of them

    @classmethod
    def _of_step(cls, arrays, *, t_s, seq, host_ns, pressure_pa, signals, process_s):
        """The block of the live step's outputs (:func:`bendsense.pipeline._kernels.live_block`, :class:`_Arrays`)."""
        step = arrays.step
        block = cls(t_s, seq, host_ns, pressure_pa, signals, None, None, step.estimating, process_s,
                    offset=step.offset, tracked=step.tracking, load=step.load)
        block._step = arrays
        block.__dict__["status"] = arrays.field("status", 0)
        return block

    @property
    def extra(self) -> dict:
        """Per-frame columns the recorded session has beside its own (n,) each (read when first asked for)."""
        if self._extra_given is not None:
            self._extra, self._extra_given = {k: np.asarray(v) for k, v in self._extra_given.items()}, None
        return self._extra

    @property
    def shape(self):
        """Shapes, batch axis n (:class:`~bendsense.shape.pcc.Shape`)."""
        if self._shape is None and self._step is not None:
            self._shape = self._step.step.shape_of(self._step.group("shape"))
        return self._shape

    @property
    def estimate(self):
        """Forces, batch axis n (:class:`~bendsense.ForceEstimate`); None without an estimate."""
        if self._estimate is None and self._step is not None and self._step.has_estimate:
            self._estimate = self._step.step.estimate_of(self._step.group("estimate"), self.pressure_pa, self.process_s)
        return self._estimate

    @property
    def track(self):
        """The causally tracked forces (:class:`~bendsense.tracking.Track`); None without a track."""
        if self._track is None and self._step is not None and self._step.has_track:
            arrays = self._step
            self._track = arrays.step.track_of(arrays.group("track"), arrays.field("estimate", 0), arrays.t)
        return self._track

    @property
    def window_p_value(self) -> np.ndarray | None:
        """Each frame's p-value of the latest completed window (n,) (the Tracker's); None untracked."""
        if self._step is not None:
            return self._step.field("track", 3) if self._step.has_track else None
        return None if self.track is None else np.asarray(self.track.window_p_value, dtype=float)

    @property
    def track_covariance_n2(self) -> np.ndarray:
        """Covariances of the tracked forces (n, 2, 2) [N²]; NaN where not tracked."""
        return self._frames("track", 2, "track", "covariance_n2", (2, 2))

    @property
    def track_status(self) -> np.ndarray | None:
        """The tracked frames' status codes (n,) of int8; None without a track."""
        if self._step is not None:
            return self._step.field("track", 4) if self._step.has_track else None
        return None if self.track is None else np.asarray(self.track.status).reshape(len(self))

    @property
    def covariance_n2(self) -> np.ndarray:
        """Covariances of the forces (n, 2, 2) [N²]; NaN where not estimated."""
        return self._frames("estimate", 1, "estimate", "covariance_n2", (2, 2))

    @property
    def contact_s_m(self) -> np.ndarray:
        """The contact location of each frame (n,) [m]: NaN for a tip load or a frame without an estimate."""
        if self._step is not None:
            c = self._step.step.contact_s_m
            return np.full(len(self), np.nan if c is None or not self._step.has_estimate else float(c))
        est = self.estimate
        if est is None or getattr(est, "load", "tip") != "contact" or est.contact_s_m is None:
            return np.full(len(self), np.nan)
        return np.broadcast_to(np.asarray(est.contact_s_m, dtype=float), (len(self),)).copy()

    @property
    def s_m(self) -> np.ndarray:
        """Arc lengths (M,) of the shapes' points [m]."""
        return self._step.step.grid.s if self._step is not None else np.asarray(self.shape.s_m, dtype=float)

    @property
    def angle_rad(self) -> np.ndarray:
        """Tangent angles (n, M) of the shapes at their points ``shape.s_m`` [rad]."""
        if self._step is not None:
            return self._step.field("shape", 2)
        return np.asarray(self.shape.angle_rad, dtype=float).reshape(len(self), -1)

    def __len__(self) -> int:
        return self.t_s.size

    def _frames(self, part, index, source, name, tail):
        """A per-frame array (n, *tail): the compiled step's ``part[index]``, else ``source.name``; else NaN."""
        arrays = self._step
        if arrays is not None and (arrays.has_track if part == "track" else arrays.has_estimate):
            return arrays.field(part, index)
        obj = getattr(self, source)
        if obj is None:
            return np.full((len(self), *tail), np.nan)
        return np.asarray(getattr(obj, name), dtype=float).reshape(len(self), *tail)

    @property
    def track_force_n(self) -> np.ndarray:
        """Tracked tip forces (n, 2) [N]; NaN where not tracked."""
        return self._frames("track", 0, "track", "force_n", (2,))

    @property
    def track_std_n(self) -> np.ndarray:
        """Standard deviations of the tracked forces (n, 2) [N]; NaN where not tracked."""
        return self._frames("track", 1, "track", "std_n", (2,))

    @property
    def force_n(self) -> np.ndarray:
        """Tip forces (n, 2) [N]; NaN where not estimated or not converged."""
        return self._frames("estimate", 0, "estimate", "force_n", (2,))

    @property
    def std_n(self) -> np.ndarray:
        """Standard deviations of the forces (n, 2) [N]; NaN where not estimated."""
        return self._frames("estimate", 11, "estimate", "std_n", (2,))

    @functools.cached_property
    def status(self) -> np.ndarray:
        """Per-frame status codes (n,) of int8 (:class:`bendsense.status.Status`).

        Those of :func:`bendsense.results.frame_codes`, and ``NO_PRESSURE`` for frames
        without pressure when forces are estimated. Their words are results.csv's ``status``.
        Worked out once per block (the processor counts them, the loop reads them).
        """
        from bendsense.results import frame_codes

        status = frame_codes(self.shape, self.estimate)
        if self.estimated:
            status[~np.isfinite(self.pressure_pa)] = Status.NO_PRESSURE
        return status

    def columns(self) -> dict:
        """The columns of ``results.csv`` for these frames (those of ``bendsense ... save``)."""
        from bendsense.results import TRACK_COLUMNS, WINDOW_COLUMN, Results, tracked_columns
        from bendsense.results.contact import CONTACT_COLUMNS
        from bendsense.session import Session

        session = Session(self.t_s, self.signals, self.pressure_pa, extra=self.extra)
        results = Results.from_state(session, self.shape, self.estimate, self.track)
        columns = results.columns
        status = self.status
        if self.estimated and self.estimate is None:  # no frame with pressure: NaN forces, in save's order
            extra = {name: columns.pop(name) for name in results.extra_names}
            columns.pop("status")
            nan = np.full(len(self), np.nan)
            contact = CONTACT_COLUMNS if self.load == "contact" else ()
            columns.update({name: nan for name in ("fx_n", "fy_n", "fx_std_n", "fy_std_n", *contact, "residual_m")})
            columns["status"] = None
            if self.tracked:
                columns.update({name: nan for name in TRACK_COLUMNS[:4]})
                columns.update({"track_status": words(status), WINDOW_COLUMN: nan})
            columns.update(extra)
        elif self.track is not None:  # the frames without pressure: that status, not the estimate's
            columns.update(tracked_columns(len(self), self.estimate, self.track, status))
        columns["status"] = words(status)
        return columns

    def frame(self, i: int = -1) -> LiveFrame:
        """Frame ``i`` of the block as a :class:`LiveFrame`.

        Parameters
        ----------
        i : int, default -1
            Index of the frame in the block (-1: the newest).
        """
        n = len(self)
        i = range(n)[i]
        est = None
        if self.estimate is not None and np.isfinite(self.pressure_pa[i]):
            est = take_frames(self.estimate, i, n)
        return LiveFrame(seq=int(self.seq[i]), t_s=float(self.t_s[i]), host_ns=int(self.host_ns[i]),
                         pressure_pa=float(self.pressure_pa[i]), delta_a=self.signals[i] - self.offset,
                         shape=take_frames(self.shape, i, n), estimate=est, process_s=self.process_s / n,
                         status=Status(self.status[i]).word,
                         track_force_n=self.track_force_n[i] if self.tracked else None,
                         track_std_n=self.track_std_n[i] if self.tracked else None)


_PIECE = 4096  # frames per call of the compiled step (~0.3 s)
_WORD_OF = tuple(str(word) for word in WORDS)  # each status code's word, as a str
_GENERAL = object()  # a processor whose options need estimate_force (the paper's method, a contact located per frame)


def frame_times(n, t_s=None, seq=None, host_ns=None):
    """A block's per-frame columns as arrays (n,): ``t_s``, ``seq``, ``host_ns``, and the times the track runs on.

    Defaults: ``t_s`` NaN, ``seq`` -1, ``host_ns`` now; the track's times are ``t_s``, the
    host's clock [s] for frames without a device time.
    """
    t_s = np.full(n, np.nan) if t_s is None else np.asarray(t_s, dtype=float)
    host_ns = np.asarray(np.full(n, time.monotonic_ns()) if host_ns is None else host_ns, dtype=np.int64)
    seq = np.full(n, -1, dtype=np.int64) if seq is None else np.asarray(seq, dtype=np.int64)
    t = t_s
    if not (math.isfinite(t_s[0]) if n == 1 else np.isfinite(t_s).all()):
        t = np.where(np.isfinite(t_s), t_s, host_ns * 1e-9)
    return t_s, seq, host_ns, t


def _fields(N, M, R, nodes):
    """The compiled step's outputs as :func:`bendsense.pipeline._kernels.carve` lays them in its four buffers.

    In the buffers' order: (group, index in the group, buffer (0 float64, 1 int64, 2 bool,
    3 int8), rows (``"n"`` the block's frames, ``"e"`` those estimated, or a number), shape
    of a row) for ``N`` channels, ``M`` points of a shape, ``R`` coils fitted and ``nodes``
    of the beam.
    """
    est = ((0, (2,)), (1, (2, 2)), (4, ()), (5, ()), (6, ()), (7, (2,)), (8, (nodes,)), (9, (2,)), (10, (2,)),
           (11, (2,)), (12, (3, 2, 2)), (14, (R, 6)), (15, (N,)))
    return (*[("shape", i, 0, "n", tail) for i, tail in enumerate(((N,), (M, 2), (M,), (2,), ()))],
            *[("estimate", i, 0, "e", tail) for i, tail in est],
            *[("track", i, 0, "n", tail) for i, tail in enumerate(((2,), (2,), (2, 2), ()))],
            ("counts", 0, 1, 5, ()), ("estimate", 2, 1, "e", ()), ("estimate", 3, 1, "e", ()),
            ("shape", 5, 2, "n", ()), ("estimate", 13, 2, "e", ()), ("track", 4, 3, "n", ()), ("status", 0, 3, "n", ()))


def _layout(fields, n, e):
    """The buffers' sizes and each output's run of them for a block of ``n`` frames, ``e`` of them estimated."""
    ends = [0, 0, 0, 0]
    groups = {}
    for group, index, buffer, rows, tail in fields:
        shape = ({"n": n, "e": e}.get(rows, rows), *tail)
        size = math.prod(shape)
        groups.setdefault(group, {})[index] = (buffer, ends[buffer], ends[buffer] + size, shape)
        ends[buffer] += size
    return tuple(ends), {g: tuple(runs[i] for i in range(len(runs))) for g, runs in groups.items()}


class _Step:
    """The constants of a processor's compiled live step (:func:`bendsense.pipeline._kernels.live_block`).

    Made once per config (an adapting processor makes a new one when its config changes);
    it also makes a block's objects of the step's arrays, on demand.
    """

    def __init__(self, processor, est):
        from bendsense.shape.pcc import _grid, calibration_args
        from bendsense.tracking import Tracker

        config = processor.config
        sensor = config.sensor
        self.config = config
        self.grid = _grid(sensor.lengths_m, processor.s_m)
        self.shape = (*calibration_args(processor.calibration, sensor),
                      np.ascontiguousarray(self.grid.seg, dtype=np.int64),
                      np.ascontiguousarray(self.grid.sigma, dtype=float))
        self.offset = self.shape[0]
        self.est = est
        self.estimating, self.tracking = processor.estimate, processor.track
        self.constraint = processor.constraint
        self.load = processor.options.get("load", "tip")
        self.contact_s_m = processor.options.get("contact_s_m")
        self.bandwidth_hz = processor.tracker.bandwidth_hz if processor.tracker is not None else None
        R, N = int(est.pb.coils.size), sensor.n_segments
        self.sizes = (R, N)
        self._fields = _fields(N, self.grid.s.size, R, int(est.problem[2]))
        self._layouts = {}  # block size → the outputs' layout (_layout)
        self.idle_tracker = Tracker().stream_state(np.zeros(1), R, N)  # what a processor that does not track passes
        # the window test: a fit of the coil angles with a noise model (what Tracker.update checks)
        windows = est.objective == "angles" and est.uncertainty == "propagated"
        window_model = (est.problem[0][1], est.pb.coils, float(est.pb.gap))
        flags = (bool(self.estimating), bool(self.tracking), bool(windows))
        self._held = (self.shape, est.model, est.problem, flags, window_model)
        self._hold()

    def _hold(self):
        """Hold the constants as the step takes them, the estimate's inside (:func:`est_kernels.hold_estimate`)."""
        shape, model, problem, flags, window_model = self._held
        estimate = (_jit.call(est_kernels.hold_estimate, problem[0]), *problem[1:])
        self.constants = _jit.call(est_kernels.hold, (shape, model, estimate, flags, window_model))

    def __getstate__(self):
        # numba's typed list does not pickle (a copied or pickled processor): it is made again of its parts
        return {k: v for k, v in self.__dict__.items() if k != "constants"}

    def __setstate__(self, state):
        self.__dict__.update(state)
        self._hold()

    def outputs(self, n):
        """The compiled step's four buffers for a block of ``n`` frames (filled by the step), and their layout.

        :func:`bendsense.pipeline._kernels.live_block` fills the buffers, :class:`_Arrays` reads them.
        """
        layout = self._layouts.get(n)
        if layout is None:
            if len(self._layouts) >= 64:  # a loop's blocks of many sizes: keep the latest
                self._layouts.clear()
            layout = self._layouts[n] = _layout(self._fields, n, n if self.estimating else 0)
        (nf, ni, nb, nc), runs = layout
        # the counts start at zero: a block of no frames, or of several calls (their counts added), has them so
        return (np.empty(nf), np.zeros(ni, dtype=np.int64), np.empty(nb, dtype=bool), np.empty(nc, dtype=np.int8)), runs

    def shape_of(self, arrays):
        """The :class:`~bendsense.shape.pcc.Shape` of the step's shape arrays."""
        from bendsense.shape.pcc import shape_of

        return shape_of(arrays, self.grid, (arrays[4].size,))

    def estimate_of(self, out, pressure_pa, process_s):
        """The :class:`~bendsense.ForceEstimate` of the step's estimate outputs."""
        from bendsense.estimation import compiled_estimate

        return compiled_estimate(self.est, out, pressure_pa, self.config, constraint=self.constraint, load=self.load,
                                 contact_s_m=self.contact_s_m, wall_time_s=process_s)

    def track_of(self, arrays, frame_force, t):
        """The :class:`~bendsense.tracking.Track` of the step's track arrays (``frame_force``: the estimate's)."""
        from bendsense.tracking import Track

        force, std, cov, window_p, status = arrays
        return Track(force_n=force, std_n=std, covariance_n2=cov, window_p_value=window_p, status=status,
                     bandwidth_hz=self.bandwidth_hz, mode="filter", t_s=t, frame_force_n=frame_force)


class LiveProcessor:
    """Turn frames into shapes and tip forces as they arrive, a block at a time, warm-started.

    Parameters
    ----------
    calibration : Calibration
        Signal → shift calibration (paper eq. 1–2).
    config : Config, optional
        Sensor, actuator and estimation options; default the paper's prototype.
    constraint : str, optional
        Force constraint (:data:`bendsense.estimation.CONSTRAINTS`); default
        ``config.estimation.constraint``.
    method : str, optional
        Estimator; default ``config.estimation.method``.
    objective : str, optional
        What the fit compares (:data:`bendsense.estimation.OBJECTIVES`); default
        ``config.estimation.objective``.
    pressure_pa : float, optional
        Pressure for frames without a reading [Pa]; without it such frames get a
        shape only (status ``no_pressure``).
    n_points : int
        Points of each shape along the sensor.
    estimate : bool
        Estimate the force (False: shapes only).
    track : bool, default True
        Track the forces causally (:class:`bendsense.tracking.Tracker`, a Kalman filter over the
        per-frame estimates, its state kept across blocks): :attr:`LiveBlock.track`.
    bandwidth_hz : float, optional
        Bandwidth of the track [Hz]; None: the tracker's default.
    window_s : float, default 0.05
        Window of the streaming model check [s].
    adapt : bool, default False
        Learn the free-bending model from the stream's free frames as it runs
        (:class:`~bendsense.estimation.live_adapt.LiveAdaptation`, :attr:`adaptation`).
    **options
        Further options of :func:`bendsense.estimation.estimate_force` (``push_only``,
        ``tip_angle_source``, ...). ``max_iter`` defaults to :data:`LIVE_MAX_ITER`.

    Attributes
    ----------
    config : Config
        The config of the next block (with ``adapt``: the latest adapted one).
    adaptation : LiveAdaptation or None
        What ``adapt`` learned (None without it).
    frames : int
        Frames processed.
    failures : int
        Frames whose force estimate did not converge.
    estimated : int
        Frames whose force was estimated (those with a pressure).
    status_counts : dict of str to int
        Frames per status (``ok``, ``extrapolated``, ``not_converged``, ...), and
        ``window_misfit``: frames tracked while the latest completed window failed the
        window test (``window_p_value`` < 0.001).
    """

    def __init__(self, calibration, config=None, *, constraint=None, method=None, objective=None, pressure_pa=None,
                 n_points=41, estimate=True, track=True, bandwidth_hz=None, window_s=0.05, adapt=False, **options):
        from bendsense.config import load_config
        from bendsense.estimation.live_adapt import LiveAdaptation

        self.config = load_config() if config is None else config
        sensor = self.config.sensor
        if calibration.n_channels != sensor.n_segments:
            raise ConfigError(
                f"calibration.n_channels: expected {sensor.n_segments} (sensor.n_segments), "
                f"got {calibration.n_channels}"
            )
        self.calibration = calibration
        self.constraint, self.method, self.objective = estimation_options(self.config, constraint, method, objective)
        self.pressure_pa = None if pressure_pa is None else float(pressure_pa)
        self._fallback_told = False
        self.s_m = np.linspace(0.0, sensor.length_m, int(n_points))
        self.estimate = bool(estimate)
        self.track = self.estimate and bool(track)
        self._track_options = {"bandwidth_hz": bandwidth_hz, "window_s": window_s}
        self.tracker = self._new_tracker()
        self._track_t = -math.inf  # the latest frame time tracked [s]
        self.options = {"max_iter": LIVE_MAX_ITER, **options}
        self.frames = 0
        self.failures = 0
        self.estimated = 0
        self.status_counts: dict[str, int] = {}
        self._previous = None
        self._offset = np.zeros(2)  # the compiled step's warm start: the last good frame's offset from its guess [N]
        self._step = None
        self._clock = ReadingClock()
        self.adaptation = LiveAdaptation(calibration, self.config) if adapt else None

    def _new_tracker(self):
        if not self.track:
            return None
        from bendsense.tracking import Tracker

        return Tracker(mode="filter", **self._track_options)

    def reset(self) -> None:
        """Forget the warm start, the track and the time origin (e.g. after a reconnect)."""
        self._previous = None
        self._offset[:] = 0.0
        self._clock.reset()
        self.tracker = self._new_tracker()
        self._track_t = -math.inf

    def _track(self, est, t, p):
        """The block's causal track; a clock that jumps back (a device reset) restarts the track there."""
        n = t.size
        if not (t[0] < self._track_t or (n > 1 and (np.diff(t) < 0).any())):  # the usual block: forward in time
            self._track_t = float(t[-1])
            return self.tracker.update(est, t, p)
        back = np.flatnonzero(np.diff(np.concatenate(([self._track_t], t))) < 0)
        parts = []
        for lo, hi in zip(np.concatenate(([0], back)), np.concatenate((back, [n]))):
            if lo in back:
                log.info("the frame clock went back %.6g s: the track restarts", (t[lo - 1] if lo else
                                                                                  self._track_t) - t[lo])
                self.tracker = self._new_tracker()
            if hi > lo:
                parts.append(self.tracker.update(take_frames(est, slice(lo, hi), n), t[lo:hi], p[lo:hi]))
        self._track_t = float(t[-1])
        return parts[0] if len(parts) == 1 else concat_frames(parts)

    def warm_up(self) -> None:
        """Compile or load the kernels before the first frame arrives, then forget the frames used.

        On the first run after an install the kernels compile (shown on stderr as it goes):
        a recording must not spend that time with a board streaming into a full queue. A
        block of one frame and one of two (a cold frame and a warm-started series: a live
        block never needs the batch kernel of large batches) of the flat calibration
        signals, at the middle of the actuator's pressure range; and the status rules of a
        block's results.csv columns (:mod:`bendsense.results._kernels`), which a recording
        writes.
        """
        from bendsense.results._kernels import compile_kernels

        lo, hi = self.config.actuator.pressure_range_pa
        flat = np.asarray(self.calibration.offset, dtype=float)
        for n in (1, 2):
            self.process_block(np.tile(flat, (n, 1)), np.full(n, 0.5 * (lo + hi)), t_s=np.arange(n) * 1e-3)
        compile_kernels()
        self._forget()
        if self.adaptation is not None:  # its worker started and warmed
            self.adaptation.start()

    def rest_status(self) -> Status:
        """The status of a frame of the actuator at rest (the flat calibration signals, no pressure), then forgotten.

        ``NOT_IDENTIFIABLE``: the constraint leaves the load of a straight actuator undetermined (both
        components free, or a fixed direction along it), so a force loop could not start from rest.
        """
        flat = np.asarray(self.calibration.offset, dtype=float)
        block = self.process_block(flat[None, :], np.zeros(1), t_s=np.zeros(1))
        self._forget()
        return Status(block.status[0])

    def _forget(self) -> None:
        self.reset()
        self.frames = self.failures = self.estimated = 0
        self.status_counts = {}
        if self.adaptation is not None:
            self.adaptation.clear()

    def _estimate(self, shape, p, n):
        """The block's force estimates (None without a pressure or with ``estimate=False``), warm-started."""
        from bendsense.estimation import estimate_force

        has_p = np.isfinite(p)
        if not (self.estimate and has_p.any()):
            return None
        warm = {"initial": self._previous} if self._previous is not None else {}
        sub = shape if has_p.all() else take_frames(shape, has_p, n)
        kwargs = {"constraint": self.constraint, "method": self.method, "objective": self.objective,
                  "calibration": self.calibration, **self.options}
        with warnings.catch_warnings():  # a block of a stream is no session: its pressures are not judged
            warnings.simplefilter("ignore", DataWarning)
            est = estimate_force(sub, p[has_p], self.config, **warm, **kwargs)
        m = int(has_p.sum())
        failed = np.flatnonzero(~np.asarray(est.success).reshape(-1))
        if warm and failed.size:
            # a start far from a frame (a fast change) can fail where its own start converges: retry those cold
            retry = estimate_force(take_frames(sub, failed, m), p[has_p][failed], self.config, **kwargs)
            est = put_frames(est, failed, retry, m)
        ok = np.flatnonzero(np.asarray(est.success).reshape(-1))
        if ok.size:  # a failed frame has NaN forces: it cannot seed the next block
            self._previous = est if m == 1 else take_frames(est, int(ok[-1]), m)
        self.failures += int(np.count_nonzero(~np.asarray(est.success)))
        self.estimated += m
        return est if m == n else expand_frames(est, has_p)

    def _compiled_step(self):
        """The compiled step of this processor's options and config; None where they need :func:`estimate_force`."""
        step = self._step
        if step is not None and (step is _GENERAL or step.config is self.config):
            return None if step is _GENERAL else step
        from bendsense.estimation import compiled

        est = compiled(self.config, self.calibration, self.constraint, self.objective,
                       {"method": self.method, **self.options})
        self._step = _GENERAL if est is None else _Step(self, est)
        return None if est is None else self._step

    def _run_step(self, step, a, p, t):
        """The compiled step's outputs of the block; a clock that goes back (a device reset) restarts the track."""
        n = t.size
        arrays = _Arrays(step, *step.outputs(n), t)
        back = self.track and n and (t[0] < self._track_t or (n > 1 and (np.diff(t) < 0).any()))
        if n and n <= _PIECE and not back:  # the usual block: one call
            parts = ((0, n),)
        else:  # a loop seconds behind: calls of a fraction of a second, so that a stop signal is handled between them
            steps = np.flatnonzero(np.diff(np.concatenate(([self._track_t], t))) < 0) if back else ()
            cuts = [0, *[int(b) for b in steps if b > 0], n]
            parts = [(lo, min(hi, lo + _PIECE)) for lo0, hi in zip(cuts, cuts[1:]) for lo in range(lo0, hi, _PIECE)]
        for lo, hi in parts:
            if back and (t[lo] < (t[lo - 1] if lo else self._track_t)):
                log.info("the frame clock went back %.6g s: the track restarts", (t[lo - 1] if lo else
                                                                                  self._track_t) - t[lo])
                self.tracker = self._new_tracker()
            whole = hi - lo == n  # the usual block: the outputs themselves
            piece = arrays if whole else _Arrays(step, *step.outputs(hi - lo), t[lo:hi])
            ap, pp, tp = (a, p, t) if whole else (a[lo:hi], p[lo:hi], t[lo:hi])
            tracker = self.tracker.stream_state(tp, *step.sizes) if self.track else step.idle_tracker
            _jit.call(live_block, ap, pp, tp, step.constants, self._offset, tracker, *piece.buffers)
            if not whole:
                arrays.put(piece, lo, hi)
            self._track_t = float(tp[-1])
        arrays.counted()
        return arrays

    def process_block(self, signals, pressure_pa=None, *, t_s=None, seq=None, host_ns=None, extra=None) -> LiveBlock:
        """Process a block of consecutive frames.

        Parameters
        ----------
        signals : array_like, shape (n, N)
            Raw signals A [signal units].
        pressure_pa : array_like, shape (n,) or None
            Pressure per frame [Pa]; NaN or None: no reading (the fallback pressure, if
            any, is used).
        t_s, seq, host_ns : array_like, shape (n,), optional
            Frame time [s], sequence numbers, arrival time [ns]; default NaN, -1, now.
        extra : dict of str to array_like, shape (n,), optional
            Further per-frame columns for ``results.csv`` (:attr:`LiveBlock.extra`).

        Returns
        -------
        LiveBlock
        """
        t_start = time.perf_counter()
        a = np.asarray(signals, dtype=float)
        if a.ndim != 2:
            raise ArgumentError(f"signals: expected shape (n, N), got {a.shape}")
        return self._block(a, pressure_pa, *frame_times(a.shape[0], t_s, seq, host_ns), extra, t_start)

    def _block(self, a, pressure_pa, t_s, seq, host_ns, t, extra, t_start) -> LiveBlock:
        """:meth:`process_block` of the signals ``a`` (n, N) and the frames' columns of :func:`frame_times`."""
        n = a.shape[0]
        if pressure_pa is None:
            p = np.full(n, np.nan)
        else:
            p = np.array(pressure_pa, dtype=float, ndmin=1)
            if p.shape != (n,):
                p = np.broadcast_to(p, (n,)).copy()
        if self.pressure_pa is not None:
            self._fill_pressure(p)
        step = self._compiled_step()
        if step is not None:
            if a.shape[1] != step.shape[0].size:
                raise ArgumentError(f"signals: expected {step.shape[0].size} channels on the last axis, got shape "
                                    f"{a.shape}")
            arrays = self._run_step(step, np.ascontiguousarray(a), p, np.ascontiguousarray(t))
            estimated, failed, _, _, misfits = arrays.buffers[1][:5].tolist()
            self.estimated += estimated
            self.failures += failed
            block = LiveBlock._of_step(arrays, t_s=t_s, seq=seq, host_ns=host_ns, pressure_pa=p, signals=a,
                                       process_s=time.perf_counter() - t_start)
        else:
            block = self._general_block(a, p, t_s, seq, host_ns, t, t_start)
            window_p = block.window_p_value
            misfits = None if window_p is None else int(np.count_nonzero(window_p < MISFIT_P))
        if extra is not None:
            block._extra_given = extra
        if self.adaptation is not None:  # an update that finished: its config from the next block on
            self.config = self.adaptation.add(block.shape, p, t) or self.config
        self.frames += n
        self._count(block.status, misfits if block.tracked else None)
        return block

    def _fill_pressure(self, p):
        """The fallback pressure into the frames of ``p`` without a reading (in place)."""
        has = np.isfinite(p)
        if has.any() and not self._fallback_told:
            # once: a fallback that the board's own readings override must not pass silently
            log.warning("the fallback pressure %g kPa is ignored for frames with a pressure reading (the board "
                        "sends one); it fills only frames without", self.pressure_pa / 1e3)
            self._fallback_told = True
        p[~has] = self.pressure_pa

    def _count(self, status, misfits):
        """Count a block's frames by status, and its frames tracked while the latest window failed the test."""
        counts = self.status_counts
        if status.size == 0:
            return
        if status.size == 1 or (status == status[0]).all():  # the usual block: one status
            word = _WORD_OF[status[0]]
            counts[word] = counts.get(word, 0) + status.size
        else:
            codes, numbers = np.unique(status, return_counts=True)
            for word, number in zip(words(codes), numbers):
                counts[word] = counts.get(word, 0) + int(number)
        if misfits is not None:
            counts[WINDOW_MISFIT] = counts.get(WINDOW_MISFIT, 0) + misfits

    def _general_block(self, a, p, t_s, seq, host_ns, t, t_start):
        """The block through ``reconstruct`` and :func:`estimate_force` (the options the step lacks)."""
        from bendsense.shape.pcc import reconstruct

        n = a.shape[0]
        with _jit.serial(n):  # a block of thousands (a loop seconds behind): the kernels warm_up compiled
            shape = reconstruct(a, self.calibration, self.config.sensor, s_m=self.s_m)
            est = self._estimate(shape, p, n)
        track = None
        if self.tracker is not None and est is not None:
            track = self._track(est, t, p)
        return LiveBlock(t_s=t_s, seq=seq, host_ns=host_ns, pressure_pa=p, signals=a, shape=shape, estimate=est,
                         estimated=self.estimate, process_s=time.perf_counter() - t_start,
                         offset=np.asarray(self.calibration.offset, dtype=float), track=track, tracked=self.track,
                         load=self.options.get("load", "tip"))

    def process_readings(self, readings) -> LiveBlock:
        """Process driver readings (:class:`~bendsense.device.driver.Reading`), in arrival order.

        ``t_s`` is the device clock from the first reading this processor saw, and the
        block's :attr:`~LiveBlock.extra` the columns a recording of these readings has
        beside its own (``host_s`` from that first reading, ``status``, ``tx_drops``;
        :func:`bendsense.session.native.records_extra`), as the recorded session gives
        them to ``save``.

        Parameters
        ----------
        readings : list of Reading
            Driver readings, oldest first.
        """
        readings = list(readings)
        if not readings:  # nothing arrived: an empty block
            return self.process_block(np.empty((0, self.calibration.n_channels)), t_s=np.empty(0))
        c = self._clock.columns(readings)
        return self.process_block(c.signals, c.pressure_pa, t_s=c.t_s, seq=c.seq, host_ns=c.host_ns, extra=c.extra)

    def process_signals(self, signals, pressure_pa=None, *, seq=-1, t_s=math.nan, host_ns=None) -> LiveFrame:
        """Process one frame given as raw signals A (N,) and the pressure [Pa] (a block of one).

        Parameters
        ----------
        signals : array_like, shape (N,)
            Raw signals A [signal units].
        pressure_pa : float, optional
            Actuation pressure [Pa]; None or NaN takes the processor's constant pressure, if it has one.
        seq : int, default -1
            Sequence number of the frame.
        t_s : float, default nan
            Time of the frame [s].
        host_ns : int, optional
            Host clock when the frame arrived [ns].
        """
        p = None if pressure_pa is None else [pressure_pa]
        return self.process_block(np.asarray(signals, dtype=float)[None], p, t_s=[t_s], seq=[seq],
                                  host_ns=[time.monotonic_ns() if host_ns is None else host_ns]).frame(0)

    def process(self, reading) -> LiveFrame:
        """Process one :class:`~bendsense.device.driver.Reading`.

        Parameters
        ----------
        reading : Reading
            One driver reading.
        """
        return self.process_readings([reading]).frame(0)

    def process_many(self, readings) -> LiveFrame:
        """Process readings as one block; the newest frame as a :class:`LiveFrame`.

        Parameters
        ----------
        readings : list of Reading
            Driver readings, oldest first.
        """
        return self.process_readings(readings).frame(-1)
