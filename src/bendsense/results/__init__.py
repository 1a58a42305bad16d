"""Results of the pipeline on disk: ``results.csv`` and ``shape.npz`` (DESIGN.md section 3).

``results.csv`` has a row per frame: ``t_s``, ``pressure_pa``, ``kappa1..kappaN``
[1/m], ``tip_x_m``, ``tip_y_m``, ``tip_angle_rad``, after estimation ``fx_n``,
``fy_n``, ``fx_std_n``, ``fy_std_n``, for a contact load (``load="contact"``)
``contact_s_m``, ``contact_std_m`` [m], then ``residual_m``, ``status``; after tracking
(:func:`bendsense.track`) ``fx_track_n``, ``fy_track_n``, ``fx_track_std_n``,
``fy_track_std_n``, ``track_status``; then ``window_p_value`` when a window model check
ran (:func:`bendsense.check_windows`); then the input's extra columns unchanged (one
whose name is a result column's, such as a ground-truth ``fx_n``, is written as
``input_fx_n``, also when there is no estimate, so that it never poses as one).
``shape.npz`` holds ``s_m`` (M,) and ``positions_m`` (frames, M, 2).
"""

from __future__ import annotations

import csv
import re
import zipfile
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from bendsense import _jit
from bendsense._batched import brief_repr
from bendsense._io import open_regular, read_text
from bendsense.errors import SessionError
from bendsense.results.contact import CONTACT_COLUMNS, contact_columns
from bendsense.session.cells import parse_column, write_columns
from bendsense.status import Status, words

WINDOW_MISFIT = "window_misfit"  # a count, not a status: frames whose latest window failed the window test
#: the flagged statuses (words) that the status lines of ``record`` and ``live`` count, with their labels
FLAGGED = ((Status.EXTRAPOLATED.word, "extrapolated"), (Status.NOT_CONVERGED.word, "not converged"),
           (Status.MODEL_MISFIT.word, "misfit"), (WINDOW_MISFIT, "window misfit"),
           (Status.NOT_IDENTIFIABLE.word, "not identifiable"), (Status.IMPLAUSIBLE_FORCE.word, "implausible force"))

__all__ = ["Results", "write_results", "read_results", "frame_status", "frame_codes", "estimate_codes",
           "tracked_columns"]

_KAPPA = re.compile(r"kappa[0-9]+$")
FORCE_COLUMNS = ("fx_n", "fy_n", "fx_std_n", "fy_std_n", "residual_m", "status")
#: the tracked force (:meth:`bendsense.Track.to_columns`), after ``status``
TRACK_COLUMNS = ("fx_track_n", "fy_track_n", "fx_track_std_n", "fy_track_std_n", "track_status")
#: the p-value of the window model check of each frame's window, after the tracked columns
WINDOW_COLUMN = "window_p_value"
RESULT_COLUMNS = ("t_s", "pressure_pa", "tip_x_m", "tip_y_m", "tip_angle_rad", *FORCE_COLUMNS, *CONTACT_COLUMNS,
                  *TRACK_COLUMNS, WINDOW_COLUMN)
_NUMERIC = ("t_s", "pressure_pa", "tip_x_m", "tip_y_m", "tip_angle_rad", "fx_n", "fy_n", "fx_std_n", "fy_std_n",
            *CONTACT_COLUMNS, "residual_m", *TRACK_COLUMNS[:4], WINDOW_COLUMN)


