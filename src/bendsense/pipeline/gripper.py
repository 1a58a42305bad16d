"""A gripper, live: one :class:`~bendsense.pipeline.LiveProcessor` per finger over the board's readings.

A gripper is its fingers (:class:`bendsense.config.GripperConfig`). The board's frames
carry every finger's channels and pressure lines; :class:`GripperProcessor` turns a block
of them into the board's arrays once (:func:`bendsense.pipeline.readings.reading_columns`), splits
them per finger (:func:`bendsense.session.fingers.split_signals`: the finger's channels, its
line's pressure) and runs each finger's own single-actuator processor on its part, with
the same frame times, sequence numbers, arrival times and recording columns. So each
finger's :class:`~bendsense.pipeline.LiveBlock` is exactly what a
:class:`~bendsense.pipeline.LiveProcessor` of that finger gives for the finger's part of
the readings: its warm start, its causal track and its window check are the finger's
own. ``record --estimate``, ``live``, the LSL streams and :mod:`bendsense.control` take
the blocks per finger name.
"""

from __future__ import annotations

import time

import numpy as np

from bendsense.errors import ArgumentError
from bendsense.pipeline.live import frame_times
from bendsense.pipeline.readings import ReadingClock
from bendsense.session.fingers import finger_parts, split_signals

__all__ = ["GripperProcessor"]


