"""Cells of the CSV files bendsense writes: one value, one string, and back.

Shared by the session CSV (:mod:`bendsense.session.csvfile`) and ``results.csv``
(:mod:`bendsense.results`). Floats are written with ``repr`` of the Python float, so
that reading a file back gives the same numbers bit for bit (``nan`` and ``inf``
included); integers and booleans with ``str``. A column read back is integers, floats
or text, whichever all of its cells are.
"""

from __future__ import annotations

import csv
import math
import re

import numpy as np

__all__ = ["format_cell", "column_cells", "parse_column", "write_columns"]

_NEEDS_QUOTES = re.compile(r'[,"\r\n]')


def format_cell(value) -> str:
    """The CSV cell of one value: ``repr`` of a float (``"nan"`` for NaN), else ``str``.

    Parameters
    ----------
    value : float, int, bool, str or numpy scalar
        The value of one cell.

    Returns
    -------
    str
        The cell, before the csv module's quoting.
    """
    if isinstance(value, (float, np.floating)):
        return "nan" if math.isnan(value) else repr(float(value))
    return str(value)


def column_cells(values) -> list[str] | None:
    """The cells of one column as :func:`format_cell` makes them, or None if one needs quotes.

    Parameters
    ----------
    values : array_like, shape (rows,)
        One column.

    Returns
    -------
    list of str or None
        One cell per row; None when a cell holds a comma, a quote or a line break, which
        the csv module would quote (the caller then writes row by row).
    """
    values = np.asarray(values)
    kind = values.dtype.kind
    # Python floats and ints format as the numpy scalars do, faster
    if kind == "f":
        return list(map(repr, values.tolist()))
    if kind in "iub":
        return list(map(str, values.tolist()))
    cells = [format_cell(v) for v in values]
    return None if any(_NEEDS_QUOTES.search(c) for c in cells) else cells


def write_columns(fh, header, columns) -> None:
    """Write a header row and one row per frame of ``columns`` to the text file ``fh``.

    The rows are what the csv module's writer writes for the cells of
    :func:`format_cell`, each line ended by a line feed; a table with no cell to quote
    is joined directly, several times faster than the csv module on long sessions.

    Parameters
    ----------
    fh : text file
        Open for writing, with ``newline=""``.
    header : sequence of str
        Column names.
    columns : sequence of array_like, each shape (rows,)
        The columns, in the order of ``header``.
    """
    writer = csv.writer(fh, lineterminator="\n")
    writer.writerow(header)
    cells = [column_cells(c) for c in columns]
    if any(c is None for c in cells):
        for row in zip(*columns):
            writer.writerow([format_cell(v) for v in row])
    elif cells and len(cells[0]):
        fh.write("\n".join(map(",".join, zip(*cells))))
        fh.write("\n")


def parse_column(cells: list[str]) -> np.ndarray:
    """One column read back: integers where every cell is one, else floats, else text.

    Parameters
    ----------
    cells : list of str
        The cells of the column, stripped.

    Returns
    -------
    ndarray, shape (rows,)
        ``int64`` when every cell is an integer, ``float`` when every cell is a number,
        else ``object`` (the strings; also integers wider than ``int64``, kept as written).
    """
    try:
        ints = [int(c) for c in cells]
        return np.array(ints, dtype=np.int64)
    except OverflowError:  # an identifier of 20 digits and more: a float would round it
        return np.array(cells, dtype=object)
    except ValueError:
        pass
    try:
        return np.array([float(c) for c in cells])
    except ValueError:
        return np.array(cells, dtype=object)
