"""Importers: CSV, NPY, CSMIP V2 (a real record) and MiniSEED -> a bag (docs/interfaces.md §1) -> the same samples."""

from __future__ import annotations

import json
import re
import zipfile
from pathlib import Path

import numpy as np
import pytest

from shm_ros.cli import main
from shm_ros.core.types import SampleFlag
from shm_ros.core.ingest import ChannelMap
from shm_ros.core.timeutil import ns_to_iso as iso_utc
from shm_ros.io.importers import ImportFileError, parse_v2, read_csv, read_npy, read_v2, write_bag
from shm_ros.io.recording import ingest_bag
from shm_ros.io.window_files import load_window

# the repository's own copy, provenance and licence in its README.md
V2_ZIP = Path(__file__).resolve().parent / "data" / "csmip_v2_sample" / "Inglewood_17May2009_CE13795P.zip"
T0 = 1_714_521_600_000_000_000


def _windows(bag, names, window_s):
    res = ingest_bag(bag, ChannelMap.simple(names), window_s=window_s)
    return res.windows, res


def test_csv_with_header_and_time_column(tmp_path):
    rng = np.random.default_rng(0)
    n, fs = 2400, 100.0
    x = rng.standard_normal((n, 2)).round(6)
    x[100, 1] = np.nan
    t = np.arange(n) / fs
    lines = ["# exported by a logger", "time,s1,s2"]
    for i in range(n):
        cell = "" if np.isnan(x[i, 1]) else repr(float(x[i, 1]))
        lines.append(f"{t[i]:.3f},{float(x[i, 0])!r},{cell}")
    (tmp_path / "a.csv").write_text("\n".join(lines) + "\n")
    rec = read_csv(tmp_path / "a.csv", time_column="time", start="2024-05-01T00:00:00Z")
    assert rec.channel_names == ["s1", "s2"] and rec.sample_rate_hz == pytest.approx(fs)
    assert rec.start_ns == T0
    write_bag([rec], tmp_path / "bag", prefix="/site")
    ws, _ = _windows(tmp_path / "bag", ["s1", "s2"], 12.0)
    assert [w.n_samples for w in ws] == [1200, 1200]
    got = np.concatenate([w.samples for w in ws])
    assert np.array_equal(got, x, equal_nan=True)
    assert ws[0].flags[100, 1] & SampleFlag.NAN
    assert ws[0].start_ns == T0


def test_csv_without_header_and_bad_cell(tmp_path):
    x = np.arange(600, dtype=float).reshape(300, 2) / 7.0
    (tmp_path / "b.csv").write_text("\n".join(f"{float(a)!r};{float(b)!r}" for a, b in x) + "\n")
    rec = read_csv(tmp_path / "b.csv", sample_rate_hz=50.0, channels=["e", "w"], start="1714521600",
                   units="cm/s^2")
    assert rec.start_ns == T0 and np.array_equal(rec.samples, x * 0.01)
    bad = tmp_path / "c.csv"
    bad.write_text("s1,s2\n1.0,2.0\n3.0,oops\n")
    with pytest.raises(ImportFileError, match=r"c\.csv: line 3, column 's2': not a number"):
        read_csv(bad, sample_rate_hz=10.0)
    with pytest.raises(ImportFileError, match="sample rate"):
        read_csv(tmp_path / "b.csv", channels=["e", "w"])


def test_npy_to_imu_bag(tmp_path):
    rng = np.random.default_rng(1)
    x = rng.standard_normal((3000, 3)) * 0.05
    np.save(tmp_path / "r.npy", x)
    rec = read_npy(tmp_path / "r.npy", sample_rate_hz=200.0, channels=["a", "b", "c"], start="2024-05-01T00:00:00Z")
    summary = write_bag([rec], tmp_path / "bag", layout="imu", axis="z", storage="sqlite3")
    assert summary["topics"] == ["/accel/a", "/accel/b", "/accel/c"] and summary["messages"] == 9000
    ws, _ = _windows(tmp_path / "bag", ["a", "b", "c"], 5.0)
    assert np.array_equal(np.concatenate([w.samples for w in ws]), x[:3000])
    with pytest.raises(ImportFileError, match="3 channels but 2 names"):
        read_npy(tmp_path / "r.npy", sample_rate_hz=200.0, channels=["a", "b"])


