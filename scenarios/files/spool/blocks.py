"""A telemetry file a block of rows at a time, each block's values exactly those the
whole read (``telemetry_reader.read_table``) holds for its rows, and each problem its
one line, with the file's row numbers.

CSV: line-aligned chunks (4 MB, or ``block_rows`` lines), each parsed as
``csvio.read_csv`` parses the whole body: by ``csvio._parse_body`` (NumPy's loadtxt,
CPython's correctly rounded ``PyOS_string_to_double``), or, when pyarrow is installed
and gives the same doubles as loadtxt on a table of hard cases (``arrow_agrees``), by
pyarrow's CSV reader, about six times faster; a chunk arrow refuses is parsed by
loadtxt, whose error is the whole read's.  One known difference: a file with a row one
field short and another one field long passes the whole read's count of commas (and is
read, misaligned) but not a block's, unless both rows fall in one block.  Cells
written ``nan`` or ``inf`` are marked as ``csvio.non_number_cells`` marks them.
Parquet: ``ParquetFile.iter_batches``, each batch converted as
``telemetry_reader.read_parquet`` converts the whole table.
"""

from __future__ import annotations

import codecs
import functools
import locale
import re
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..csvio import _first_bad_row, _parse_body, comments, marks_of, non_number_rows
from ..rundir import RunDirError
from ..telemetry_reader import NS_PER, not_parquet, parquet_file

CHUNK_CHARS = 4 << 20       # text read per block: ~38 k telemetry rows (a larger block is
                            # no faster, and malloc keeps more of it)
PARQUET_BATCH = 1 << 16     # rows per Parquet batch


@dataclass(frozen=True)
class Header:
    """What the whole read's ``Table`` says of the file besides its rows."""

    names: list[str]            # every column of the file
    epoch: str | None
    epoch_source: str


@dataclass(frozen=True)
class Block:
    """Rows [row0, row0 + n) of the file (0: the first data row): the wanted columns
    (numbers as float, NaN where empty; time tags as text or int64 ns) and, per
    numeric column, the cells written as a non-number (``Table.written``)."""

    row0: int
    n: int
    columns: dict[str, np.ndarray]
    written: dict[str, np.ndarray] = field(default_factory=dict)


def read_blocks(path: Path, wanted: set[str], time_col: str, block_rows: int | None
                ) -> tuple[Header, Iterator[Block]]:
    """The file's header and its blocks (at least one, empty for a file without
    rows); a RunDirError in one line when it cannot be read, as the whole read's."""
    from ..telemetry_reader import is_parquet
    if is_parquet(path):
        return _parquet_blocks(path, wanted, time_col, block_rows)
    return _csv_blocks(path, wanted, (time_col,), block_rows)


# --------------------------------------------------------------------------- CSV

def _csv_blocks(path: Path, only: set[str], text_cols, block_rows):
    if not path.is_file():
        raise RunDirError(f"{path}: no such telemetry file")
    fh = open(path)  # noqa: SIM115 (closed by the generator)
    try:
        lines = [fh.readline()]
        while lines[-1].startswith("#"):
            lines.append(fh.readline())
    except UnicodeDecodeError:
        fh.close()
        raise _not_text(path) from None
    header = lines[-1]
    names = header.strip().split(",")
    if not header.strip():
        blank = _rest_is_blank(fh, path)
        fh.close()
        raise RunDirError(f"{path}: the file is empty (no header)" if blank
                          else f"{path}: row 1 is empty; it must be the header of column names")
    wanted = [n for n in names if n in only]
    text = [n for n in wanted if n in text_cols]
    numbers = [n for n in wanted if n not in text_cols]
    head = Header(names, comments(path).get("epoch_utc"), "its # epoch_utc line")
    return head, _csv_rows(_as_bytes(fh, path, lines), path, names, wanted, text, numbers,
                           block_rows)


