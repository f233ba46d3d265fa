"""Recordings from other tools -> bags of the recording layout (docs/interfaces.md §1; ``shm-ros import``).

Readers return :class:`ImportedRecord` (samples in m/s^2, a start time, a rate or per-sample stamps);
:func:`write_bag` writes any number of them as ``AccelBlock`` messages (default) or per-sample
``sensor_msgs/Imu`` topics. Formats:

* CSV: one column per channel (header names or ``channels``), optional time column;
* NPY: an (n_samples, n_channels) array with a sample rate and channel names;
* CSMIP V2 (the strong-motion "V2" corrected accelerograms of the California Strong Motion
  Instrumentation Program, also distributed by COSMOS): text header (station, channel, start time
  UTC, ``N points of accel data equally spaced at DT sec, in cm/sec2``) and fixed-width values;
* MiniSEED through ObsPy.

Values are never altered other than by the declared unit factor; NaN cells stay NaN (ingest flags
them). Bad input raises :class:`ImportFileError` naming the file, line and field. Stamps must lie
between 1970 and 2038 (a ROS time's seconds are a 32-bit integer); the bag is written under a
temporary name and renamed when complete, so a failed import leaves nothing behind.
"""

from __future__ import annotations

import csv
import math
import re
import tokenize
import zipfile
from collections.abc import Sequence
from dataclasses import dataclass, field
from datetime import datetime, timezone
from pathlib import Path
from typing import Any

import numpy as np

from shm_ros.core.ingest.units import unit_factor
from shm_ros.errors import InputError

FORMATS = ("csv", "npy", "v2", "miniseed")


class ImportFileError(InputError):
    """An input file cannot be imported; the message names the file and what is wrong."""


@dataclass
class ImportedRecord:
    """Samples of one or more channels sharing a time base, in m/s^2."""

    channel_names: list[str]
    samples: np.ndarray  # (n, c) float64, m/s^2
    sample_rate_hz: float
    start_ns: int
    stamps_ns: np.ndarray | None = None  # per-sample stamps when not exactly start + k / rate
    source: str = ""
    metadata: dict[str, Any] = field(default_factory=dict)

    @property
    def n_samples(self) -> int:
        return int(self.samples.shape[0])

    def times_ns(self) -> np.ndarray:
        if self.stamps_ns is not None:
            return self.stamps_ns
        return self.start_ns + np.round(np.arange(self.n_samples) * (1e9 / self.sample_rate_hz)).astype(np.int64)


MAX_STAMP_NS = (2**31 - 1) * 1_000_000_000  # builtin_interfaces/Time.sec is an int32


def check_stamp(ns: float, what: str) -> int:
    """A stamp in ns that a bag can hold (1970 .. 2038); ImportFileError naming ``what`` otherwise."""
    if not (math.isfinite(ns) and 0 <= ns <= MAX_STAMP_NS):
        raise ImportFileError(f"{what}: time {ns / 1e9:.6g} s since 1970 is outside 1970-01-01 .. 2038-01-19 "
                              "(what a ROS time holds)")
    return int(ns)


def parse_time(text: str | None, what: str = "start") -> int:
    """ISO 8601 (``2024-05-01T00:00:00Z``, naive = UTC) or epoch seconds -> ns since the epoch."""
    if text is None or text == "":
        return 0
    try:
        seconds = float(text)
    except ValueError:
        pass
    else:
        return check_stamp(round(seconds * 1e9) if math.isfinite(seconds) else seconds, what)
    try:
        dt = datetime.fromisoformat(text.replace("Z", "+00:00"))
        if dt.tzinfo is None:
            dt = dt.replace(tzinfo=timezone.utc)
        whole = int(dt.replace(microsecond=0).timestamp())
    except (ValueError, OverflowError, OSError):
        raise ImportFileError(f"{what}: cannot read time {text!r} (ISO 8601 or epoch seconds)") from None
    return check_stamp(whole * 1_000_000_000 + dt.microsecond * 1000, what)


def _factor(units: str, source: str) -> float:
    f = unit_factor(units)
    if f is None:
        raise ImportFileError(f"{source}: unknown units {units!r} (m/s^2, g, cm/s^2 or mm/s^2)")
    return f


# ----------------------------------------------------------------------------------------------
# CSV and NPY


