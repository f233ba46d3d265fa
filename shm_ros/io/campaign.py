"""Write a simulated campaign: the bag, the NOMINAL structure file, ``truth.json`` and the true
modes as a tracked-modes table ``truth_modes.csv`` (docs/interfaces.md §4).

``write_campaign(campaign, out_dir)`` streams windows into ``OUT/bag`` (rosbag2, MCAP by default with
zstd chunk compression, or sqlite3), writes ``OUT/structure.yaml`` (the nominal structure file, which
mentions none of the hidden effects) and ``OUT/truth.json`` (true modal properties per window, the
hidden effects and their parameters, the faults, the seed; with ``schema_version`` and
``provenance``). The same scenario and seed give byte-identical bag files.
"""

from __future__ import annotations

import sys
import time
from collections.abc import Callable, Iterator
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass
from pathlib import Path
from typing import Protocol

import numpy as np

from shm_ros.core.provenance import stamp_output
from shm_ros.core.simulate.campaign import Campaign, SimulatedWindow
from shm_ros.core.structure import structure_from_dict
from shm_ros.io import jsonio
from shm_ros.io.atomic import staged_path
from shm_ros.io.bags import BagWriter
from shm_ros.io.structure import dump_structure

RECEIVE_LATENCY_NS = 2_000_000  # a driver's stamp precedes the recorder's receive time a little


@dataclass
class CampaignFiles:
    bag: Path
    structure: Path
    truth: Path
    truth_table: Path
    n_windows: int
    bag_bytes: int
    seconds: float


class _ThreadLimits(Protocol):
    def restore_original_limits(self) -> None: ...


def _limit_threads() -> _ThreadLimits | None:
    """One BLAS thread per process: many small eigenproblems are slower with a thread pool."""
    try:
        from threadpoolctl import threadpool_limits
    except ImportError:  # optional; numbers are identical either way
        return None
    return threadpool_limits(1)


def _window_job(args: tuple[Campaign, int]) -> SimulatedWindow:
    campaign, i = args
    w = campaign.window(i)
    w.accel = np.zeros((0, len(w.sensor_ids)))  # the writer needs only the recording
    return w


_WORKER_CAMPAIGN: Campaign | None = None


def _init_worker(campaign: Campaign) -> None:
    global _WORKER_CAMPAIGN
    _WORKER_CAMPAIGN = campaign
    _limit_threads()


def _worker_window(i: int) -> SimulatedWindow:
    assert _WORKER_CAMPAIGN is not None
    return _window_job((_WORKER_CAMPAIGN, i))


def iter_windows(campaign: Campaign, workers: int = 1) -> Iterator[SimulatedWindow]:
    """Windows in order; ``workers`` > 1 computes them in worker processes (same results)."""
    if workers <= 1 or campaign.n_windows < 4:
        for i in range(campaign.n_windows):
            yield _window_job((campaign, i))
        return
    with ProcessPoolExecutor(max_workers=workers, initializer=_init_worker, initargs=(campaign,)) as pool:
        yield from pool.map(_worker_window, range(campaign.n_windows), chunksize=2)


def write_campaign(campaign: Campaign, out_dir: str | Path, *, workers: int = 1,
                   progress: Callable[[int, int, float], None] | None = None,
                   command_config: dict | None = None, overwrite: bool = False) -> CampaignFiles:
    """Simulate every window of ``campaign`` and write the three outputs into ``out_dir``; the bag
    appears when complete (written under a temporary name), replacing an earlier one only with
    ``overwrite``."""
    sc = campaign.scenario
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    bag = out / "bag"
    if bag.exists() and not overwrite:
        raise FileExistsError(f"{bag}: already exists; choose an empty --out directory")
    t0 = time.perf_counter()
    limiter = _limit_threads()
    prefix = "/" + sc.prefix.strip("/") if sc.prefix.strip("/") else ""
    temp_topic = f"{prefix}/temperature/t1"
    tstamps, tvalues = campaign.temperature_stamps_ns, campaign.temperature_measured_c
    t_next = 0
    entries = []
    try:
        with staged_path(bag) as staged, BagWriter(staged, storage=sc.storage, compress=sc.compress) as writer:
            for w in iter_windows(campaign, workers):
                start, end = campaign.window_bounds_ns(w.index)
                while t_next < tstamps.size and tstamps[t_next] < end:
                    writer.temperature(temp_topic, int(tstamps[t_next]), float(tvalues[t_next]), variance=0.0025)
                    t_next += 1
                if sc.unrelated_topics:  # what else a field recorder captures: must be ignored
                    status = writer._types["std_msgs/msg/String"](data=f"daq ok, burst {w.index}")
                    writer.write(f"{prefix}/daq/status", "std_msgs/msg/String", start, status)
                if sc.output == "imu":
                    _write_imu(writer, prefix, w)
                else:
                    _write_blocks(writer, f"{prefix}/accel_block", w, sc.block_s)
                entries.append(w.truth)
                if progress is not None:
                    progress(w.index + 1, campaign.n_windows, time.perf_counter() - t0)
            while t_next < tstamps.size:
                writer.temperature(temp_topic, int(tstamps[t_next]), float(tvalues[t_next]), variance=0.0025)
                t_next += 1
    finally:
        if limiter is not None:
            limiter.restore_original_limits()
    structure = out / "structure.yaml"
    dump_structure(structure_from_dict(campaign.nominal_structure, source=str(structure)), structure)
    truth = out / "truth.json"
    payload = {**campaign.truth_header(), "topics": _topics(campaign, prefix), "windows": entries}
    config = {"scenario": sc.to_dict(), **(command_config or {})}
    jsonio.dump(stamp_output(payload, config=config, seed=sc.seed), truth)
    table = out / "truth_modes.csv"
    write_truth_table(entries, campaign.sensor_ids, table)
    size = sum(p.stat().st_size for p in bag.rglob("*") if p.is_file())
    return CampaignFiles(bag=bag, structure=structure, truth=truth, truth_table=table, n_windows=campaign.n_windows,
                         bag_bytes=size, seconds=time.perf_counter() - t0)


