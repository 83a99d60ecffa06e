"""A real telemetry file read into dynprop's own columns (docs/telemetry.md).

A ground system's file names its columns its own way, holds angles in µrad or
rad and wheel speeds in rad/s, dates its rows in UTC and may be Parquet.  The
scenario's ``telemetry`` section (``config.sections.Telemetry``; `dynprop estimate
--column/--unit/--epoch-utc`) says which column is which and in what unit; here
each is read and converted at the boundary to the canonical columns the rest of
dynprop reads: ``t_s`` in seconds from the scenario's ``epoch_utc``,
``roll_deg``/``pitch_deg``/``yaw_deg``/``yaw_sigma_deg`` in degrees,
``wheelN_rpm`` in rpm, ``sun_head`` (0, 1, 2) and ``maneuver`` (0, 1).  dynprop's own
telemetry.csv is read as it is: its t_s and values bit for bit.

The time is either ``t_s`` seconds from an epoch (the file's ``# epoch_utc:`` line
or Parquet key-value metadata ``epoch_utc``, else ``telemetry.epoch_utc``, else the
scenario's) or ``time_utc`` ISO 8601 UTC tags (a Parquet timestamp column too).
Either way the file's epoch (for tags, its first tag) must be within
``telemetry.epoch_tolerance_s`` of the scenario's: the Sun and the orbit are
computed from the scenario's epoch, so the scenario must start where the data does.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..config.suggestions import closest
from ..units import RAD2DEG, RADPS2RPM
from .columns import epoch_ns, utc_text
from .csvio import comments, non_number_cells, read_csv
from .rundir import RunDirError

# telemetry.columns key -> (canonical column, unit key in telemetry.units, required)
MEASUREMENTS = {
    "roll": ("roll_deg", "roll", True),
    "pitch": ("pitch_deg", "pitch", False),
    "yaw": ("yaw_deg", "yaw", True),
    "yaw_sigma": ("yaw_sigma_deg", "yaw_sigma", False),
    "sun_head": ("sun_head", None, False),
    "maneuver": ("maneuver", None, False),
}
# The factor from each unit to the canonical one (None: the values as they are, so
# that a file in degrees and rpm is read bit for bit).
TO_DEG = {"deg": None, "rad": RAD2DEG, "urad": 1e-6 * RAD2DEG}
TO_RPM = {"rpm": None, "rad/s": RADPS2RPM}
# The raw Sun-sensor angles of dynprop's own telemetry.csv, read when a file has them
# (by these names, in degrees) so that the screen can judge each head's field of view.
SUN_ANGLE_COLUMNS = tuple(f"{h}_{a}_deg" for h in ("dss", "cass1", "cass2")
                          for a in ("alpha", "beta"))
PARQUET_SUFFIXES = (".parquet", ".pq")
NS_PER = {"s": 10**9, "ms": 10**6, "us": 10**3, "ns": 1}


@dataclass(frozen=True)
class Table:
    """What a file holds: ``columns`` the ones asked for (numbers as float, NaN where
    empty; time tags as text, "" where empty, or as int64 ns from a Parquet
    timestamp), ``names`` every column it has, ``epoch`` its own epoch_utc, if any."""

    columns: dict[str, np.ndarray]
    names: list[str]
    epoch: str | None
    epoch_source: str
    # Per numeric column, the cells whose text (or Parquet value) was a non-number
    # such as ``nan`` or ``inf``: not a dropout (an empty cell) but a bad value.
    written: dict[str, np.ndarray] = field(default_factory=dict)


def is_parquet(path: Path) -> bool:
    return Path(path).suffix.lower() in PARQUET_SUFFIXES


def wheel_keys(n_wheels: int) -> list[tuple[str, str]]:
    """(telemetry.columns key, canonical column) of each wheel."""
    return [(f"wheel{i + 1}", f"wheel{i + 1}_rpm") for i in range(n_wheels)]


def mapped_name(columns, key: str, canonical: str) -> str:
    """The file's column for a key (the canonical name when the section has no key)."""
    return getattr(columns, key, canonical)