def read_csv(path: str | Path, *, sample_rate_hz: float | None = None, channels: Sequence[str] | None = None,
             time_column: str | None = None, start: str | None = None, units: str = "m/s^2",
             delimiter: str | None = None) -> ImportedRecord:
    """A CSV file: a header row of channel names (or ``channels`` for a file without one).

    ``time_column`` (seconds; epoch seconds when > 1e8) gives per-sample stamps and, without
    ``sample_rate_hz``, the rate; otherwise ``sample_rate_hz`` is required and ``start`` (ISO 8601 or
    epoch seconds) sets the first sample's time. Empty or ``nan`` cells are NaN.
    """
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8-sig")
    except OSError as exc:
        raise ImportFileError(f"{path}: cannot read: {exc}") from None
    lines = [ln for ln in text.splitlines() if ln.strip() and not ln.lstrip().startswith("#")]
    if not lines:
        raise ImportFileError(f"{path}: no data rows")
    if delimiter is None:
        try:
            delimiter = csv.Sniffer().sniff(lines[0], delimiters=",;\t ").delimiter
        except csv.Error:
            delimiter = ","
    try:
        rows = list(csv.reader(lines, delimiter=delimiter, skipinitialspace=True))
    except csv.Error as exc:
        raise ImportFileError(f"{path}: not a CSV table: {exc}") from None
    if not rows or not rows[0]:
        raise ImportFileError(f"{path}: no columns")
    header_present = any(_not_number(c) for c in rows[0])
    names = [c.strip() for c in rows[0]] if header_present else None
    body = rows[1:] if header_present else rows
    if not body:
        raise ImportFileError(f"{path}: a header row and no data rows")
    ncol = len(rows[0])
    if names is None:
        if channels is None:
            if time_column is not None:
                raise ImportFileError(f"{path}: no header row: give the channel names")
            names = [f"ch{i + 1}" for i in range(ncol)]
        else:
            names = list(channels)
            if time_column is not None and time_column not in names:
                names = [time_column] + names
        if len(names) != ncol:
            raise ImportFileError(f"{path}: {ncol} columns but {len(names)} names ({', '.join(names)})")
    data = np.empty((len(body), ncol))
    for i, row in enumerate(body):
        if len(row) != ncol:
            raise ImportFileError(f"{path}: line {i + 1 + header_present}: {len(row)} fields, expected {ncol}")
        for j, cell in enumerate(row):
            c = cell.strip()
            if c == "" or c.lower() in ("nan", "na", "null"):
                data[i, j] = np.nan
                continue
            try:
                data[i, j] = float(c)
            except ValueError:
                raise ImportFileError(f"{path}: line {i + 1 + header_present}, column {names[j]!r}: "
                                   f"not a number: {cell!r}") from None
    stamps = None
    if time_column is not None:
        if time_column not in names:
            raise ImportFileError(f"{path}: no time column {time_column!r} (columns: {', '.join(names)})")
        k = names.index(time_column)
        tcol = data[:, k]
        if not np.all(np.isfinite(tcol)) or np.any(np.diff(tcol) <= 0):
            raise ImportFileError(f"{path}: time column {time_column!r} must be finite and increasing")
        base = parse_time(start, f"{path}: start") if tcol[0] < 1e8 else 0
        check_stamp(base + float(tcol[0]) * 1e9, f"{path}: time column {time_column!r}, first row")
        check_stamp(base + float(tcol[-1]) * 1e9, f"{path}: time column {time_column!r}, last row")
        stamps = base + np.round(tcol * 1e9).astype(np.int64)
        data = np.delete(data, k, axis=1)
        names = names[:k] + names[k + 1:]
        if sample_rate_hz is None:
            if stamps.size < 2 or not np.median(np.diff(stamps)) > 0:
                raise ImportFileError(f"{path}: give the sample rate (the time column has fewer than two distinct "
                                      "stamps)")
            sample_rate_hz = 1e9 / float(np.median(np.diff(stamps)))
    if channels is not None and header_present:
        missing = [c for c in channels if c not in names]
        if missing:
            raise ImportFileError(f"{path}: no column(s) {', '.join(missing)} (columns: {', '.join(names)})")
        idx = [names.index(c) for c in channels]
        data, names = data[:, idx], list(channels)
    if sample_rate_hz is None or not 0 < sample_rate_hz < math.inf:
        raise ImportFileError(f"{path}: give the sample rate (or a time column)")
    start_ns = int(stamps[0]) if stamps is not None else parse_time(start, f"{path}: start")
    return ImportedRecord(names, data * _factor(units, str(path)), float(sample_rate_hz), start_ns,
                          stamps, str(path), {"format": "csv"})