@dataclass(frozen=True, eq=False)
class Results:
    """Per-frame results as read back from an output directory."""

    __repr__ = brief_repr  # a line or two, not every value of every frame

    columns: dict
    s_m: np.ndarray
    positions_m: np.ndarray
    extra_names: tuple = field(default_factory=tuple)

    @classmethod
    def from_state(cls, session, shape, estimate=None, track=None) -> Results:
        """The results of a processed session in memory: the columns of ``results.csv``.

        Parameters
        ----------
        session : Session
            The processed session.
        shape : Shape
            Its reconstructed shapes.
        estimate : ForceEstimate, optional
            Its force estimates; of a contact load (``load="contact"``) also the columns
            ``contact_s_m, contact_std_m`` after ``fy_std_n``.
        track : Track, optional
            Its tracked forces (:func:`bendsense.track`): the columns
            :data:`TRACK_COLUMNS` after ``status``, and the track's ``window_p_value``.
        """
        frames = len(session)
        kappa = np.asarray(shape.curvature_per_m)
        kappa = kappa.reshape(frames, kappa.shape[-1] if kappa.ndim else 1)  # no frames: still N columns
        tip = np.asarray(shape.tip_position_m).reshape(frames, 2)
        columns: dict[str, np.ndarray] = {
            "t_s": session.t_s,
            "pressure_pa": session.pressure_pa,
            **{f"kappa{i + 1}": kappa[:, i] for i in range(kappa.shape[1])},
            "tip_x_m": tip[:, 0],
            "tip_y_m": tip[:, 1],
            "tip_angle_rad": np.asarray(shape.tip_angle_rad).reshape(frames),
        }
        if estimate is not None:
            force = np.asarray(estimate.force_n).reshape(frames, 2)
            std = np.asarray(estimate.std_n).reshape(frames, 2)
            columns.update(
                fx_n=force[:, 0],
                fy_n=force[:, 1],
                fx_std_n=std[:, 0],
                fy_std_n=std[:, 1],
                **contact_columns(frames, estimate),
                residual_m=np.asarray(estimate.residual_m).reshape(frames),
            )
        codes = frame_codes(shape, estimate)
        columns["status"] = words(codes)
        columns.update(tracked_columns(frames, estimate, track, codes))
        extra_names = []
        for name, values in session.extra.items():
            # an input column named like a result (e.g. ground truth fx_n) is kept as
            # input_fx_n, with or without an estimate: it never poses as one
            reserved = name in columns or name in RESULT_COLUMNS or _KAPPA.match(name)
            name = f"input_{name}" if reserved else name
            columns[name] = values
            extra_names.append(name)
        positions = np.asarray(shape.positions_m).reshape(frames, np.size(shape.s_m), 2)
        return cls(columns=columns, s_m=np.asarray(shape.s_m), positions_m=positions,
                   extra_names=tuple(extra_names))

    def write(self, out_dir, *, overwrite: bool = False, inputs=(), source=None) -> Path:
        """Write ``results.csv`` and ``shape.npz`` into ``out_dir`` (as :func:`write_results`).

        Parameters
        ----------
        out_dir : path
            Output directory (:func:`write_results`).
        overwrite : bool, default False
            Replace only a previous bendsense output there.
        inputs : iterable of paths
            Inputs never to be written over (the session's source among them).
        source : path, optional
            The session file or directory the results were made from, named in the
            directory's manifest.
        """
        from bendsense import output

        out_dir = Path(out_dir)
        output.check([output.directory(out_dir, overwrite=overwrite)], inputs)
        with output.write_dir(out_dir, overwrite=overwrite, inputs=inputs, writer="bendsense save",
                              source=source) as tmp:
            self.write_files(tmp)
        return out_dir

    def write_files(self, directory) -> None:
        """Write ``results.csv`` and ``shape.npz`` into ``directory`` (existing; no manifest, no checks).

        The writer inside :meth:`write` (and inside a gripper's output directory, one
        directory per finger: :func:`bendsense.results.gripper.write_gripper_results`).

        Parameters
        ----------
        directory : path
            An existing directory, being written (e.g. by :func:`bendsense.output.write_dir`).
        """
        directory = Path(directory)
        columns = self.columns
        with open(directory / "results.csv", "w", encoding="utf-8", newline="") as fh:
            write_columns(fh, list(columns), list(columns.values()))
        # stored, not deflated: positions of noisy shapes deflate by ~10 % at ~35 ms per
        # 1,000 frames, the largest cost of writing; np.load reads either
        np.savez(directory / "shape.npz", s_m=self.s_m, positions_m=self.positions_m)

    def __getitem__(self, name):
        return self.columns[name]

    @property
    def curvature_per_m(self) -> np.ndarray:
        """Segment curvatures, shape (frames, N) [1/m]."""
        n = sum(1 for k in self.columns if _KAPPA.match(k))
        return np.column_stack([self.columns[f"kappa{i + 1}"] for i in range(n)])

    @property
    def has_forces(self) -> bool:
        """True when the results include a force estimate."""
        return "fx_n" in self.columns

    @property
    def has_contact(self) -> bool:
        """True when the results hold a contact location (:data:`~bendsense.results.contact.CONTACT_COLUMNS`)."""
        return "contact_s_m" in self.columns

    @property
    def has_track(self) -> bool:
        """True when the results include a tracked force (:data:`TRACK_COLUMNS`)."""
        return "fx_track_n" in self.columns