def read_table(path: Path, spec, n_wheels: int) -> Table:
    """The columns ``spec`` (the scenario's ``telemetry`` section) names, from a CSV
    or (by its suffix) a Parquet file; a RunDirError in one line if it cannot be read."""
    path = Path(path)
    c = spec.columns
    wanted = {c.t_s, c.time_utc, *(mapped_name(c, k, canon) for k, (canon, _, _)
                                   in MEASUREMENTS.items()),
              *(mapped_name(c, k, canon) for k, canon in wheel_keys(n_wheels)),
              *SUN_ANGLE_COLUMNS}
    if is_parquet(path):
        return read_parquet(path, wanted, c.time_utc)
    cols = read_input_csv(path, "telemetry", text=(c.time_utc,), only=wanted)
    with open(path) as fh:
        header = next((line for line in fh if not line.startswith("#")), "")
    return Table(cols, header.strip().split(","), comments(path).get("epoch_utc"),
                 "its # epoch_utc line",
                 non_number_cells(path, [n for n, v in cols.items() if v.dtype.kind == "f"]))


def read_input_csv(path: Path, kind: str, **how) -> dict[str, np.ndarray]:
    """The columns of a CSV the user named (``how``: ``csvio.read_csv``'s ``text`` and
    ``only``), or one line saying why it cannot be read."""
    if not path.is_file():
        raise RunDirError(f"{path}: no such {kind} file")
    try:
        return read_csv(path, **how)
    except UnicodeDecodeError:
        raise RunDirError(f"{path}: not a CSV text file (it holds bytes that are not UTF-8 "
                          "text)") from None
    except ValueError as exc:
        # read_csv's own one line, naming the file, the row and the column.
        raise RunDirError(str(exc).splitlines()[0]) from None


def parquet_file(path: Path):
    """``path`` opened as a ``pyarrow.parquet.ParquetFile`` (its schema read), or one
    line saying why not: no pyarrow, no such file, not Parquet."""
    try:
        import pyarrow as pa
        import pyarrow.parquet as pq
    except ImportError:
        raise RunDirError(f"{path}: reading Parquet needs pyarrow: pip install "
                          "'dynprop[parquet]'") from None
    if not path.is_file():
        raise RunDirError(f"{path}: no such telemetry file")
    try:
        pf = pq.ParquetFile(path)
        _ = pf.schema_arrow    # converted here: a schema pyarrow refuses is this line too
    except (pa.ArrowException, OSError) as exc:
        raise not_parquet(path, exc) from None
    return pf


def not_parquet(path: Path, exc: Exception) -> RunDirError:
    return RunDirError(f"{path}: not a Parquet file pyarrow can read "
                       f"({str(exc).splitlines()[0] if str(exc) else type(exc).__name__})")


