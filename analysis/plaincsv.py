"""A run's CSV log read as whole arrays when it holds only what the runs write: plain decimal numbers and empty
fields, no quotes, every row with the header's fields. Each column comes back as pandas would read it (int64 when
every field is an integer, float64 otherwise, an empty field NaN) with its numbers correctly rounded, as pandas reads
them with ``float_precision="round_trip"``; anything else is None, and the caller reads the file with pandas
(:func:`analysis.load.read_csv_strict`). One pass of NumPy over the text's bytes instead of pandas' parser: a run's
train.csv of 1000 episodes is read several times faster (docs/performance.md)."""

from __future__ import annotations

import re
import warnings
from collections.abc import Collection

import numpy as np

COMMA, NEWLINE = ord(","), ord("\n")
MAX_INT_CHARS = 15  # integers of at most 15 characters, sign included, are summed in int64; longer: pandas
_ALLOWED = np.zeros(256, dtype=bool)  # a number's characters, and the separator after it
_ALLOWED[np.frombuffer(b"0123456789.eE+-,", dtype=np.uint8)] = True
_FLOAT_MARKS = np.zeros(256, dtype=bool)
_FLOAT_MARKS[np.frombuffer(b".eE", dtype=np.uint8)] = True
# a word of a text column (offline eval.csv's score_reference): pandas keeps it as it is, unless it reads it as a
# missing value, a boolean or an infinity
_WORD = re.compile(r"[A-Za-z_][A-Za-z0-9_./-]*")
# The fields pandas' read_csv reads as a missing value by default (its documented ``na_values`` default), written out
# here rather than imported from pandas' internals: tests/test_plaincsv.py checks that read_csv reads exactly these,
# of them and their case variants, as NaN, so a pandas that changes the list fails that test.
NA_VALUES = frozenset({"", "#N/A", "#N/A N/A", "#NA", "-1.#IND", "-1.#QNAN", "-NaN", "-nan", "1.#IND", "1.#QNAN",
                       "<NA>", "N/A", "NA", "NULL", "NaN", "None", "n/a", "nan", "null"})
_NOT_WORDS = {*NA_VALUES, "true", "false", "inf", "infinity"}


def plain_columns(text: str, keep: Collection[str] | None = None, words: Collection[str] = ()
                  ) -> tuple[list[str], dict[str, np.ndarray]] | None:
    """(the header's names, the columns ``keep`` names, all when None, in the header's order) of a CSV ``text``
    with a header of distinct names, at least one row, every row ending in a newline, and plain numbers or empty
    fields in those columns, or words (:data:`_WORD`; an object column of strings) in the columns ``words`` names;
    None for any other text."""
    head_end = text.find("\n")
    if head_end <= 0 or not text.endswith("\n") or head_end == len(text) - 1:
        return None
    if '"' in text or "\r" in text or "\0" in text:
        return None
    header = text[:head_end].split(",")
    # pandas renames an empty or repeated name and drops a byte order mark: those headers are left to it
    if len(set(header)) != len(header) or "" in header or not text[:head_end].isascii():
        return None
    body = text[head_end + 1:]
    try:
        data = np.frombuffer(body.encode("ascii"), dtype=np.uint8)
    except UnicodeEncodeError:
        return None
    width = len(header)
    ends = np.flatnonzero((data == COMMA) | (data == NEWLINE))
    if len(ends) % width:
        return None
    ends = ends.reshape(-1, width)
    # every row: width - 1 commas, then its newline
    if not (data[ends[:, -1]] == NEWLINE).all() or (data[ends[:, :-1]] == NEWLINE).any():
        return None
    starts = np.empty_like(ends)
    starts.reshape(-1)[0] = 0
    starts.reshape(-1)[1:] = ends.reshape(-1)[:-1] + 1
    lengths = ends - starts
    columns: dict[str, np.ndarray] = {}
    for j, name in enumerate(header):
        if keep is not None and name not in keep:
            continue
        if name in words:
            column = _words(body, starts[:, j].tolist(), ends[:, j].tolist())
        else:
            column = _column(data, starts[:, j], lengths[:, j])
        if column is None:
            return None
        columns[name] = column
    return header, columns


