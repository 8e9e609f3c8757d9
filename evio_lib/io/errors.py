"""Numeric text tables: reading with error messages that name the FILE, the LINE and the problem; exact writing.

Every text reader of :mod:`evio_lib.io` (ECD, EuRoC, TUM) parses its files through :func:`read_table`:

* fast path: one ``np.loadtxt`` call with a structured dtype (integer columns parsed as integers, which
  is about twice as fast as parsing everything as float);
* slow path, only when the fast path fails: the file is walked line by line to find the first bad line and
  report it, e.g. ``events.txt line 1042: expected 4 columns (t x y p), got 3``.

Checks that need the parsed values (finite numbers, sorted timestamps, value ranges) go through
:meth:`Table.error`, which maps a row back to its line number (comment and blank lines are skipped).

Quaternions read from files (TUM, ECD, EuRoC ground truth) go through :func:`unit_quaternions`: a row whose norm
is within ``QUATERNION_NORM_TOL`` = 1e-3 of 1 (a file written with few decimals) is divided by its norm (rows within
1e-6, the tolerance :meth:`evio_lib.sequence.GroundTruth.validate` accepts, keep their numbers exactly, so file round
trips stay bit-exact); a row further from 1 (norm 2, 0.5, 0) is not a rotation and raises an error naming the row.
"""
from __future__ import annotations

import math
import warnings
from dataclasses import dataclass
from pathlib import Path
from typing import Sequence

import numpy as np

__all__ = ["DataFileError", "Table", "read_table", "read_text", "require_file", "time_format", "write_table", "unit_quaternions",
           "quaternion_norm_problem", "QUATERNION_NORM_TOL"]

#: Largest |norm - 1| of a quaternion that readers normalise; beyond it the quaternion is refused.
QUATERNION_NORM_TOL = 1e-3
#: Rows with |norm - 1| up to this are kept as they are (the tolerance of GroundTruth.validate()).
_QUATERNION_EXACT_TOL = 1e-6


class DataFileError(ValueError):
    """A data file is missing or malformed; the message names the file, the line (where there is one) and the problem."""


def require_file(path: str | Path, what: str) -> Path:
    """Return ``path`` as a Path if it is an existing file, else raise DataFileError saying what was expected.

    Args:
        path: file that must exist.
        what: what the file should hold, e.g. "the event list `t x y p`".

    >>> require_file("/no/such/events.txt", "the event list")
    Traceback (most recent call last):
    ...
    evio_lib.io.errors.DataFileError: events.txt: file not found at /no/such/events.txt (expected the event list)
    """
    path = Path(path)
    if not path.is_file():
        raise DataFileError(f"{path.name}: file not found at {path} (expected {what})")
    return path


def read_text(path: str | Path, name: str | None = None) -> str:
    """Return the text of the UTF-8 file ``path``; a file that is not UTF-8 text raises DataFileError naming its line.

    Args:
        path: the file.
        name: how messages call it (default: its file name).

    >>> import tempfile, os
    >>> folder = tempfile.mkdtemp()
    >>> _ = open(os.path.join(folder, "calib.txt"), "wb").write(b"199.1 198.8\\n\\xe9t\\xe9\\n")
    >>> read_text(os.path.join(folder, "calib.txt"))
    Traceback (most recent call last):
    ...
    evio_lib.io.errors.DataFileError: calib.txt line 2: not UTF-8 text (byte 0xe9 at column 1); expected a plain-text file saved as UTF-8 (or ASCII)
    """
    path = Path(path)
    data = path.read_bytes()
    try:
        return data.decode("utf-8")
    except UnicodeDecodeError as exc:
        line = data.count(b"\n", 0, exc.start) + 1
        column = exc.start - (data.rfind(b"\n", 0, exc.start) + 1) + 1
        raise DataFileError(f"{name or path.name} line {line}: not UTF-8 text (byte 0x{data[exc.start]:02x} at column "
                            f"{column}); expected a plain-text file saved as UTF-8 (or ASCII)") from None