def read_parquet(path: Path, wanted: set[str], time_col: str) -> Table:
    """The ``wanted`` columns of a Parquet file and its ``epoch_utc`` metadata."""
    pf = parquet_file(path)
    import pyarrow as pa
    schema = pf.schema_arrow
    try:
        table = pf.read(columns=[n for n in schema.names if n in wanted])
    except (pa.ArrowException, OSError) as exc:
        raise not_parquet(path, exc) from None
    meta = {k.decode(errors="replace"): v.decode(errors="replace")
            for k, v in (schema.metadata or {}).items()}
    columns, problems, written = {}, [], {}
    for name in table.column_names:
        col = table.column(name)
        nulls = col.is_null().to_numpy(zero_copy_only=False)
        if pa.types.is_timestamp(col.type):
            # An Arrow timestamp is an instant counted in UTC whatever its zone says.
            raw = col.cast(pa.int64()).fill_null(0).to_numpy(zero_copy_only=False)
            columns[name] = raw.astype(np.int64) * NS_PER[col.type.unit]
            if nulls.any():
                problems.append(f"{path}: row {int(np.argmax(nulls)) + 2}, column {name}: "
                                "no time tag")
        elif pa.types.is_string(col.type) or pa.types.is_large_string(col.type):
            if name != time_col:
                problems.append(f"{path}: column {name} holds text, not numbers")
                continue
            columns[name] = np.array(["" if v is None else v for v in col.to_pylist()],
                                     dtype=str)
        elif pa.types.is_integer(col.type) or pa.types.is_floating(col.type) \
                or pa.types.is_boolean(col.type):
            values = col.cast(pa.float64()).to_numpy(zero_copy_only=False)
            columns[name] = np.where(nulls, np.nan, values)
            # A null is a dropout, and so is a NaN: numpy-based writers store a missing
            # float as NaN.  An infinity is a bad value (an overflow).
            bad = np.isinf(values) & ~nulls
            if bad.any():
                written[name] = bad
        else:
            problems.append(f"{path}: column {name} has type {col.type}, not numbers or "
                            "time tags")
    if problems:
        raise RunDirError("\n".join(problems))
    return Table(columns, list(schema.names), meta.get("epoch_utc"),
                 "its Parquet metadata epoch_utc", written)


def converted(values: np.ndarray, factor: float | None) -> np.ndarray:
    return values if factor is None else values * factor


def measurements(path: Path, table: Table, spec, n_wheels: int
                 ) -> tuple[dict[str, np.ndarray], list[str]]:
    """The canonical measurement columns of ``table`` (``spec``: the scenario's
    ``telemetry`` section) in degrees and rpm, and one line per problem: a required
    column the file lacks, or one the section names that it lacks (with the file's
    column most like it)."""
    time_names = {spec.columns.t_s, spec.columns.time_utc}
    keys = [(key, canon, TO_DEG[getattr(spec.units, unit)] if unit else None, required)
            for key, (canon, unit, required) in MEASUREMENTS.items()]
    keys += [(key, canon, TO_RPM[spec.units.wheels], True) for key, canon in wheel_keys(n_wheels)]
    named = {mapped_name(spec.columns, key, canon) for key, canon, _, _ in keys}
    unused = [c for c in table.names if c not in named and c not in time_names]
    out, problems = {}, []
    for key, canon, factor, required in keys:
        name = mapped_name(spec.columns, key, canon)
        values = table.columns.get(name)
        if values is not None:
            if values.dtype.kind not in "fiu":
                problems.append(f"{path}: column {name} holds text, not numbers")
            else:
                out[canon] = converted(np.asarray(values, dtype=float), factor)
            continue
        if name != canon:
            # The section names this column: its absence is an error, optional or not.
            typo = closest(name, unused)
            problems.append(f"{path}: no column {name} (telemetry.columns.{key})"
                            + (f"; did you mean '{typo}'?" if typo else ""))
        elif required:
            # A file column that looks like the missing one is most likely it, misspelt:
            # name the file's column and suggest the valid name, as for a scenario key.
            typo = closest(name, unused)
            problems.append(f"{path}: unknown column {typo}; did you mean '{name}'?" if typo
                            else f"{path}: missing column {name}")
    for name in SUN_ANGLE_COLUMNS:
        values = table.columns.get(name)
        if values is not None and values.dtype.kind in "fiu":
            out[name] = np.asarray(values, dtype=float)
    return out, problems


def written_marks(table: Table, spec, n_wheels: int) -> dict[str, np.ndarray]:
    """``Table.written`` by canonical column (``measurements``' names)."""
    canon = {mapped_name(spec.columns, key, c): c for key, (c, _, _) in MEASUREMENTS.items()}
    canon |= {mapped_name(spec.columns, key, c): c for key, c in wheel_keys(n_wheels)}
    canon |= {n: n for n in SUN_ANGLE_COLUMNS}
    return {canon[n]: m for n, m in table.written.items() if n in canon}