def _not_number(cell: str) -> bool:
    try:
        float(cell)
        return False
    except ValueError:
        return cell.strip().lower() not in ("", "nan", "na", "null")


def read_npy(path: str | Path, *, sample_rate_hz: float, channels: Sequence[str] | None = None,
             start: str | None = None, units: str = "m/s^2") -> ImportedRecord:
    """An ``.npy`` array (n_samples, n_channels) (a 1-D array is one channel)."""
    path = Path(path)
    a = _load_npy(path)
    if a.ndim == 1:
        a = a[:, None]
    if a.ndim != 2 or a.dtype.kind not in "iuf" or a.shape[0] == 0:
        raise ImportFileError(f"{path}: expected a real (n_samples, n_channels) array with samples, got "
                              f"{a.dtype} {a.shape}")
    names = list(channels) if channels is not None else [f"ch{i + 1}" for i in range(a.shape[1])]
    if len(names) != a.shape[1]:
        raise ImportFileError(f"{path}: {a.shape[1]} channels but {len(names)} names")
    if not sample_rate_hz or not 0 < sample_rate_hz < math.inf:
        raise ImportFileError(f"{path}: give the sample rate")
    return ImportedRecord(names, a.astype(np.float64) * _factor(units, str(path)), float(sample_rate_hz),
                          parse_time(start, f"{path}: start"), None, str(path), {"format": "npy"})


def _load_npy(path: Path) -> np.ndarray:
    """The array of an ``.npy`` file; its header is checked (numeric or boolean dtype, data that
    fits the file) before any data is read, and any damage is an ImportFileError."""
    try:
        with open(path, "rb") as fh:
            version = np.lib.format.read_magic(fh)
            if version == (1, 0):
                shape, fortran, dtype = np.lib.format.read_array_header_1_0(fh)
            else:
                shape, fortran, dtype = np.lib.format.read_array_header_2_0(fh)
            size = path.stat().st_size - fh.tell()
            if dtype.hasobject or math.prod(shape) * dtype.itemsize > size:
                raise ImportFileError(f"{path}: header announces {dtype} {shape}, which the file does not hold")
            a = np.fromfile(fh, dtype=dtype, count=math.prod(shape))
    except ImportFileError:
        raise
    except (OSError, ValueError, EOFError, SyntaxError, tokenize.TokenError, UnicodeDecodeError, TypeError) as exc:
        raise ImportFileError(f"{path}: cannot read as .npy: {type(exc).__name__}: {exc}") from None
    return a.reshape(shape, order="F" if fortran else "C")


# ----------------------------------------------------------------------------------------------
# CSMIP V2


_V2_START = re.compile(r"Start time:\s*(\d+)/(\d+)/(\d+),\s*(\d+):(\d+):([\d.]+)\s*UTC", re.I)
_V2_STATION = re.compile(r"Station No\.\s*(\S+)")
_V2_CHAN = re.compile(r"Chan\s+(\d+)\s*:\s*(.*?)\s*(?:Location:\s*(.*?))?\s*$")
_V2_DATA = re.compile(r"^\s*(\d+)\s+points of accel data equally spaced at\s*([\d.Ee+-]+)\s*sec,\s*"
                      r"in\s*([^.\s]+(?:\.\S+)?)\.?\s*\((\d+)[fF](\d+)\.(\d+)\)", re.I)
_V2_UNITS = {"cm/sec2": 0.01, "cm/s2": 0.01, "cm/sec/sec": 0.01, "g": 9.80665, "mm/sec2": 0.001,
             "m/sec2": 1.0}


@dataclass
class V2Channel:
    station: str
    channel: int
    orientation: str
    location: str
    start_ns: int
    dt_s: float
    accel_m_s2: np.ndarray
    units_in_file: str
    source: str