def unit_quaternions(q: np.ndarray) -> tuple[np.ndarray, int, float]:
    """Return (q normalised (N, 4), index of the first row beyond QUATERNION_NORM_TOL or -1, that row's norm).

    q_unit = q / |q| for rows with 1e-6 < | |q| - 1 | <= QUATERNION_NORM_TOL; other rows are copied unchanged (the
    caller raises for the row named by the index). The input is not modified.

    Args:
        q: (N, 4) finite quaternions (any component order: the norm does not depend on it).

    >>> q, bad, norm = unit_quaternions(np.array([[0.0, 0.0, 0.0, 1.0005], [0.0, 0.0, 0.0, 2.0]]))
    >>> q[0].tolist(), bad, norm
    ([0.0, 0.0, 0.0, 1.0], 1, 2.0)
    """
    q = np.array(q, dtype=np.float64)
    if q.ndim != 2 or q.shape[1] != 4:
        raise ValueError(f"quaternions must have shape (N, 4); got {q.shape}")
    norm = np.linalg.norm(q, axis=1)
    error = np.abs(norm - 1.0)
    bad = np.flatnonzero(~(error <= QUATERNION_NORM_TOL))  # NaN counts as bad
    fix = (error > _QUATERNION_EXACT_TOL) & (error <= QUATERNION_NORM_TOL)
    q[fix] /= norm[fix, None]  # q <- q / |q|
    return q, (int(bad[0]) if bad.size else -1), (float(norm[bad[0]]) if bad.size else 1.0)


def quaternion_norm_problem(norm: float, layout: str) -> str:
    """Return the message for a quaternion whose norm is too far from 1 (``layout`` names its columns)."""
    if norm < 1e-6:
        return f"quaternion ({layout}) has zero norm; expected a unit quaternion"
    return (f"quaternion ({layout}) has norm {norm:.6g}; expected a unit quaternion "
            f"(norms within {QUATERNION_NORM_TOL:g} of 1 are normalised, others are not rotations)")


def _is_data_line(stripped: str) -> bool:
    """Return True for a line that holds data (not blank, not a comment)."""
    return bool(stripped)


def _strip_comment(line: str, comment: str) -> str:
    """Return ``line`` without its comment part and surrounding whitespace (like np.loadtxt does)."""
    return line.split(comment, 1)[0].strip()