def file_names(spec, n_wheels: int) -> dict[str, str]:
    """The file's name of each canonical column, for messages."""
    names = {c: mapped_name(spec.columns, key, c) for key, (c, _, _) in MEASUREMENTS.items()}
    return names | {c: mapped_name(spec.columns, key, c) for key, c in wheel_keys(n_wheels)}


def _span(seconds: float) -> str:
    a = abs(seconds)
    if a >= 2 * 86400:
        return f"{a / 86400:.3g} days"
    if a >= 2 * 3600:
        return f"{a / 3600:.3g} h"
    if a >= 120:
        return f"{a / 60:.3g} min"
    return f"{a:.3g} s"


def _apart(ns: int, ref_ns: int) -> tuple[float, str]:
    """Seconds between two instants and how the first stands to the second."""
    d = (ns - ref_ns) / 1e9
    return d, f"{_span(d)} {'after' if d > 0 else 'before'}"


def _seconds(ns: np.ndarray) -> np.ndarray:
    """int64 ns as float seconds, exact to the double's precision (a year of ns does
    not fit a double's 53 bits whole)."""
    whole, part = np.divmod(ns, 10**9)
    return whole.astype(float) + part / 1e9


def tag_ns(path: Path, name: str, tags: np.ndarray) -> tuple[np.ndarray | None, list[str]]:
    """ISO 8601 UTC tags as int64 ns since 1970 (None, with one line, if any is not):
    ``Z``, ``+00:00`` or no zone are UTC; another offset is refused, since it would
    say the file's clock is not UTC."""
    if tags.dtype.kind in "iu":              # a Parquet timestamp, in ns already
        return tags.astype(np.int64), []
    text = np.char.strip(tags.astype(str))
    empty = text == ""
    if empty.any():
        return None, [f"{path}: row {int(np.argmax(empty)) + 2}, column {name}: no time tag"]
    text = np.char.rstrip(text, "Zz")
    text = np.char.replace(text, "+00:00", "")
    sep = np.maximum(np.char.find(text, "T"), np.char.find(text, " "))
    zone = (sep >= 0) & ((np.char.rfind(text, "+") > sep) | (np.char.rfind(text, "-") > sep))
    if zone.any():
        k = int(np.argmax(zone))
        return None, [f"{path}: row {k + 2}, column {name}: {str(tags[k]).strip()!r} is not "
                      "UTC; time tags must be UTC (Z, +00:00 or no zone)"]
    try:
        ns = _parsed(text)
        bad = np.isnat(ns)
    except (ValueError, UserWarning):
        bad = np.array([_not_a_time(t) for t in text])
    if bad.any():
        k = int(np.argmax(bad))
        return None, [f"{path}: row {k + 2}, column {name}: {str(tags[k]).strip()!r} is not "
                      "an ISO 8601 time (2026-03-20T12:00:00.512Z)"]
    return ns.view(np.int64), []


def _parsed(text) -> np.ndarray:
    """NumPy's ISO 8601 parse; what it would take for a zone (a stray letter) is an
    error, not a warning."""
    with warnings.catch_warnings():
        warnings.simplefilter("error", UserWarning)
        return np.array(text, dtype="datetime64[ns]")


def _not_a_time(text: str) -> bool:
    try:
        return bool(np.isnat(_parsed(text)))
    except (ValueError, UserWarning):
        return True