def parse_v2(text: str, source: str = "<v2>") -> list[V2Channel]:
    """Every channel section of a CSMIP V2 text (sections end with a ``/&`` line)."""
    lines = text.replace("\r\n", "\n").replace("\r", "\n").split("\n")
    out: list[dict[str, Any]] = []
    section_start = 0
    i = 0
    while i < len(lines):
        m = _V2_DATA.match(lines[i])
        if not m:
            if lines[i].startswith("/&"):
                section_start = i + 1
            i += 1
            continue
        header = lines[section_start:i]
        where = f"{source}: line {i + 1}"
        try:
            dt = float(m.group(2))
        except ValueError:
            raise ImportFileError(f"{where}: bad sample interval {m.group(2)!r}") from None
        n, units, per_line, width = int(m.group(1)), m.group(3), int(m.group(4)), int(m.group(5))
        if not (0 < per_line <= 100 and 0 < width <= 100):
            raise ImportFileError(f"{where}: bad value format ({per_line}F{width})")
        if n > 10**8:
            raise ImportFileError(f"{where}: {n} points announced; refused (more than 10^8)")
        factor = _V2_UNITS.get(units.lower().rstrip("."))
        if factor is None:
            raise ImportFileError(f"{where}: unknown units {units!r} in the accel data header")
        if not (n > 0 and 0 < dt < math.inf):
            raise ImportFileError(f"{where}: bad point count {n} or interval {dt}")
        vals: list[float] = []
        j = i + 1
        while len(vals) < n and j < len(lines):
            ln = lines[j]
            for k in range(0, min(len(ln), per_line * width), width):
                cell = ln[k:k + width].strip()
                if cell:
                    try:
                        vals.append(float(cell))
                    except ValueError:
                        raise ImportFileError(f"{source}: line {j + 1}, field {k // width + 1}: "
                                           f"not a number: {cell!r}") from None
            j += 1
        if len(vals) < n:
            raise ImportFileError(f"{where}: header announces {n} points, file holds {len(vals)}")
        out.append(_v2_header(header, source, i) | {"n": n, "dt": dt, "vals": vals[:n], "units": units,
                                                      "factor": factor})
        i = j
    if not out:
        raise ImportFileError(f"{source}: no 'N points of accel data equally spaced at DT sec' header: "
                           "not a CSMIP V2 file")
    chans = []
    for h in out:
        chans.append(V2Channel(h["station"], h["channel"], h["orientation"], h["location"], h["start_ns"],
                               h["dt"], np.asarray(h["vals"], np.float64) * h["factor"], h["units"], source))
    return chans


def _v2_header(header: list[str], source: str, line_no: int) -> dict[str, Any]:
    text = "\n".join(header)
    m = _V2_START.search(text)
    if not m:
        raise ImportFileError(f"{source}: no 'Start time: M/D/YY, hh:mm:ss UTC' before line {line_no + 1}")
    mo, d, y, hh, mm, ss = m.groups()
    year = int(y) + (2000 if int(y) < 70 else 1900) if len(y) <= 2 else int(y)
    try:
        sec = float(ss)
        base = datetime(year, int(mo), int(d), int(hh), int(mm), int(sec), tzinfo=timezone.utc)
    except ValueError as exc:
        raise ImportFileError(f"{source}: bad start time {m.group(0)!r}: {exc}") from None
    start_ns = check_stamp(int(base.timestamp()) * 1_000_000_000 + int(round((sec - int(sec)) * 1e9)),
                           f"{source}: start time")
    st = _V2_STATION.search(text)
    station = st.group(1) if st else "unknown"
    chan, orient, loc = 0, "", ""
    for ln in header:
        c = _V2_CHAN.search(ln)
        if c and "Location" in ln:
            chan, orient, loc = int(c.group(1)), c.group(2).strip(), (c.group(3) or "").strip()
            break
    else:
        for ln in header:
            c = _V2_CHAN.search(ln)
            if c:
                chan, orient = int(c.group(1)), c.group(2).strip()
                break
    return {"station": station, "channel": chan, "orientation": orient, "location": loc, "start_ns": start_ns}


