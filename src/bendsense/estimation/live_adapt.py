"""Learn the free-bending model while a live stream runs (``record --estimate --adapt``, ``live``, ``control``).

:class:`LiveAdaptation` is what :class:`bendsense.pipeline.LiveProcessor` does with
``adapt=True``. It keeps a bounded buffer of the stream's frames (segment curvatures,
pressure, time), spread over pressure: :data:`PER_BIN` frames per 1 kPa bin of the
config's pressure range, the newest of each bin. Every :data:`EVERY_S` seconds of
device time, or as soon as :data:`NEW_BINS` bins more are covered than at the last
update, it hands the buffer to one worker process, which runs :func:`bendsense.adapt`
on it: the ORIGINAL config's prior updated by every free frame in the buffer (a frame
counts once, however many updates it sees; ``adapt`` chooses the free frames and
refuses loaded ones). The processor checks for the result without waiting, once per
block, and continues with the adapted config from the next block: the same arrays of
the same shapes, so nothing compiles in the loop. An update that learned nothing
(``adapt`` refused: too few free frames, or a frame selection that did not settle) is
not swapped in. Each update starts from the prior with every frame kept, so a refusal is
the verdict of all of them: an earlier update's config, learned from a part of them
(the first second of a sweep, say), is withdrawn and the loop goes back to the prior.
The config the stream ends with is the last update's, as ``adapt`` on the same frames
offline gives it.

A process and not a thread: the compiled kernels hold the GIL, and an update of a few
hundred frames (0.5–2 s) would stall the loop. The worker is spawned and warmed when
the processor warms up (:meth:`LiveAdaptation.start`), uses one numba and BLAS thread,
ignores Ctrl-C and ends with its parent (as :mod:`bendsense.batch`'s workers do), and
runs at a lower priority (``nice`` 10) than the loop.
"""

from __future__ import annotations

import concurrent.futures as cf
import logging
import math

import numpy as np

log = logging.getLogger("bendsense")

__all__ = ["EVERY_S", "NEW_BINS", "PER_BIN", "LiveAdaptation"]

#: Device time between two updates [s].
EVERY_S = 5.0
#: Pressure bins (1 kPa) newly covered that start an update before :data:`EVERY_S`.
NEW_BINS = 10
#: Frames kept per 1 kPa pressure bin (the newest).
PER_BIN = 4


def _learn(kappa, pressure_pa, t_s, config, calibration, source):
    """The worker's job: :func:`bendsense.adapt` on the buffer.

    Returns (the config, or None when refused; the pressures of its free frames; the report; why it refused).
    """
    from bendsense.identify.sessions import adapt

    result = adapt(kappa, pressure_pa, config, calibration=calibration, t_s=t_s, source=source)
    return (None if result.refused else result.config), pressure_pa[result.free], result.report, result.why