def _header_peaks(text: str) -> tuple[float, float]:
    """(peak cm/s^2, time s) from the V2 text header, read independently of the importer."""
    m = re.search(r"Peak acceleration =\s*([-\d.]+)\s*cm/sec/sec\s+at\s+([\d.]+)\s*sec", text)
    assert m, "sample header has no peak line"
    return float(m.group(1)), float(m.group(2))


def test_v2_real_record_header_and_values(tmp_path):
    with zipfile.ZipFile(V2_ZIP) as z:
        texts = {n: z.read(n).decode("latin-1") for n in z.namelist() if n.endswith(".V2")}
    (rec,) = read_v2(V2_ZIP, channels={1: "g0"})
    assert rec.metadata["station"] == "13795"
    assert rec.sample_rate_hz == 200.0 and rec.n_samples == 12800 and len(rec.channel_names) == 12
    assert iso_utc(rec.start_ns) == "2009-05-18T03:39:38.000Z"
    assert rec.channel_names[0] == "g0" and rec.channel_names[4] == "chan5"
    meta = rec.metadata["channels"]
    assert meta[0]["orientation"] == "Up" and meta[0]["location"] == "Freefield"
    assert meta[4]["location"].startswith("Bent 4")
    for j, name in enumerate(sorted(texts)):
        peak, at = _header_peaks(texts[name])
        col = rec.samples[:, j]
        k = int(np.argmax(np.abs(col)))
        assert col[k] * 100 == pytest.approx(peak, abs=1e-3), name  # m/s^2 back to cm/s^2
        assert k / 200.0 == pytest.approx(at, abs=1e-9), name
    # the first data line of channel 1, read as plain text
    lines = texts["CHAN001.V2"].splitlines()
    i = next(i for i, ln in enumerate(lines) if "points of accel data" in ln)
    first = [float(v) for v in lines[i + 1].split()]
    assert np.array_equal(rec.samples[:8, 0], np.asarray(first) * 0.01)
    # through a bag and ingest: one 64 s window holding exactly these values
    write_bag([rec], tmp_path / "bag")
    ws, res = _windows(tmp_path / "bag", rec.channel_names, 64.0)
    assert len(ws) == 1 and ws[0].n_samples == 12800
    assert np.array_equal(ws[0].samples, rec.samples)
    assert ws[0].is_event and ws[0].pga_m_s2 > 0.5


def test_v2_file_with_several_channel_sections(tmp_path):
    with zipfile.ZipFile(V2_ZIP) as z:
        a, b = z.read("CHAN002.V2").decode("latin-1"), z.read("CHAN007.V2").decode("latin-1")
    (tmp_path / "two.v2").write_text(a + b, encoding="latin-1")  # each section ends with a /& line
    (rec,) = read_v2(tmp_path / "two.v2")
    assert rec.channel_names == ["chan2", "chan7"] and rec.samples.shape == (12800, 2)
    (full,) = read_v2(V2_ZIP)
    assert np.array_equal(rec.samples, full.samples[:, [1, 6]])


def test_v2_damaged_text_names_file_and_line():
    with zipfile.ZipFile(V2_ZIP) as z:
        text = z.read("CHAN001.V2").decode("latin-1")
    lines = text.splitlines()
    i = next(i for i, ln in enumerate(lines) if "points of accel data" in ln)
    broken = "\n".join(lines[: i + 3] + ["   .0001  x.0002" + " " * 60] + lines[i + 4: i + 10])
    with pytest.raises(ImportFileError, match=rf"CHAN001: line {i + 4}, field 2: not a number"):
        parse_v2(broken, "CHAN001")
    short = "\n".join(lines[: i + 20])
    with pytest.raises(ImportFileError, match="announces 12800 points, file holds 152"):
        parse_v2(short, "CHAN001")
    with pytest.raises(ImportFileError, match="not a CSMIP V2 file"):
        parse_v2("hello\nworld\n", "junk.V2")