def _as_bytes(fh, path: Path, lines: list[str]):
    """The file after its header, opened as bytes when its text is UTF-8 (or ASCII)
    and its header lines end in \n or \r\n (then each chunk is handed to the parser
    as it is, when it is ASCII without \r, or decoded as ``open`` decodes it);
    otherwise ``fh`` itself, read as text."""
    enc = codecs.lookup(locale.getpreferredencoding(False)).name
    if enc not in ("utf-8", "ascii"):
        return fh
    raw = open(path, "rb")  # noqa: SIM115 (closed by the generator)
    for line in lines:
        got = raw.readline().decode(enc, errors="replace")
        if "\r" in got.removesuffix("\r\n") or got.replace("\r\n", "\n") != line:
            raw.close()
            return fh
    fh.close()
    return raw


def _not_text(path) -> RunDirError:
    return RunDirError(f"{path}: not a CSV text file (it holds bytes that are not UTF-8 text)")


def _rest_is_blank(fh, path) -> bool:
    try:
        return all(not chunk.strip() for chunk in iter(lambda: fh.read(CHUNK_CHARS), ""))
    except UnicodeDecodeError:
        raise _not_text(path) from None


def _chunks(fh, block_rows: int | None) -> Iterator:
    """The text (or bytes) after the header in pieces that end at a line's end (the
    last at the file's), of ``block_rows`` lines each when given."""
    while piece := fh.read(CHUNK_CHARS):
        nl = "\n" if isinstance(piece, str) else b"\n"
        if not piece.endswith(nl):
            piece += fh.readline()
        yield from _by_lines(piece, block_rows, nl)


def _by_lines(text, block_rows: int | None, nl) -> Iterator:
    if block_rows is None:
        if text:
            yield text
        return
    start = 0
    while start < len(text):
        end = start
        for _ in range(block_rows):
            end = text.find(nl, end) + 1
            if end == 0:
                end = len(text)
                break
        yield text[start:end]
        start = end


def _text(chunk) -> tuple[str | None, bytes | None]:
    """A chunk as ``open`` would read it (str, with \r\n and \r as \n) and, when
    that is its very bytes (ASCII without \r), as bytes; decoded only if needed."""
    if isinstance(chunk, str):
        return chunk, None
    if chunk.isascii() and b"\r" not in chunk:
        return None, chunk
    text = chunk.decode("utf-8")
    return (text.replace("\r\n", "\n").replace("\r", "\n") if "\r" in text else text), None


def _csv_rows(fh, path, names, wanted, text, numbers, block_rows) -> Iterator[Block]:
    row0, blank_lines, any_rows = 0, False, False
    arrow = _arrow_reader(names, text, numbers) if arrow_agrees() else None
    with fh:
        try:
            for chunk in _chunks(fh, block_rows):
                body, data = _text(chunk)
                if (body or data).isspace():
                    # Blank lines are skipped by the parser; a line of spaces is not
                    # (the whole body is then an error, unless it holds nothing else).
                    blank_lines |= bool((body or data.decode()).strip("\n"))
                    continue
                cols = None
                if arrow is not None:
                    cols = arrow(data if data is not None else body.encode())
                if cols is None:
                    try:
                        cols = _parse_body(body or data.decode(), names, text, numbers)
                    except ValueError:
                        raise _bad_csv(path, names, wanted, text, block_rows) from None
                n = len(cols[wanted[0]]) if wanted else 0
                any_rows = True
                yield Block(row0, n, cols, _written(body, data, names, numbers, n))
                row0 += n
        except UnicodeDecodeError:
            raise _not_text(path) from None
    if blank_lines and any_rows:
        raise _bad_csv(path, names, wanted, text, block_rows)
    if not any_rows:
        yield Block(0, 0, {n: np.empty(0, dtype=str if n in text else float)
                           for n in wanted})


def _bad_csv(path, names, wanted, text, block_rows) -> RunDirError:
    """``read_csv``'s one line for a file NumPy cannot parse: the first row
    ``_first_bad_row`` finds in the whole body (numbered as its lines are), found chunk
    by chunk from the start; a file that is not UTF-8 anywhere says so instead, as the
    whole read decodes every byte first."""
    first, lines = None, 0
    try:
        with open(path) as fh:
            line = fh.readline()
            while line.startswith("#"):
                line = fh.readline()
            for chunk in _chunks(fh, block_rows):
                if first is None:
                    why = _first_bad_row(chunk, names, wanted, text)
                    found = re.match(r"row (\d+)", why)
                    if found:
                        k = int(found.group(1)) + lines
                        first = f"row {k}" + why[found.end():]
                    lines += len(chunk.splitlines())
    except UnicodeDecodeError:
        return _not_text(path)
    return RunDirError(f"{path}: {first or 'not a CSV of numbers'}")


