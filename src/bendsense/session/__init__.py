"""Sessions: a recording of sensor signals and pressure, frame by frame.

:class:`Session` holds the frames in memory, and :func:`read_session` reads either file
format into one. Each format of DESIGN.md section 3 is a module of its own:

- :mod:`bendsense.session.csvfile`: the session CSV, for interchange (read and written);
- :mod:`bendsense.session.native`: the native session directory the recorder writes,
  crash-safe, with the device's raw records (and its export to and import from CSV);
- :mod:`bendsense.session.cells`: how one CSV cell is written and read back (shared
  with ``results.csv``);
- :mod:`bendsense.session.inputs`: a run's session, config and calibration as objects,
  each given or its path.

:mod:`bendsense.session.base` holds the :class:`Session` object alone, so that the
format modules build it without importing this package's dispatch.
"""

from __future__ import annotations

import os

from bendsense import validation as check
from bendsense._io import check_regular_file
from bendsense.errors import SessionError
from bendsense.session.base import Session
from bendsense.session.csvfile import read_session_csv, write_session_csv
from bendsense.session.native import read_session_dir

__all__ = ["Session", "read_session", "read_session_csv", "write_session_csv"]


def read_session(path: str | os.PathLike) -> Session:
    """Read a session: a native session directory or a session CSV.

    Parameters
    ----------
    path : path
        A native session directory (:func:`bendsense.session.native.read_session_dir`)
        or a session CSV (:func:`bendsense.session.csvfile.read_session_csv`).

    Returns
    -------
    Session

    Raises
    ------
    ArgumentError
        If ``path`` is not a path (a ``str`` or ``os.PathLike``).
    SessionError
        If ``path`` does not exist, is neither a regular file nor a directory (a FIFO,
        a device), or is not a readable session.
    """
    path = check.path("path", path)
    if path.is_dir():
        return read_session_dir(path)
    if not path.exists():
        raise SessionError(f"{path}: no such file or session directory")
    check_regular_file(path, "session (a session CSV or a native session directory)", SessionError)
    return read_session_csv(path)