class GripperProcessor:
    """Shapes and forces of every finger of a gripper, a block of board frames at a time.

    Parameters
    ----------
    calibrations : Calibration, path or mapping
        The fingers' calibrations, as :func:`bendsense.session.fingers.calibrations` takes them:
        one for every finger (fingers of one sensor design), or a mapping finger name →
        Calibration or path.
    gripper : GripperConfig
        The fingers: each finger's config, board channels and pressure line.
    pressure_pa : float, optional
        Pressure for frames without a reading of a finger's line [Pa] (also for a board
        that sends fewer lines than the gripper maps).
    finger_options : mapping of str to dict, optional
        Further options of one finger's processor (e.g. its known ``contact_s_m``), over
        the shared ``options``.
    **options
        Options of every finger's :class:`~bendsense.pipeline.LiveProcessor`
        (``constraint``, ``estimate``, ``bandwidth_hz``, ``load``, ``contact_s_m``, ...).

    Attributes
    ----------
    fingers : tuple of str
        The finger names, in the config's order.
    processors : dict of str to LiveProcessor
        Each finger's processor.
    frames : int
        Board frames processed.
    """

    def __init__(self, calibrations, gripper, *, pressure_pa=None, finger_options=None, **options):
        from bendsense.config import GripperConfig
        from bendsense.pipeline import LiveProcessor
        from bendsense.session.fingers import calibrations as finger_calibrations

        if not isinstance(gripper, GripperConfig):
            raise ArgumentError(f"gripper: expected a GripperConfig (a config with fingers:), got "
                                f"{type(gripper).__name__}; one actuator: bendsense.pipeline.LiveProcessor")
        self.gripper = gripper
        self.fingers = tuple(gripper.names)
        unknown = sorted(set(finger_options or {}) - set(self.fingers))
        if unknown:
            raise ArgumentError(f"finger_options: unknown finger {', '.join(unknown)} (fingers "
                                f"{', '.join(self.fingers)})")
        cals = finger_calibrations(gripper, calibrations)
        self.pressure_pa = None if pressure_pa is None else float(pressure_pa)
        self.processors = {
            f.name: LiveProcessor(cals[f.name], f.config, pressure_pa=pressure_pa,
                                  **{**options, **(finger_options or {}).get(f.name, {})})
            for f in gripper.fingers
        }
        self.frames = 0
        self._clock = ReadingClock()
        self._lines_reported = 0  # the most pressure lines a SAMPLE of this run carried
        self._board = None  # (channels, pressure lines) of the board's blocks, checked against the fingers

    # the finger processors' shared options, for the outputs' metadata
    def _first(self):
        return self.processors[self.fingers[0]]

    @property
    def constraint(self) -> str:
        """Force constraint (the first finger's; the fingers share the options given)."""
        return self._first().constraint

    @property
    def method(self) -> str:
        """Estimator method (the first finger's)."""
        return self._first().method

    @property
    def objective(self) -> str:
        """What the fit compares (the first finger's)."""
        return self._first().objective

    @property
    def estimate(self) -> bool:
        """Whether the fingers' forces are estimated."""
        return self._first().estimate

    @property
    def track(self) -> bool:
        """Whether the fingers' forces are tracked causally."""
        return self._first().track

    @property
    def failures(self) -> int:
        """Force estimates that did not converge, over all fingers."""
        return sum(p.failures for p in self.processors.values())

    @property
    def estimated(self) -> int:
        """Frames whose force was estimated, over all fingers (a board frame counts once per finger)."""
        return sum(p.estimated for p in self.processors.values())

    @property
    def status_counts(self) -> dict:
        """Frames per status over all fingers (a board frame counts once per finger)."""
        out: dict[str, int] = {}
        for p in self.processors.values():
            for status, count in p.status_counts.items():
                out[status] = out.get(status, 0) + count
        return out

    def reset(self) -> None:
        """Forget every finger's warm start and track, and the time origin (e.g. after a reconnect)."""
        for p in self.processors.values():
            p.reset()
        self._clock.reset()
        self._lines_reported = 0

    def warm_up(self) -> None:
        """Compile or load the kernels before the first frame arrives (every finger's), then forget the frames."""
        for p in self.processors.values():
            p.warm_up()
        self.reset()
        self.frames = 0

    def process_block(self, signals, pressure_pa=None, *, t_s=None, seq=None, host_ns=None, extra=None) -> dict:
        """Process a block of consecutive board frames: every finger's part through its processor.

        Parameters
        ----------
        signals : array_like, shape (n, N_board)
            Raw signals of every board channel [signal units].
        pressure_pa : array_like, shape (n,) or (n, n_lines), optional
            Pressure per frame and line [Pa]; NaN or None: no reading (the fallback
            pressure, if any, is used).
        t_s, seq, host_ns : array_like, shape (n,), optional
            Frame time [s], sequence numbers, arrival time [ns]; default NaN, -1, now.
        extra : dict of str to array_like, shape (n,), optional
            Further per-frame columns for each finger's ``results.csv``.

        Returns
        -------
        dict of str to LiveBlock
            Each finger's block, in the config's order.
        """
        a = np.asarray(signals, dtype=float)
        if a.ndim != 2:
            raise ArgumentError(f"signals: expected shape (n, N), got {a.shape}")
        n = a.shape[0]
        p = np.full((n, 1), np.nan) if pressure_pa is None else np.asarray(pressure_pa, dtype=float)
        if p.ndim == 1:
            p = p[:, None]
        if self.pressure_pa is not None and p.shape[1] < self.gripper.n_lines:
            # lines the board does not send: frames without a reading of them, filled by the fallback
            p = np.hstack([p, np.full((p.shape[0], self.gripper.n_lines - p.shape[1]), np.nan)])
        times = frame_times(n, t_s, seq, host_ns)  # one arrival time for every finger's copy of a frame
        parts = self._split(a, p)
        blocks = {name: self.processors[name]._block(*parts[name], *times, extra, time.perf_counter())
                  for name in self.fingers}
        self.frames += n
        return blocks

    def _split(self, a, p) -> dict:
        """Each finger's (signals, pressure) of a block of the board (:func:`~bendsense.session.fingers.split_signals`).

        The board's shape is checked against the fingers when it first comes or changes,
        not at every block: a loop's blocks come from one board.
        """
        board = (a.shape[1], p.shape[1])
        p = p if p.shape[1] > 1 else p[:, 0]
        if board != self._board:
            parts = split_signals(a, p, self.gripper)  # its checks, their one clear error
            self._board = board
            return parts
        return finger_parts(a, p, self.gripper)

    def process_readings(self, readings) -> dict:
        """Process driver readings (:class:`~bendsense.device.driver.Reading`) of the board, in arrival order.

        Each finger's block is what :meth:`bendsense.pipeline.LiveProcessor.process_readings`
        gives for readings holding only the finger's channels and its line's pressure: ``t_s``
        is the device clock from the first reading this processor saw, the block's
        :attr:`~bendsense.pipeline.LiveBlock.extra` the recording's columns (``host_s``,
        ``status``, ``tx_drops``). A line the board stopped reporting reads as no pressure
        (its fingers' frames ``no_pressure``); a board that never reported a finger's line
        is an :class:`~bendsense.errors.ArgumentError`.

        Parameters
        ----------
        readings : list of Reading
            Driver readings, oldest first.

        Returns
        -------
        dict of str to LiveBlock
            Each finger's block, in the config's order.
        """
        c = self._clock.columns(readings)
        p, lines = c.pressures_pa, self.gripper.n_lines
        if p.shape[1] < lines <= self._lines_reported:
            # lines the board reported before and stopped reporting: frames without a reading of them (no_pressure),
            # not a board that never had them (one error)
            p = np.hstack([p, np.full((p.shape[0], lines - p.shape[1]), np.nan)])
        self._lines_reported = max(self._lines_reported, p.shape[1])
        return self.process_block(c.signals, p, t_s=c.t_s, seq=c.seq, host_ns=c.host_ns, extra=c.extra)