def read_v2(path: str | Path, *, channels: dict[int, str] | None = None) -> list[ImportedRecord]:
    """A V2 file, or a ``.zip`` of them: channels sharing start and interval form one record.

    Channel ``n`` is named ``chan<n>`` unless ``channels`` maps its number to a name.
    """
    path = Path(path)
    texts: list[tuple[str, str]] = []
    try:
        if zipfile.is_zipfile(path):
            with zipfile.ZipFile(path) as z:
                for name in sorted(z.namelist()):
                    if name.upper().endswith(".V2"):
                        if z.getinfo(name).file_size > 2**30:
                            raise ImportFileError(f"{path}:{name}: more than 1 GiB uncompressed; refused")
                        texts.append((f"{path}:{name}", z.read(name).decode("latin-1")))
            if not texts:
                raise ImportFileError(f"{path}: no .V2 member in the archive")
        else:
            texts.append((str(path), path.read_text(encoding="latin-1")))
    except (OSError, zipfile.BadZipFile, zipfile.LargeZipFile, EOFError, NotImplementedError) as exc:
        raise ImportFileError(f"{path}: cannot read: {exc}") from None
    chans: list[V2Channel] = []
    for src, text in texts:
        chans.extend(parse_v2(text, src))
    groups: dict[tuple[int, float, int], list[V2Channel]] = {}
    for c in chans:
        groups.setdefault((c.start_ns, c.dt_s, c.accel_m_s2.size), []).append(c)
    out = []
    for (start_ns, dt, _n), cs in sorted(groups.items()):
        names = [(channels or {}).get(c.channel, f"chan{c.channel}") for c in cs]
        out.append(ImportedRecord(
            names, np.column_stack([c.accel_m_s2 for c in cs]), 1.0 / dt, start_ns, None, str(path),
            {"format": "csmip-v2", "station": cs[0].station,
             "channels": [{"name": nm, "number": c.channel, "orientation": c.orientation,
                           "location": c.location, "units_in_file": c.units_in_file, "file": c.source}
                          for nm, c in zip(names, cs, strict=True)]}))
    return out


# ----------------------------------------------------------------------------------------------
# MiniSEED


def read_miniseed(path: str | Path, *, units: str = "m/s^2", scale: float = 1.0,
                  channels: dict[str, str] | None = None) -> list[ImportedRecord]:
    """MiniSEED through ObsPy: one record per trace (gaps split a channel into several traces).

    Samples are multiplied by ``scale`` (e.g. 1/sensitivity for counts) and the ``units`` factor.
    A trace is named by its SEED id ``NET.STA.LOC.CHA`` unless ``channels`` maps that id to a name.
    """
    try:
        import obspy
    except ImportError:  # pragma: no cover - obspy is a runtime dependency
        raise ImportFileError("MiniSEED needs ObsPy (pip install obspy)") from None
    from obspy.io.mseed.core import _is_mseed

    path = Path(path)
    try:
        if not _is_mseed(str(path)):
            raise ImportFileError(f"{path}: not a MiniSEED file")
        st = obspy.read(str(path), format="MSEED")
    except ImportFileError:
        raise
    except Exception as exc:  # ObsPy raises plain Exception for unreadable records, besides its own errors
        raise ImportFileError(f"{path}: cannot read as MiniSEED: {type(exc).__name__}: {exc}") from None
    f = _factor(units, str(path)) * float(scale)
    out = []
    for tr in st:
        if np.asarray(tr.data).dtype.kind not in "iuf":
            raise ImportFileError(f"{path}: trace {tr.id} holds {np.asarray(tr.data).dtype} data, not samples")
        sid = tr.id
        name = (channels or {}).get(sid, sid)
        start_ns = int(tr.stats.starttime.ns)
        out.append(ImportedRecord([name], (np.asarray(tr.data, np.float64) * f)[:, None],
                                  float(tr.stats.sampling_rate), start_ns, None, str(path),
                                  {"format": "miniseed", "seed_id": sid}))
    if not out:
        raise ImportFileError(f"{path}: no traces")
    return out


# ----------------------------------------------------------------------------------------------
# dispatch and bag writing


def detect_format(path: str | Path) -> str:
    p = Path(path)
    suffix = p.suffix.lower()
    if suffix in (".csv", ".txt", ".tsv"):
        return "csv"
    if suffix == ".npy":
        return "npy"
    if suffix in (".v2", ".zip"):
        return "v2"
    if suffix in (".mseed", ".miniseed", ".msd"):
        return "miniseed"
    raise ImportFileError(f"{p}: cannot tell the format from the name; give --format ({', '.join(FORMATS)})")


def read_any(path: str | Path, fmt: str | None = None, **opts: Any) -> list[ImportedRecord]:
    fmt = fmt or detect_format(path)
    if fmt == "csv":
        return [read_csv(path, **_pick(opts, "sample_rate_hz", "channels", "time_column", "start", "units"))]
    if fmt == "npy":
        return [read_npy(path, **_pick(opts, "sample_rate_hz", "channels", "start", "units"))]
    if fmt == "v2":
        return read_v2(path, channels=opts.get("v2_channels"))
    if fmt == "miniseed":
        return read_miniseed(path, **_pick(opts, "units", "scale", "seed_channels"))
    raise ImportFileError(f"{path}: unknown format {fmt!r} ({', '.join(FORMATS)})")


