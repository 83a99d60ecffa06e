"""The rows' times a block at a time: ``telemetry_reader.file_times`` over the whole
file, its problems found across blocks and told in its order, with its row numbers.

The ISO 8601 tags of a block all written alike (``2026-03-20T12:00:00.512Z``, the
layout telemetry.csv writes) are read by integer arithmetic on their characters,
about 15 times faster than NumPy's parser and to the same nanosecond
(``fixed_layout_ns``; tests/scenarios/test_telemetry_spool.py checks it against
``tag_ns``); any other block goes through ``tag_ns`` itself.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..columns import epoch_ns, utc_text
from ..telemetry_reader import _apart, _no_time, _seconds, _seconds_epoch, tag_ns
from .blocks import Header

# tag_ns' three refusals, in the order it looks for them over the whole column.
KINDS = ("no time tag", "is not UTC", "is not an ISO 8601 time")
DAYS_BEFORE_MONTH = np.array([0, 31, 59, 90, 120, 151, 181, 212, 243, 273, 304, 334])


class Times:
    """``file_times`` for a file read in blocks: ``block`` gives each block's t_s
    (None where it has none), ``problems`` the whole read's lines once every block is
    seen, and ``known`` whether the whole read has a t_s at all."""

    def __init__(self, path: Path, head: Header, present: set[str], s):
        from ..telemetry_reader import Table
        self.path, self.spec = path, s.telemetry
        c = self.spec.columns
        self.scen = int(epoch_ns(s.epoch_utc).astype(np.int64))
        self.scen_text = utc_text(epoch_ns(s.epoch_utc))
        self.has_secs, self.has_tags = c.t_s in present, c.time_utc in present
        self.tag_problem: dict[str, tuple[int, str]] = {}     # kind -> (row, line)
        self.first: tuple | None = None                       # (t[0], ns[0]) of row 0
        self.secs_text = False
        self.epoch, self.epoch_problem = None, None
        self.header_problem = None
        if not self.has_secs and not self.has_tags:
            self.header_problem = _no_time(path, Table({}, head.names, head.epoch,
                                                       head.epoch_source), self.spec)
        elif self.has_secs:
            table = Table({}, head.names, head.epoch, head.epoch_source)
            self.epoch, self.epoch_problem = _seconds_epoch(path, table, self.spec)

    @property
    def known(self) -> bool:
        """Whether the whole read returns a t_s (file_times' t is not None)."""
        if self.header_problem or self.secs_text:
            return False
        return self.has_secs or not self.tag_problem

    def block(self, cols: dict, row0: int) -> np.ndarray | None:
        c = self.spec.columns
        ns = self._tags(cols[c.time_utc], row0) if self.has_tags else None
        if not self.has_secs:
            if ns is None:
                return None
            if row0 == 0 and len(ns):
                self.first = (None, int(ns[0]))
            return _seconds(ns - self.scen)
        secs = cols[c.t_s]
        if secs.dtype.kind not in "fiu":
            self.secs_text = True
            return None
        t = np.asarray(secs, dtype=float)
        if row0 == 0 and len(t):
            self.first = (t[0], None if ns is None or not len(ns) else int(ns[0]))
        if self.epoch is None or self.epoch[0] == self.scen:
            return t
        return t + (self.epoch[0] - self.scen) / 1e9

    def _tags(self, tags, row0: int) -> np.ndarray | None:
        if len(tags) == 0:
            return np.zeros(0, dtype=np.int64)
        ns = fixed_layout_ns(tags)
        if ns is not None:
            return ns
        tags = _as_text(tags)
        ns, problems = tag_ns(self.path, self.spec.columns.time_utc, tags)
        if problems:
            # tag_ns reports the first row of the first of its kinds found in the
            # block; over the file, the first of each kind is kept (see problems).
            line = problems[0]
            kind = next(k for k in KINDS if k in line)
            prefix = f"{self.path}: row "
            rest = line[len(prefix):]
            digits = len(rest) - len(rest.lstrip("0123456789"))
            row = int(rest[:digits]) - 2 + row0
            if kind not in self.tag_problem:
                self.tag_problem[kind] = (row, f"{prefix}{row + 2}{rest[digits:]}")
            return None
        return ns

    def problems(self, n_rows: int) -> list[str]:
        """file_times' lines, in its order."""
        if self.header_problem:
            return [self.header_problem]
        spec, path, tol = self.spec, self.path, self.spec.epoch_tolerance_s
        c = spec.columns
        out = []
        tag_ok = self.has_tags and n_rows > 0 and not self.tag_problem
        if self.tag_problem:
            # tag_ns looks for empty tags over the whole column, then zones, then
            # the parse: the first kind found anywhere, at its first row.
            out.append(next(self.tag_problem[k][1] for k in KINDS if k in self.tag_problem))
        if not self.has_secs:
            if tag_ok:
                d, how = _apart(self.first[1], self.scen)
                if abs(d) > tol:
                    first = utc_text(np.array([self.first[1]]).view("datetime64[ns]"))[0]
                    out.append(f"{path}: its epoch {first} (the first {c.time_utc}) is "
                               f"{how} the scenario's epoch_utc {self.scen_text} (tolerance "
                               f"{tol:g} s): set epoch_utc to the file's start")
            return out
        if self.secs_text:
            return out + [f"{path}: column {c.t_s} holds text, not seconds"]
        out += [self.epoch_problem] if self.epoch_problem else []
        if self.epoch is None:
            return out
        d, how = _apart(self.epoch[0], self.scen)
        if abs(d) > tol:
            out.append(f"{path}: its epoch_utc {utc_text(np.datetime64(self.epoch[0], 'ns'))} "
                       f"({self.epoch[1]}) is {how} the scenario's epoch_utc {self.scen_text} "
                       f"(tolerance {tol:g} s): its {c.t_s} counts from another "
                       "time; set the scenario's epoch_utc to the file's")
        if tag_ok and self.first is not None and np.isfinite(self.first[0]):
            first = self.epoch[0] + int(round(self.first[0] * 1e9))
            d_tag, how_tag = _apart(self.first[1], first)
            if abs(d_tag) > tol:
                out.append(f"{path}: its first {c.time_utc} is {how_tag} its "
                           f"epoch_utc + {c.t_s} (tolerance {tol:g} s): the two "
                           "time columns disagree")
        return out


def _as_text(tags) -> np.ndarray:
    """A block's tags as NumPy text (pyarrow's strings as ``_parse_body`` gives them)."""
    if isinstance(tags, np.ndarray):
        return tags
    # _parse_body reads an empty cell as "nan", and then "nan" as "".
    return np.array(["" if v is None or v == "nan" else v for v in tags.to_pylist()],
                    dtype=str)


def _char_matrix(tags) -> np.ndarray | None:
    """The tags as an (n, L) matrix of character codes when every tag has L ASCII
    characters (None otherwise)."""
    if isinstance(tags, np.ndarray):
        if tags.dtype.kind == "i":
            return None
        if tags.dtype.kind != "U" or not len(tags):
            return None
        width = tags.dtype.itemsize // 4
        codes = tags.view(np.uint32).reshape(len(tags), width)
        if width == 0 or not np.all(codes[:, -1]) or codes.max() >= 128:
            return None
        return codes
    import pyarrow as pa
    if tags.null_count or not len(tags):
        return None
    if not pa.types.is_string(tags.type):
        return None
    offsets = np.frombuffer(tags.buffers()[1], dtype=np.int32,
                            count=len(tags) + 1, offset=tags.offset * 4)
    width = int(offsets[1] - offsets[0])
    if width == 0 or np.any(np.diff(offsets) != width):
        return None
    data = np.frombuffer(tags.buffers()[2], dtype=np.uint8)[offsets[0]:offsets[-1]]
    return data.reshape(len(tags), width)


def fixed_layout_ns(tags) -> np.ndarray | None:
    """``tag_ns`` of tags all written ``YYYY-MM-DDTHH:MM:SS[.f…]`` with up to 9
    fraction digits and an optional final Z, each a valid date and time of 1900–2199
    (the instants NumPy's parser gives, to the nanosecond); None for any other block,
    which ``tag_ns`` then reads."""
    m = _char_matrix(tags)
    if m is None:
        return None
    width = m.shape[1]
    z = int(m[0, -1]) in (ord("Z"), ord("z"))
    if z and not np.all(m[:, -1] == m[0, -1]):
        return None
    body = width - z
    frac = body - 20
    if body < 19 or frac == 0 or frac > 9:
        return None
    layout = "dddd-dd-ddTdd:dd:dd" + ("." + "d" * frac if frac > 0 else "")
    # One pass over the characters: a digit's code less 48 is at most 9 (unsigned),
    # a separator's less its own is 0.
    low = np.array([48 if ch == "d" else ord(ch) for ch in layout], dtype=m.dtype)
    span = np.array([9 if ch == "d" else 0 for ch in layout], dtype=m.dtype)
    if np.any((m[:, :body] - low) > span):
        return None

    def num(a: int, b: int) -> np.ndarray:
        out = m[:, a].astype(np.int64) - 48
        for j in range(a + 1, b):
            out = out * 10 + (m[:, j].astype(np.int64) - 48)
        return out
    year, month, day = num(0, 4), num(5, 7), num(8, 10)
    hour, minute, sec = num(11, 13), num(14, 16), num(17, 19)
    leap = (year % 4 == 0) & ((year % 100 != 0) | (year % 400 == 0))
    if np.any((year < 1900) | (year > 2199) | (month < 1) | (month > 12) | (day < 1)
              | (hour > 23) | (minute > 59) | (sec > 59)):
        return None
    month_days = np.array([31, 28, 31, 30, 31, 30, 31, 31, 30, 31, 30, 31])[month - 1]
    if np.any(day > month_days + ((month == 2) & leap)):
        return None
    y = year - 1
    days = (365 * y + y // 4 - y // 100 + y // 400 - 719162       # 1970-01-01 is day 0
            + DAYS_BEFORE_MONTH[month - 1] + ((month > 2) & leap) + day - 1)
    ns = ((days * 24 + hour) * 60 + minute) * 60 + sec
    ns = ns * 10**9
    if frac > 0:
        ns = ns + num(20, 20 + frac) * 10 ** (9 - frac)
    return ns