def test_miniseed_with_a_gap(tmp_path):
    obspy = pytest.importorskip("obspy")
    rng = np.random.default_rng(2)
    fs = 100.0
    counts = rng.integers(-2**20, 2**20, 4000).astype(np.int32)
    t0 = obspy.UTCDateTime("2024-05-01T00:00:00Z")
    tr1 = obspy.Trace(counts[:2500].copy(), header={"network": "XX", "station": "BR1", "location": "00",
                                                     "channel": "HNZ", "sampling_rate": fs, "starttime": t0})
    tr2 = obspy.Trace(counts[2600:].copy(), header={"network": "XX", "station": "BR1", "location": "00",
                                                     "channel": "HNZ", "sampling_rate": fs,
                                                     "starttime": t0 + 26.0})  # 1 s missing
    obspy.Stream([tr1, tr2]).write(str(tmp_path / "r.mseed"), format="MSEED", encoding="STEIM2")
    assert main(["import", str(tmp_path / "r.mseed"), "--out", str(tmp_path / "bag"), "--scale", "1e-6",
                 "--prefix", "/site"]) == 0
    ws, res = _windows(tmp_path / "bag", ["XX.BR1.00.HNZ"], 10.0)
    # [0, 25 s) -> 10 s, 10 s, 5 s windows; 1.01 s without samples ends the burst; the next one
    # starts at 26 s: one 10 s window, its 4 s remainder dropped
    scale = 1e-6
    k = [(w.start_ns - T0) // 10_000_000 for w in ws]
    assert k[:3] == [0, 1000, 2000]
    for w, kk in zip(ws, k, strict=True):
        idx = kk + np.arange(w.n_samples)
        assert np.array_equal(w.samples[:, 0], counts[idx] * scale)
    assert not any(w.start_ns < T0 + 26_000_000_000 < w.end_ns for w in ws)  # nothing spans the gap


def test_cli_ingest_writes_json_and_npz(tmp_path):
    rng = np.random.default_rng(3)
    x = rng.standard_normal((4000, 2)) * 0.01
    x[:, 0] += 9.81
    np.save(tmp_path / "r.npy", x)
    assert main(["import", str(tmp_path / "r.npy"), "--rate", "200", "--channels", "s1,s2",
                 "--start", "2024-05-01T00:00:00Z", "--out", str(tmp_path / "bag")]) == 0
    (tmp_path / "s.yaml").write_text(
        "name: t\nkind: girder\ngirder:\n  spans: [10.0]\n  elements_per_span: 4\n"
        "  section: {E: 3.0e10, I: 0.5, A: 2.0, rho: 2500}\n"
        "  bearings:\n    - {x: 0.0, k_vertical: 1.0e9}\n    - {x: 10.0, k_vertical: 1.0e9}\n"
        "sensors:\n  - {id: s1, at: {x: 3.0}, direction: vertical}\n"
        "  - {id: s2, at: {x: 6.0}, direction: vertical}\n")
    out = tmp_path / "out"
    assert main(["ingest", str(tmp_path / "bag"), "--structure", str(tmp_path / "s.yaml"), "--out", str(out),
                 "--window", "10", "--quiet"]) == 0
    doc = json.loads((out / "windows.json").read_text())
    assert doc["schema_version"] and doc["provenance"]["configuration"]["ingest"]["window_s"] == 10.0
    assert [w["n_samples"] for w in doc["windows"]] == [2000, 2000]
    w1 = load_window(out / doc["windows"][1]["file"])
    assert np.array_equal(w1.samples, x[2000:]) and w1.channel_names == ["s1", "s2"]
    assert w1.start_ns == T0 + 10_000_000_000 and w1.temperature_c is None
    # a missing bag is a bad option: refused before any work, nothing written
    assert main(["ingest", str(tmp_path / "nobag"), "--structure", str(tmp_path / "s.yaml"), "--out",
                 str(tmp_path / "o2"), "--quiet"]) == 2 and not (tmp_path / "o2").exists()