@dataclass(frozen=True)
class Table:
    """Parsed numeric table: a structured array with one field per column, plus where it came from.

    Attributes:
        data: (N,) structured array, one named field per column (float64 or int64).
        name: name of the file in error messages (e.g. "events.txt" or "mav0/imu0/data.csv").
        path: the file.
        comment: comment character of the file.
    """

    data: np.ndarray
    name: str
    path: Path
    comment: str = "#"

    def __len__(self) -> int:
        return int(self.data.shape[0])

    def __getitem__(self, column: str) -> np.ndarray:
        return self.data[column]

    def line(self, row: int) -> int:
        """Return the 1-based line number in the file of data row ``row`` (0-based, comments/blank lines skipped)."""
        seen = -1
        with open(self.path, "r", encoding="utf-8", errors="replace") as f:
            for number, line in enumerate(f, start=1):
                if _is_data_line(_strip_comment(line, self.comment)):
                    seen += 1
                    if seen == row:
                        return number
        raise IndexError(f"row {row} not found in {self.path}")

    def error(self, row: int, problem: str) -> DataFileError:
        """Return a DataFileError "NAME line L: problem" for data row ``row``."""
        return DataFileError(f"{self.name} line {self.line(int(row))}: {problem}")

    def check_finite(self) -> None:
        """Raise DataFileError at the first NaN/inf value of a float column."""
        for column in self.data.dtype.names:
            values = self.data[column]
            if np.issubdtype(values.dtype, np.floating):
                bad = ~np.isfinite(values)
                if bad.any():
                    row = int(np.flatnonzero(bad)[0])
                    raise self.error(row, f"column '{column}' must be a finite number; got {values[row].item()}")

    def check_times(self, column: str = "t", *, strict: bool = True) -> None:
        """Raise DataFileError at the first timestamp that breaks the order.

        Args:
            column: the time column.
            strict: True requires strictly increasing times (IMU, images, poses); False allows equal neighbours
                (events may share a timestamp).
        """
        t = self.data[column]
        bad = (t[1:] <= t[:-1]) if strict else (t[1:] < t[:-1])
        if bad.any():
            row = int(np.flatnonzero(bad)[0]) + 1
            order = "strictly increasing (no duplicates)" if strict else "sorted (non-decreasing)"
            raise self.error(
                row, f"timestamp {t[row].item()!r} follows {t[row - 1].item()!r} on the previous data line; {column} must be {order}"
            )

    def unit_quaternions(self, columns: Sequence[str], layout: str | None = None) -> np.ndarray:
        """Return the (N, 4) quaternions in ``columns`` (in that order), normalised; raise at a row that is no rotation.

        Rows within 1e-6 of unit norm are returned exactly as read, rows within QUATERNION_NORM_TOL (1e-3) are
        divided by their norm, others raise DataFileError "NAME line L: quaternion (LAYOUT) has norm ...".

        Args:
            columns: the four column names, in the order of the returned array (e.g. qx qy qz qw).
            layout: how the message names the columns (default: ``columns`` joined; e.g. "qw qx qy qz" for the
                order in a EuRoC file).
        """
        q, bad, norm = unit_quaternions(np.stack([self.data[c] for c in columns], axis=1))
        if bad >= 0:
            raise self.error(bad, quaternion_norm_problem(norm, layout or " ".join(columns)))
        return q

    def check_range(self, column: str, low: float, high: float, what: str) -> None:
        """Raise DataFileError at the first value of ``column`` outside [low, high]; ``what`` explains the range."""
        values = self.data[column]
        bad = (values < low) | (values > high)
        if bad.any():
            row = int(np.flatnonzero(bad)[0])
            raise self.error(row, f"column '{column}' value {values[row].item()} is out of range: {what}")


def _diagnose(path: Path, name: str, columns: Sequence[str], int_columns: set[str], delimiter: str | None,
              comment: str, fallback: str) -> DataFileError:
    """Walk the file line by line and return a DataFileError for its first malformed line."""
    layout = " ".join(columns)
    with open(path, "r", encoding="utf-8", errors="replace") as f:
        for number, line in enumerate(f, start=1):
            stripped = _strip_comment(line, comment)
            if not _is_data_line(stripped):
                continue
            tokens = [tok.strip() for tok in stripped.split(delimiter)]
            if len(tokens) != len(columns):
                other = next((d for d in (",", ";") if d != delimiter and stripped.count(d) == len(columns) - 1), None)
                hint = (f" (its values are separated by '{other}'; this format separates its columns by "
                        f"{'spaces' if delimiter is None else repr(delimiter)})" if other else "")
                return DataFileError(
                    f"{name} line {number}: expected {len(columns)} columns ({layout}), got {len(tokens)}{hint}"
                )
            for column, tok in zip(columns, tokens):
                if column in int_columns:
                    try:
                        int(tok)
                    except ValueError:
                        return DataFileError(f"{name} line {number}: column '{column}' must be an integer; got {tok!r}")
                else:
                    try:
                        value = float(tok)
                    except ValueError:
                        return DataFileError(f"{name} line {number}: column '{column}' must be a number; got {tok!r}")
                    if not math.isfinite(value):
                        return DataFileError(f"{name} line {number}: column '{column}' must be a finite number; got {tok!r}")
    return DataFileError(f"{name}: could not parse the table ({layout}): {fallback}")