def _written(chunk: str | None, data: bytes | None, names, numbers, n: int
             ) -> dict[str, np.ndarray]:
    """``csvio.non_number_cells`` for the chunk's rows (its text, or its ASCII bytes):
    the cells of ``numbers`` whose text is a non-finite number (rows counted as it
    counts them, blank lines skipped)."""
    if chunk is None:
        if b"n" not in data and b"N" not in data:
            return {}
        chunk = data.decode()
    if not _may_hold_non_numbers(chunk):
        return {}
    cols = [(j, name) for j, name in enumerate(names) if name in numbers]
    hits: dict[str, list[int]] = {}
    non_number_rows(chunk.split("\n"), cols, hits)
    return marks_of(hits, n)


def _may_hold_non_numbers(chunk: str) -> bool:
    # "nan" and "inf" both hold an n or an N; ISO tags and numbers hold neither, so
    # most chunks are passed over by two character searches.
    if "n" not in chunk and "N" not in chunk:
        return False
    low = chunk.lower()
    return "nan" in low or "inf" in low


# --------------------------------------------------------------------------- arrow

# Cells the two parsers must read to the same double, or both refuse: signs, zeros,
# subnormals, overflow, 17 digits and more, spaces, every spelling of nan and inf
# ``float`` takes, and what CPython refuses (underscores, hex, C suffixes, quotes).
HARD_CELLS = ("", "0", "-0", "-0.0", "+1.5", ".5", "5.", "-.5", "1E5", "1e+05", "1e-05",
              "1e308", "1e309", "-1e309", "4.9e-324", "2.5e-324", "2.4e-324", "1e-400",
              "2.2250738585072011e-308", "0.30000000000000004", "5485.0967000000001",
              "9007199254740993", "123456789012345678901234567890",
              "1." + "0" * 400 + "1", "0." + "0" * 330 + "5", " 1.5", "1.5 ", "\t1.5 ",
              "inf", "-inf", "+inf", "Inf", "INF", "Infinity", "-infinity", "nan", "NaN",
              "-nan", "+nan", "NAN", "1e5000", "0e999999999", "00001.5", "-00",
              "1.0e-0010", "1_000", "0x10", "1d5", "1.5f", "e5", "1e", "--1", "1.5.5",
              "'1'", '"1.5"', "1.5#c", "١", " ")


@functools.cache
def arrow_agrees() -> bool:
    """Whether the installed pyarrow reads every one of ``HARD_CELLS`` to loadtxt's
    double, bit for bit (NaN's sign included), and refuses what loadtxt refuses; the
    CSV fast path is taken only then."""
    try:
        import pyarrow  # noqa: F401
    except ImportError:
        return False
    read = _arrow_reader(["a", "b"], [], ["a", "b"])
    for cell in HARD_CELLS:
        line = f"{cell},1\n"
        try:
            slow = _parse_body(line, ["a", "b"])["a"].view(np.int64).tolist()
        except ValueError:
            slow = None
        fast = read(line)
        if (fast["a"].view(np.int64).tolist() if fast is not None else None) != slow:
            return False
    return True