def tracked_columns(frames: int, estimate=None, track=None, status=None) -> dict:
    """The columns after ``status``: the tracked force and the window p-value, where known.

    Parameters
    ----------
    frames : int
        Frames of the results.
    estimate : ForceEstimate, optional
        Its ``window_p_value`` (:func:`bendsense.check_windows`) is the column
        ``window_p_value`` when there is no track.
    track : Track, optional
        The tracked force: the columns :data:`TRACK_COLUMNS`, and its ``window_p_value``.
    status : ndarray of int, shape (frames,), optional
        The frames' own status codes (:func:`frame_codes`): a frame that is not ``OK``
        has that reason as its ``track_status`` too (the track's value stays, a
        prediction where the frame has no force), never ``ok``.

    Returns
    -------
    dict of str to ndarray, shape (frames,)
        Empty without a track and without a window check.
    """
    columns = {}
    window = getattr(estimate, WINDOW_COLUMN, None)
    if track is not None:
        columns.update({name: np.asarray(values).reshape(frames) for name, values in track.to_columns().items()})
        if status is not None:
            own = np.asarray(status).reshape(frames)
            columns["track_status"] = words(np.where(own != Status.OK, own, np.asarray(track.status).reshape(frames)))
        window = track.window_p_value
    if window is not None:
        columns[WINDOW_COLUMN] = np.asarray(window, dtype=float).reshape(frames)
    return columns


def estimate_codes(estimate, n: int) -> np.ndarray:
    """Per-frame status codes (n,) of a force estimate alone: its own, and what the outputs add.

    The estimate's :attr:`~bendsense.ForceEstimate.status`; ``NO_FORCE`` for an ``OK``
    frame without a finite force (whatever the solver said), ``CONTACT_UNRESOLVED`` for
    an ``OK`` frame of a contact load whose ``contact_std_m`` is infinite
    (:func:`bendsense.results._kernels.estimate_code`, the live step's rule too).

    Parameters
    ----------
    estimate : ForceEstimate
        Force estimates of ``n`` frames.
    n : int
        The number of frames.
    """
    from bendsense.results import _kernels

    unresolved = np.zeros(n, dtype=bool)
    if getattr(estimate, "load", "tip") == "contact" and estimate.contact_std_m is not None:
        unresolved = np.isinf(_frames_of(estimate.contact_std_m, n, float))
    codes = np.empty(n, dtype=np.int8)
    _jit.call(_kernels.estimate_codes_into, _whole(estimate.status, n, np.int8), _whole(estimate.success, n, bool),
              np.ascontiguousarray(np.asarray(estimate.force_n, dtype=float).reshape(n, 2)),
              np.ascontiguousarray(unresolved), codes)
    return codes


def _frames_of(values, n: int, dtype) -> np.ndarray:
    """``values`` as an array (n,) of ``dtype``: itself when it is one (a view, not to be written), else broadcast."""
    a = np.asarray(values, dtype=dtype)
    return a if a.shape == (n,) else np.broadcast_to(a, (n,))


def _whole(values, n: int, dtype) -> np.ndarray:
    """:func:`_frames_of` as a contiguous array (what the status kernels take: one compiled version)."""
    return np.ascontiguousarray(_frames_of(values, n, dtype))