def read_table(path: str | Path, columns: Sequence[str], *, name: str | None = None, int_columns: Sequence[str] = (),
               delimiter: str | None = None, comment: str = "#") -> Table:
    """Return the numeric table in ``path`` as a :class:`Table` with one field per column.

    Args:
        path: text file, one row per line; blank lines and ``comment`` lines (or line ends) are ignored.
        columns: names of the columns, in file order; the row length must match.
        name: how errors name the file (default: the file name).
        int_columns: columns parsed as int64 (exact, e.g. nanosecond timestamps or pixel coordinates);
            the others are float64.
        delimiter: column separator; None means any whitespace.
        comment: comment character.

    Raises:
        DataFileError: "NAME line L: problem" for a wrong column count, a non-number, a non-integer in an
            integer column or a non-finite value; "NAME: file not found ..." for a missing file.

    >>> import tempfile, os
    >>> d = tempfile.mkdtemp(); p = os.path.join(d, "imu.txt")
    >>> _ = open(p, "w").write("# t v\\n0.0 1.5\\n0.1 2.5\\n")
    >>> read_table(p, ["t", "v"])["v"].tolist()
    [1.5, 2.5]
    >>> _ = open(p, "w").write("0.0 1.5\\n0.1\\n")
    >>> read_table(p, ["t", "v"])
    Traceback (most recent call last):
    ...
    evio_lib.io.errors.DataFileError: imu.txt line 2: expected 2 columns (t v), got 1
    """
    path = require_file(path, f"a table with columns ({' '.join(columns)})")
    name = path.name if name is None else name
    ints = set(int_columns)
    dtype = np.dtype([(c, "<i8" if c in ints else "<f8") for c in columns])
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # "input contained no data" for an empty file: zero rows is fine
            data = np.loadtxt(path, dtype=dtype, delimiter=delimiter, comments=comment, ndmin=1, encoding="utf-8")
    except (ValueError, TypeError, IndexError) as exc:
        raise _diagnose(path, name, columns, ints, delimiter, comment, str(exc)) from None
    table = Table(data=data, name=name, path=path, comment=comment)
    table.check_finite()
    return table


def time_format(t: np.ndarray) -> str:
    """Return the printf format for a timestamp column: "%.9f" (ns, the ECD style) when that is exact, else "%r".

    Nine decimals reproduce every timestamp that lies on the nanosecond grid; other float64 times (e.g. from a
    simulator) are written with Python's shortest exact representation, so reading the file back gives the
    same float64 values in both cases.

    >>> time_format(np.array([0.5, 0.003811])), time_format(np.array([0.1234567891234]))
    ('%.9f', '%r')
    """
    t = np.asarray(t, dtype=np.float64)
    on_grid = np.round(t * 1e9) / 1e9 == t  # t = N * 1e-9 exactly as float64 -> "%.9f" parses back to t
    return "%.9f" if bool(np.all(on_grid)) else "%r"


def write_table(path: str | Path, columns: Sequence[np.ndarray], formats: Sequence[str], *, header: str | None = None,
                progress: bool = False, chunk_rows: int = 200_000) -> None:
    """Write equally long 1-D ``columns`` as a space-separated text table, one row per line.

    Args:
        path: output file (overwritten).
        columns: K arrays of shape (N,).
        formats: K printf formats, e.g. "%.9f", "%d", "%r" (shortest exact float representation).
        header: optional first line, written as a "# ..." comment.
        progress: show a tqdm progress bar (useful for millions of events).
        chunk_rows: rows formatted per block.
    """
    if len(columns) != len(formats):
        raise ValueError(f"formats must have one entry per column ({len(columns)}); got {len(formats)}")
    n = int(np.shape(columns[0])[0]) if columns else 0
    for i, c in enumerate(columns):
        if np.ndim(c) != 1 or np.shape(c)[0] != n:
            raise ValueError(f"columns[{i}] must have shape ({n},); got {np.shape(c)}")
    row_format = " ".join(formats) + "\n"
    starts = range(0, n, chunk_rows)
    if progress:
        from tqdm.auto import tqdm

        starts = tqdm(starts, desc=Path(path).name, unit="block")
    with open(path, "w", encoding="utf-8", newline="\n") as f:
        if header is not None:
            f.write(f"# {header}\n")
        for i in starts:
            block = [np.asarray(c[i:i + chunk_rows]).tolist() for c in columns]
            f.write("".join([row_format % row for row in zip(*block)]))