def _arrow_reader(names, text, numbers):
    """A chunk's columns by pyarrow (None when it refuses the chunk): quotes, escapes
    and comments are not CSV syntax here, as for loadtxt; an empty cell is NaN."""
    import pyarrow as pa
    import pyarrow.csv as pacsv

    read_opts = pacsv.ReadOptions(column_names=names, block_size=1 << 24)
    parse_opts = pacsv.ParseOptions(quote_char=False, double_quote=False, escape_char=False,
                                    newlines_in_values=False, ignore_empty_lines=True)
    conv_opts = pacsv.ConvertOptions(
        include_columns=numbers + text, null_values=[""], strings_can_be_null=True,
        quoted_strings_can_be_null=False,
        column_types={**{n: pa.float64() for n in numbers}, **{n: pa.string() for n in text}})

    # malloc's pool: arrow's own (mimalloc) keeps tens of MB it has freed.
    pool = pa.system_memory_pool()

    def read(chunk: str | bytes) -> dict[str, object] | None:
        data = chunk.encode() if isinstance(chunk, str) else chunk
        try:
            table = pacsv.read_csv(pa.py_buffer(data), read_opts, parse_opts, conv_opts,
                                   memory_pool=pool)
        except (pa.ArrowException, ValueError):
            return None
        out = {}
        for name in names:
            if name in numbers:
                # (An empty cell, null, becomes NaN: arrow_agrees checks its bits.)
                out[name] = table.column(name).to_numpy()
            elif name in text:
                # Left as arrow strings (times.fixed_layout_ns reads their bytes);
                # times._as_text turns them into _parse_body's text, null and "nan"
                # both "".
                out[name] = table.column(name).combine_chunks()
        return out
    return read


# --------------------------------------------------------------------------- Parquet

def _parquet_blocks(path: Path, wanted: set[str], time_col: str, block_rows):
    pf = parquet_file(path)
    import pyarrow as pa
    schema = pf.schema_arrow
    meta = {k.decode(errors="replace"): v.decode(errors="replace")
            for k, v in (schema.metadata or {}).items()}
    head = Header(list(schema.names), meta.get("epoch_utc"), "its Parquet metadata epoch_utc")
    names = [n for n in schema.names if n in wanted]
    problems = {}
    for name in names:
        kind = schema.field(name).type
        if pa.types.is_string(kind) or pa.types.is_large_string(kind):
            if name != time_col:
                problems[name] = f"{path}: column {name} holds text, not numbers"
        elif not (pa.types.is_timestamp(kind) or pa.types.is_integer(kind)
                  or pa.types.is_floating(kind) or pa.types.is_boolean(kind)):
            problems[name] = f"{path}: column {name} has type {kind}, not numbers or time tags"
    return head, _parquet_rows(pf, path, names, problems, block_rows)


def _parquet_rows(pf, path, names, problems, block_rows) -> Iterator[Block]:
    import pyarrow as pa
    no_tag: dict[str, int] = {}
    row0 = 0
    try:
        for batch in pf.iter_batches(batch_size=block_rows or PARQUET_BATCH, columns=names):
            cols, written = {}, {}
            for name in names:
                if name in problems:
                    continue
                col = batch.column(name)
                nulls = col.is_null().to_numpy(zero_copy_only=False)
                if pa.types.is_timestamp(col.type):
                    raw = col.cast(pa.int64()).fill_null(0).to_numpy(zero_copy_only=False)
                    cols[name] = raw.astype(np.int64) * NS_PER[col.type.unit]
                    if nulls.any() and name not in no_tag:
                        no_tag[name] = row0 + int(np.argmax(nulls))
                elif pa.types.is_string(col.type) or pa.types.is_large_string(col.type):
                    cols[name] = np.array(["" if v is None else v for v in col.to_pylist()],
                                          dtype=str)
                else:
                    values = col.cast(pa.float64()).to_numpy(zero_copy_only=False)
                    cols[name] = np.where(nulls, np.nan, values)
                    bad = np.isinf(values) & ~nulls
                    if bad.any():
                        written[name] = bad
            if not problems:
                yield Block(row0, batch.num_rows, cols, written)
            row0 += batch.num_rows
    except (pa.ArrowException, OSError) as exc:
        raise not_parquet(path, exc) from None
    # read_parquet's lines, in the file's column order, once every row is seen.
    lines = [problems.get(n) or (f"{path}: row {no_tag[n] + 2}, column {n}: no time tag"
                                 if n in no_tag else None) for n in names]
    if any(lines):
        raise RunDirError("\n".join(x for x in lines if x))
    if row0 == 0:
        yield Block(0, 0, {n: np.empty(0, dtype=np.int64 if pa.types.is_timestamp(
            pf.schema_arrow.field(n).type) else float) for n in names})