def frame_codes(shape, estimate=None) -> np.ndarray:
    """Per-frame status codes (n,) of int8: the shape's, then the force estimate's (:mod:`bendsense.status`).

    ``EXTRAPOLATED`` (signals outside the calibrated range), the estimate's own
    (:func:`estimate_codes`) where the shape is ok or the estimate failed, and over all
    ``NO_SHAPE`` (non-finite signals: nothing to estimate from) and ``IMPLAUSIBLE_SHAPE``
    (a tip angle beyond a full turn: a unit or calibration mistake).

    Parameters
    ----------
    shape : Shape
        Reconstructed shapes, batch axis over frames.
    estimate : ForceEstimate, optional
        Force estimates of the same frames.
    """
    from bendsense.results import _kernels

    n = np.shape(shape.tip_angle_rad)[0] if np.ndim(shape.tip_angle_rad) else 1
    kappa = np.asarray(getattr(shape, "curvature_per_m", np.zeros((n, 1))), dtype=float)
    kappa = kappa.reshape(n, kappa.shape[-1] if kappa.ndim else 1)  # (a block without frames too)
    has_estimate = estimate is not None
    own = estimate_codes(estimate, n) if has_estimate else np.zeros(n, dtype=np.int8)
    success = _whole(estimate.success, n, bool) if has_estimate else np.zeros(n, dtype=bool)
    codes = np.empty(n, dtype=np.int8)
    # (the tip turned by more than a full turn is a unit or calibration mistake: a bending actuator does not)
    _jit.call(_kernels.frame_codes_into, _whole(getattr(shape, "extrapolated", False), n, bool),
              np.ascontiguousarray(kappa), _whole(shape.tip_angle_rad, n, float), has_estimate, own, success, codes)
    return codes


def frame_status(shape, estimate=None) -> np.ndarray:
    """Per-frame ``status`` words of results.csv: ``ok`` or a short reason (the words of :func:`frame_codes`).

    ``extrapolated``, ``no_shape``, ``not_converged``, ``not_identifiable`` (the shape
    does not determine the load along one direction: σ is infinite there),
    ``pressure_out_of_range``, ``model_misfit`` (the model shape stays over 5 % of the
    length from the measured one, or a χ² beyond chance), ``contact_unresolved``,
    ``implausible_force`` (:func:`bendsense.estimation.plausibility.force_bound_n`: force
    kept), ``no_force`` and ``implausible_shape``.

    Parameters
    ----------
    shape : Shape
        Reconstructed shapes, batch axis over frames.
    estimate : ForceEstimate, optional
        Force estimates of the same frames.
    """
    return words(frame_codes(shape, estimate))


def flagged_counts(counts: dict, sep: str = "  ") -> str:
    """``extrapolated N  not converged N  misfit N  not identifiable N  implausible force N`` for a status line.

    Parameters
    ----------
    counts : dict of str to int
        Frames per status (e.g. ``LiveProcessor.status_counts``).
    sep : str
        Between the counts.
    """
    return sep.join(f"{label} {counts.get(status, 0)}" for status, label in FLAGGED)


def write_results(out_dir, session, shape, estimate=None, *, track=None, overwrite: bool = False, inputs=()) -> Path:
    """Write ``results.csv`` and ``shape.npz`` of a processed session into ``out_dir``.

    The directory is written complete or not at all (:func:`bendsense.output.write_dir`):
    files go to a hidden directory beside it that is swapped in at the end, with a
    manifest of what bendsense wrote.

    Parameters
    ----------
    out_dir : path
        Output directory; must not exist (or be empty) unless ``overwrite``, which
        replaces only a previous bendsense output there.
    session : Session
        The input session (time, pressure and extra columns).
    shape : Shape
        Reconstructed shapes, batch axis over the session's frames.
    estimate : ForceEstimate, optional
        Force estimates for the same frames.
    track : Track, optional
        Tracked forces of the same frames (:func:`bendsense.track`).
    overwrite : bool, default False
        Replace a previous bendsense output in ``out_dir``.
    inputs : iterable of paths
        Inputs never to be written over (the session's source is always one; the
        directory's manifest names it).

    Raises
    ------
    OutputExistsError, OutputError
        See :func:`bendsense.output.check`.
    """
    source = getattr(session, "source", None)
    source = source if source and Path(source).exists() else None
    return Results.from_state(session, shape, estimate, track).write(
        out_dir, overwrite=overwrite, inputs=[*inputs, *([source] if source else [])], source=source)