def file_times(path: Path, table: Table, s) -> tuple[np.ndarray | None, list[str]]:
    """t_s in seconds from the scenario's epoch_utc, and one line per problem (see
    the module doc).  With both t_s and time_utc, t_s (exact) is taken and time_utc's
    first tag checked against it."""
    spec = s.telemetry
    tol = spec.epoch_tolerance_s
    scen = int(epoch_ns(s.epoch_utc).astype(np.int64))
    scen_text = utc_text(epoch_ns(s.epoch_utc))
    secs = table.columns.get(spec.columns.t_s)
    tags = table.columns.get(spec.columns.time_utc)
    if secs is None and tags is None:
        return None, [_no_time(path, table, spec)]
    problems = []
    ns = None
    if tags is not None and len(tags):
        ns, problems = tag_ns(path, spec.columns.time_utc, tags)
    if secs is None:
        if ns is None:
            return (np.empty(0) if not problems else None), problems
        d, how = _apart(int(ns[0]), scen)
        if abs(d) > tol:
            problems.append(f"{path}: its epoch {utc_text(ns[:1].view('datetime64[ns]'))[0]} "
                            f"(the first {spec.columns.time_utc}) is {how} the scenario's "
                            f"epoch_utc {scen_text} (tolerance {tol:g} s): set epoch_utc to "
                            "the file's start")
        return _seconds(ns - scen), problems
    if secs.dtype.kind not in "fiu":
        return None, problems + [f"{path}: column {spec.columns.t_s} holds text, not seconds"]
    epoch, problem = _seconds_epoch(path, table, spec)
    problems += [problem] if problem else []
    if epoch is None:
        return np.asarray(secs, dtype=float), problems
    t = np.asarray(secs, dtype=float)
    d, how = _apart(epoch[0], scen)
    if abs(d) > tol:
        problems.append(f"{path}: its epoch_utc {utc_text(np.datetime64(epoch[0], 'ns'))} "
                        f"({epoch[1]}) is {how} the scenario's epoch_utc {scen_text} "
                        f"(tolerance {tol:g} s): its {spec.columns.t_s} counts from another "
                        "time; set the scenario's epoch_utc to the file's")
    if ns is not None and len(t) and np.isfinite(t[0]):
        # The tags and the seconds must say the same time.
        first = epoch[0] + int(round(t[0] * 1e9))
        d_tag, how_tag = _apart(int(ns[0]), first)
        if abs(d_tag) > tol:
            problems.append(f"{path}: its first {spec.columns.time_utc} is {how_tag} its "
                            f"epoch_utc + {spec.columns.t_s} (tolerance {tol:g} s): the two "
                            "time columns disagree")
    # Seconds from the file's epoch are seconds from the scenario's (within tolerance):
    # the difference is added, and nothing at all when there is none (dynprop's own).
    return (t if epoch[0] == scen else t + (epoch[0] - scen) / 1e9), problems


def _seconds_epoch(path: Path, table: Table, spec) -> tuple[tuple[int, str] | None, str | None]:
    """The epoch a t_s column counts from, in ns, and where it was said (None: the
    scenario's own, as for dynprop's telemetry.csv of before it carried one)."""
    given = []
    for text, source in ((table.epoch, table.epoch_source),
                         (spec.epoch_utc, "telemetry.epoch_utc")):
        if text is None:
            continue
        try:
            given.append((int(epoch_ns(text).astype(np.int64)), source))
        except ValueError as exc:
            return None, f"{path}: {source}: {exc}"
    if not given:
        return None, None
    if len(given) == 2 and abs(given[0][0] - given[1][0]) > spec.epoch_tolerance_s * 1e9:
        _, how = _apart(given[1][0], given[0][0])
        return given[0], (f"{path}: telemetry.epoch_utc {spec.epoch_utc} is {how} "
                          f"{given[0][1]} {table.epoch}; leave telemetry.epoch_utc out (the "
                          "file says its epoch)")
    return given[0], None


def _no_time(path: Path, table: Table, spec) -> str:
    names = (spec.columns.t_s, spec.columns.time_utc)
    for name in names:
        typo = closest(name, table.names)
        if typo:
            return f"{path}: unknown column {typo}; did you mean '{name}'?"
    return f"{path}: missing column {names[0]} (or {names[1]}): the time of each row"