def _words(body: str, starts: list[int], ends: list[int]) -> np.ndarray | None:
    """A text column as pandas reads one of words: an object array of strings, NaN for an empty field (float64 NaN
    when every field is empty); None when a field is anything but a word or empty."""
    values = [body[a:b] for a, b in zip(starts, ends)]
    if not any(values):
        return np.full(len(values), np.nan)
    if any(v and (not _WORD.fullmatch(v) or v.lower() in _NOT_WORDS or v in _NOT_WORDS) for v in values):
        return None
    return np.array([v if v else np.nan for v in values], dtype=object)


def _column(data: np.ndarray, starts: np.ndarray, lengths: np.ndarray) -> np.ndarray | None:
    """One column's fields (their first bytes and lengths in ``data``) as numbers: int64 when every field is an
    integer, else float64 with NaN for an empty field; None when a field is not a number."""
    filled = lengths > 0
    if not filled.any():
        return np.full(len(lengths), np.nan)
    first, size = starts[filled], lengths[filled]
    spans = size + 1  # each field and the separator after it
    ends = np.cumsum(spans)
    chars = data[np.repeat(first - (ends - spans), spans) + np.arange(int(ends[-1]))]
    chars[ends - 1] = COMMA
    if not _ALLOWED[chars].all():
        return None
    is_float = not filled.all() or bool(_FLOAT_MARKS[chars].any())
    if not is_float:
        return _integers(chars, ends - spans, ends) if int(size.max()) <= MAX_INT_CHARS else None
    values = _numbers(chars[:-1].tobytes().decode("ascii"), len(first))
    if values is None:
        return None
    if filled.all():
        return values
    out = np.full(len(lengths), np.nan)
    out[filled] = values
    return out


def _integers(chars: np.ndarray, starts: np.ndarray, ends: np.ndarray) -> np.ndarray | None:
    """Fields of digits with an optional leading sign (each from ``starts`` to the separator before ``ends``, at most
    :data:`MAX_INT_CHARS` characters) as int64, summed digit by digit at once (each digit times its power of ten);
    None when a field has a sign elsewhere or no digit. What NumPy's parser reads from them, exactly."""
    digit = (chars >= ord("0")) & (chars <= ord("9"))
    sign = (chars == ord("+")) | (chars == ord("-"))
    if sign.any():
        at_start = np.zeros(len(chars), dtype=bool)
        at_start[starts] = True
        if (sign & ~at_start).any():
            return None
    if (np.add.reduceat(digit, starts) == 0).any():
        return None
    after = np.repeat(ends - 2, ends - starts) - np.arange(len(chars))  # characters after this one in its field
    worth = np.where(digit, (chars.astype(np.int64) - ord("0")) * _POWERS[np.clip(after, 0, MAX_INT_CHARS)], 0)
    values = np.add.reduceat(worth, starts)
    values[chars[starts] == ord("-")] *= -1
    return values


_POWERS = 10 ** np.arange(MAX_INT_CHARS + 1, dtype=np.int64)


def _numbers(text: str, count: int) -> np.ndarray | None:
    """``count`` comma-separated numbers of ``text`` as float64, or None when one is not a number. NumPy's parser
    (the C library's strtod grammar, correctly rounded) takes an optional sign, digits with at most one point and an
    optional exponent, as pandas' does, and refuses a lone sign or point, a second point or sign, an exponent without
    digits (tests/test_plaincsv.py)."""
    with warnings.catch_warnings():
        warnings.simplefilter("error", DeprecationWarning)  # NumPy's "could not be read to its end"
        try:
            values = np.fromstring(text, dtype=np.float64, sep=",")
        except (ValueError, DeprecationWarning):
            return None
    return values if len(values) == count else None