def _pick(opts: dict[str, Any], *keys: str) -> dict[str, Any]:
    rename = {"seed_channels": "channels"}
    return {rename.get(k, k): opts[k] for k in keys if opts.get(k) is not None}


def write_bag(records: Sequence[ImportedRecord], out: str | Path, *, layout: str = "block",
              prefix: str = "", storage: str = "mcap", compress: bool = True, block_s: float = 1.0,
              axis: str = "z", overwrite: bool = False) -> dict[str, Any]:
    """Write records as a bag of the recording layout; returns a summary (topics, messages, samples, span).

    ``layout="block"``: ``<prefix>/accel_block`` AccelBlocks of ``block_s`` seconds (records with
    per-sample stamps must be evenly sampled); ``layout="imu"``: one ``sensor_msgs/Imu`` per sample
    on ``<prefix>/accel/<channel>``, the value on ``axis`` (the others 0).
    """
    from shm_ros.io.atomic import staged_path
    from shm_ros.io.bags import BagWriter

    if layout not in ("block", "imu"):
        raise ImportFileError(f"layout must be block or imu, got {layout!r}")
    if axis not in ("x", "y", "z"):
        raise ImportFileError(f"axis must be x, y or z, got {axis!r}")
    prefix = "/" + prefix.strip("/") if prefix.strip("/") else ""
    out = Path(out)
    if out.exists() and not overwrite:
        raise ImportFileError(f"{out}: already exists (choose a new bag name, or --overwrite)")
    if not any(r.n_samples for r in records):
        raise ImportFileError(f"{', '.join(r.source for r in records) or 'input'}: no samples to import")
    pieces = []  # (t_first, order, record, slice)
    for r_i, r in enumerate(records):
        if r.samples.ndim != 2 or r.samples.shape[1] != len(r.channel_names):
            raise ImportFileError(f"{r.source}: samples do not match the channel names")
        if not 0 < r.sample_rate_hz < math.inf:
            raise ImportFileError(f"{r.source}: sample rate {r.sample_rate_hz} Hz")
        if r.n_samples == 0:
            continue
        times = r.times_ns()
        check_stamp(float(times.min()), f"{r.source}: first sample")
        check_stamp(float(times.max()), f"{r.source}: last sample")
        if layout == "block" and r.stamps_ns is not None:
            d = np.diff(r.stamps_ns)
            period = 1e9 / r.sample_rate_hz
            if d.size and np.max(np.abs(d - period)) > 0.01 * period:
                raise ImportFileError(f"{r.source}: stamps are not evenly spaced: use the imu layout "
                                   "(which keeps every stamp)")
        step = max(1, int(round(block_s * r.sample_rate_hz)))
        for k in range(0, r.n_samples, step):
            pieces.append((int(times[k]), r_i, r, slice(k, min(k + step, r.n_samples))))
    pieces.sort(key=lambda p: (p[0], p[1]))
    n_msgs = 0
    topics: set[str] = set()
    ax = "xyz".index(axis)
    with staged_path(out) as tmp, BagWriter(tmp, storage=storage, compress=compress) as w:
        for t_first, _, r, sl in pieces:
            if layout == "block":
                topic = f"{prefix}/accel_block"
                w.accel_block(topic, t_first, r.sample_rate_hz, r.channel_names, r.samples[sl])
                n_msgs += 1
                topics.add(topic)
            else:
                times = r.times_ns()[sl]
                for j, name in enumerate(r.channel_names):
                    xyz = np.zeros((times.size, 3))
                    xyz[:, ax] = r.samples[sl, j]
                    topic = f"{prefix}/accel/{name}"
                    w.imu_series(topic, times, xyz)
                    n_msgs += times.size
                    topics.add(topic)
    t0 = min((int(r.times_ns()[0]) for r in records if r.n_samples), default=0)
    t1 = max((int(r.times_ns()[-1]) for r in records if r.n_samples), default=0)
    return {"bag": str(out), "layout": layout, "topics": sorted(topics), "messages": n_msgs,
            "channels": sorted({c for r in records for c in r.channel_names}),
            "samples": int(sum(r.samples.size for r in records)), "start_ns": t0, "last_ns": t1}


__all__ = ["ImportFileError", "ImportedRecord", "read_csv", "read_npy", "read_v2", "parse_v2", "read_miniseed",
           "read_any", "write_bag", "detect_format", "parse_time"]