def read_results(out_dir) -> Results:
    """Read an output directory written by :func:`write_results`.

    Parameters
    ----------
    out_dir : str or path-like
        The output directory (holding ``results.csv`` and ``shape.npz``).
    """
    out_dir = Path(out_dir)
    path = out_dir / "results.csv"
    if not out_dir.exists():
        raise SessionError(f"{out_dir}: no such results directory")
    if not path.exists():
        raise SessionError(f"{out_dir}: no results.csv (not a results directory)")
    rows = list(csv.reader(read_text(path, "results CSV", SessionError).splitlines()))
    if not rows:
        raise SessionError(f"{path}: empty (no header row)")
    header, body = rows[0], rows[1:]
    for line, row in enumerate(body, start=2):
        if len(row) != len(header):  # (zip below would cut every column to the shortest row)
            raise SessionError(f"{path}: line {line}: {len(row)} cells, expected {len(header)} (one per column)")
    cells = list(zip(*body)) if body else [[] for _ in header]
    columns = {h: parse_column(list(c)) for h, c in zip(header, cells)}
    for h in (*_NUMERIC, *(h for h in header if _KAPPA.match(h))):
        if h in columns:
            try:
                columns[h] = columns[h].astype(float)
            except ValueError:
                line, cell = next((k, c) for k, c in enumerate(columns[h], start=2) if not _is_number(c))
                raise SessionError(f"{path}: column {h}: expected numbers, got {cell!r} on line {line}") from None
            inf = np.flatnonzero(np.isinf(columns[h]))
            if inf.size and h in ("t_s", "pressure_pa"):  # (an infinite std marks an unidentifiable direction)
                raise SessionError(f"{path}: line {inf[0] + 2}, column {h}: must be finite or nan, got inf")
    missing = [h for h in ("t_s", "tip_x_m", "tip_y_m", "tip_angle_rad", "kappa1", "status") if h not in columns]
    if missing:
        raise SessionError(f"{path}: not a results.csv of bendsense (no column {missing[0]})")
    npz_path = out_dir / "shape.npz"
    if not npz_path.exists():
        raise SessionError(_no_shapes(out_dir, npz_path))
    # our own file object: np.load leaks its handle when the zip is damaged
    fh = open_regular(npz_path, "shape.npz", SessionError)
    try:
        with fh, np.load(fh) as npz:
            s_m, positions = np.asarray(npz["s_m"], dtype=float), np.asarray(npz["positions_m"], dtype=float)
    except (OSError, ValueError, KeyError, EOFError, zipfile.BadZipFile) as err:
        raise SessionError(f"{npz_path}: not a shape.npz of bendsense ({' '.join(str(err).split())[:80]})") from None
    frames = len(columns["t_s"])
    if positions.ndim != 3 or positions.shape[0] != frames or positions.shape[1:] != (s_m.size, 2):
        raise SessionError(f"{npz_path}: positions_m has shape {positions.shape}, expected ({frames}, {s_m.size}, 2) "
                           "for the frames of results.csv")
    known = set(RESULT_COLUMNS)
    extra = tuple(h for h in header if h not in known and not _KAPPA.match(h))
    return Results(columns=columns, s_m=s_m, positions_m=positions, extra_names=extra)


def _no_shapes(out_dir: Path, npz_path: Path) -> str:
    """Why a results.csv has no shape.npz beside it: a recording's (``record --estimate``), else a damaged directory."""
    from bendsense.session.native import is_session_dir

    session = next((d for d in (out_dir, out_dir.parent) if is_session_dir(d)), None)
    if session is None:
        return f"{npz_path}: missing (every results directory has one)"
    return (f"{out_dir / 'results.csv'}: a recording's results ('record --estimate' keeps no shapes); for a results "
            f"directory: bendsense load {session} --calibration CAL.yaml reconstruct estimate save OUT_DIR")


def _is_number(cell) -> bool:
    try:
        float(cell)
    except ValueError:
        return False
    return True