def write_truth_table(entries: list[dict], sensor_ids: list[str], path: str | Path) -> Path:
    """The true modes as a tracked-modes table (docs/interfaces.md §4): one row per window, ``time``
    (window start, ISO 8601), ``mode<k>_hz``, ``mode<k>_damping``, ``mode<k>_shape_<sensor>``, and
    covariates ``temperature_c`` (the recorded mean, as ``ingest`` computes it), ``temperature_true_c``,
    ``rms_accel`` (mean over sensors, m/s^2) and ``pga`` (m/s^2, earthquakes; 0 otherwise)."""
    import csv

    n_modes = max((len(e["frequencies_hz"]) for e in entries), default=0)
    header = ["time"]
    for k in range(1, n_modes + 1):
        header += [f"mode{k}_hz", f"mode{k}_damping"] + [f"mode{k}_shape_{s}" for s in sensor_ids]
    header += ["temperature_c", "temperature_true_c", "rms_accel", "pga"]
    path = Path(path)
    with path.open("w", newline="", encoding="utf-8") as fh:
        w = csv.writer(fh)
        w.writerow(header)
        for e in entries:
            row: list = [e["start"]]
            for k in range(n_modes):
                if k < len(e["frequencies_hz"]):
                    row += [f"{e['frequencies_hz'][k]:.8g}", f"{e['damping_ratios'][k]:.6g}"]
                    row += [f"{e['mode_shapes'][s][k]:.6g}" for s in sensor_ids]
                else:
                    row += [""] * (2 + len(sensor_ids))
            t = e.get("temperature_measured_c")
            rms = np.mean(list(e["rms_accel_m_s2"].values()))
            pga = (e.get("event") or {}).get("pga_m_s2", 0.0)
            row += ["" if t is None else f"{t:.4f}", f"{e['temperature_c']:.4f}", f"{rms:.6g}", f"{pga:.6g}"]
            w.writerow(row)
    return path


def _topics(campaign: Campaign, prefix: str) -> dict:
    sc = campaign.scenario
    accel = ({sid: f"{prefix}/accel/{sid}" for sid in campaign.sensor_ids} if sc.output == "imu"
             else {"accel_block": f"{prefix}/accel_block"})
    return {"accel": accel, "temperature": f"{prefix}/temperature/t1", "format": sc.output, "storage": sc.storage}


def _write_imu(writer: BagWriter, prefix: str, w: SimulatedWindow) -> None:
    rec = w.recording
    for c, sid in enumerate(rec.sensor_ids):
        xyz = rec.imu_xyz(c)
        stamps = rec.stamps_ns
        recv = stamps + RECEIVE_LATENCY_NS
        if rec.keep is not None:
            assert rec.shift_ns is not None and rec.repeat is not None  # faults fill the masks together
            keep = rec.keep[:, c]
            counts = keep.astype(np.int64) * (1 + rec.repeat[:, c].astype(np.int64))
            stamps = np.repeat(stamps + rec.shift_ns[:, c], counts)
            recv = np.repeat(recv, counts)
            xyz = np.repeat(xyz, counts, axis=0)
        writer.imu_series(f"{prefix}/accel/{sid}", stamps, xyz, receive_ns=recv)


def _write_blocks(writer: BagWriter, topic: str, w: SimulatedWindow, block_s: float) -> None:
    rec = w.recording
    n = rec.n
    per = max(1, int(round(block_s * w.fs)))
    if rec.keep is None:
        runs = [(0, n, 0)]
        rep = None
    else:
        assert rec.shift_ns is not None and rec.repeat is not None  # faults fill the masks together
        keep = np.all(rec.keep, axis=1)
        shift = rec.shift_ns[:, 0]
        rep = rec.repeat.max(axis=1)
        runs = []
        k = 0
        while k < n:
            if not keep[k]:
                k += 1
                continue
            j = k + 1
            while j < n and keep[j] and shift[j] == shift[k]:
                j += 1
            runs.append((k, j, int(shift[k])))
            k = j
    names = list(rec.sensor_ids)
    for k0, k1, sh in runs:
        for b0 in range(k0, k1, per):
            b1 = min(b0 + per, k1)
            t = int(rec.stamps_ns[b0]) + sh
            copies = 1 + (int(rep[b0:b1].max()) if rep is not None else 0)
            for _ in range(copies):  # a duplicated block repeats its stamp
                writer.accel_block(topic, t, w.fs, names, rec.values[b0:b1])


def print_progress(every: int = 1) -> Callable[[int, int, float], None]:
    """A progress callback printing ``window k/N, elapsed, ETA`` to stderr."""
    def cb(k: int, n: int, elapsed: float) -> None:
        if k % every == 0 or k == n:
            eta = elapsed / k * (n - k)
            print(f"simulate: window {k}/{n}  {elapsed:7.1f} s elapsed, ~{eta:6.1f} s left",
                  file=sys.stderr, flush=True)
    return cb