class LiveAdaptation:
    """The free-bending model of a live stream, learned by a worker process between blocks.

    Parameters
    ----------
    calibration : Calibration
        The sensor's calibration (its error model weighs the free frames).
    config : Config
        The actuator, with the prior (``parameter_covariance``) every update starts from.
    source : str
        What the adapted config's provenance names (e.g. ``"live PORT"``).

    Attributes
    ----------
    prior : Config
        The config every update starts from.
    config : Config
        The latest adapted config: ``prior`` until an update learned something, and
        again after a later update (on those frames and more) refused.
    updates : int
        Updates that learned something (withdrawn ones included).
    report : str
        The latest update's report (:attr:`bendsense.identify.sessions.Adaptation.report`).
    why : str
        Why the latest update was not used ("" if it was, or none finished).
    """

    def __init__(self, calibration, config, *, source: str = "a live stream"):
        from bendsense.identify.sessions import _check_prior

        _check_prior(config)
        self.calibration, self.prior, self.config, self.source = calibration, config, config, source
        lo, hi = config.actuator.pressure_range_pa
        self._lo, bins = lo, int(np.ceil((hi - lo) / 1e3)) + 1
        n = config.sensor.n_segments
        self._kappa = np.zeros((bins, PER_BIN, n))
        self._p = np.full((bins, PER_BIN), np.nan)
        self._t = np.zeros((bins, PER_BIN))
        self._next = np.zeros(bins, dtype=int)
        self._pool = self._job = None
        self._job_t = math.nan  # the device time of the newest frame of the update submitted last [s]
        self._last_t, self._last_bins, self._since = None, 0, 0
        self.updates = 0
        self._free_p = np.zeros(0)  # the pressures of the free frames the config learned from [Pa]
        self.report, self.why = "adapt: no update yet", ""

    @property
    def free(self) -> int:
        """Free frames of the config's update (0 while it is the prior)."""
        return self._free_p.size

    def start(self) -> None:
        """Spawn the worker and warm it: an update on a straight actuator over mid pressures (it learns nothing)."""
        from bendsense.stop_signals import worker_pool

        # at a lower priority: the loop and, on a test machine, the simulated board must not wait for an update
        self._pool = worker_pool(1, nice=10)
        lo, hi = self.prior.actuator.pressure_range_pa
        p = np.linspace(lo + 0.2 * (hi - lo), lo + 0.8 * (hi - lo), 8)
        self._pool.submit(_learn, np.zeros((p.size, self.prior.sensor.n_segments)), p, np.arange(p.size) * 1e-3,
                          self.prior, self.calibration, "warm-up").result()

    def clear(self) -> None:
        """Forget the frames kept (and a pending update's result)."""
        self._p[:] = np.nan
        self._next[:] = 0
        self._job, self._last_t, self._last_bins, self._since = None, None, 0, 0

    def add(self, shape, pressure_pa, t_s):
        """Keep a block's usable frames; return the adapted config when an update has just finished, else None.

        Parameters
        ----------
        shape : Shape
            The block's shapes.
        pressure_pa, t_s : ndarray, shape (n,)
            Pressure [Pa] and device time [s] of each frame.
        """
        kappa = np.asarray(shape.curvature_per_m, dtype=float).reshape(len(pressure_pa), -1)
        with np.errstate(invalid="ignore"):
            b = np.floor((pressure_pa - self._lo) / 1e3)
            usable = (np.isfinite(b) & (b >= 0) & (b < self._next.size) & np.all(np.isfinite(kappa), axis=-1)
                      & ~np.broadcast_to(np.asarray(shape.extrapolated, dtype=bool), b.shape))
        rows = np.flatnonzero(usable)
        for k in rows[-PER_BIN * 50:]:  # the newest of a long block (a loop seconds behind)
            i = int(b[k])
            j = self._next[i] % PER_BIN
            self._kappa[i, j], self._p[i, j], self._t[i, j] = kappa[k], pressure_pa[k], t_s[k]
            self._next[i] += 1
        self._since += rows.size
        new = self._result()
        if rows.size and self._job is None and self._due(float(t_s[rows[-1]])):
            self._submit()
        return new

    def _submit(self) -> None:
        """Hand every frame kept to the worker: an update from the prior."""
        keep = np.isfinite(self._p)
        self._job_t = float(self._t[keep].max())
        self._job = self._pool.submit(_learn, self._kappa[keep], self._p[keep], self._t[keep], self.prior,
                                      self.calibration, self.source)
        self._since = 0

    def _due(self, t: float) -> bool:
        """An update is due: :data:`EVERY_S` since the last, or :data:`NEW_BINS` bins newly covered."""
        bins = int(np.count_nonzero(self._next))
        if self._last_t is None:
            self._last_t = t
        if t - self._last_t < EVERY_S and bins - self._last_bins < NEW_BINS:
            return False
        self._last_t, self._last_bins = t, bins
        return True

    def _result(self):
        """The finished update's config (None: none finished, or it learned nothing)."""
        if self._job is None or not self._job.done():
            return None
        job, self._job = self._job, None
        try:
            config, free, self.report, self.why = job.result()
        except Exception as err:  # noqa: BLE001 (a failed update must not stop the stream: the config is kept)
            self.why = f"the update failed ({type(err).__name__}: {err})"
            self.report = f"adapt: {self.why}; the config kept"
            log.warning("%s", self.report)
            return None
        if config is None:
            if self.config is self.prior:
                return None
            self.config, self._free_p = self.prior, np.zeros(0)
            log.info("adapt: the update with the frames up to t = %.3f s refused (%s): the one before it is "
                     "withdrawn, back to the prior", self._job_t, self.why)
            return self.prior
        self.config, self._free_p = config, free
        self.updates += 1
        log.info("adapt: update %d from %d free frames, the newest at t = %.3f s", self.updates, free.size,
                 self._job_t)
        return config

    def close(self, wait: bool = True):
        """The last update (from every frame kept, waited for), then stop the worker; the adapted config, or None.

        Parameters
        ----------
        wait : bool, default True
            False for an interrupted command: no last update; a pending one is cancelled
            and the latest finished one is the answer.
        """
        if self._pool is None:
            return None
        if not wait and self._job is not None and self._job.done():
            self._result()  # an update that finished since the last block
        for _ in range(2 if wait else 0):  # the pending update, then one with the frames that came since
            if self._job is not None:
                cf.wait([self._job])
                self._result()
            if not self._since:
                break
            self._submit()
        # waited for: the process's exit would wait for a running update all the same, and a pool whose manager
        # thread is still winding down races Python's exit hook for its wake-up pipe (an OSError traceback at exit)
        self._pool.shutdown(wait=True, cancel_futures=True)
        self._pool = None
        return None if self.config is self.prior else self.config

    def summary(self) -> str:
        """One line: what was learned (K0 and its sigma before -> after, at the free frames' pressures)."""
        from bendsense.identify.sessions import k0_with_sigma

        if self.config is self.prior:
            withdrawn = f" ({self.updates} earlier update(s) withdrawn)" if self.updates else ""
            return f"adapt: learned nothing, the config's prior kept: {self.why or 'no update finished'}{withdrawn}"
        # at the pressures it learned from, not the buffer's: an update of the first seconds knows nothing above them
        levels = np.unique(np.round(np.percentile(self._free_p, [5, 50, 95]), -3))
        (k0, before), (k1, after) = (k0_with_sigma(c, levels) for c in (self.prior, self.config))
        return (f"adapt: {self.updates} update(s), the latest from {self.free} free frames; K0 " + ", ".join(
            f"{lv / 1e3:.0f} kPa {100 * (b / a - 1):+.1f} % (sigma {100 * sa / abs(a):.1f} % -> "
            f"{100 * sb / abs(b):.1f} %)" for lv, a, b, sa, sb in zip(levels, k0, k1, before, after, strict=True)))
