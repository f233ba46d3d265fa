"""Property-based fuzzing of every parser and message handler that reads outside input: structure
YAML, matrices files, bags (damaged MCAP files), CDR decoding of Imu messages, AccelBlock and
sample handlers of ingest, the importers (CSV, NPY, CSMIP V2, MiniSEED) and ROS parameters (graph
parameters files and the node's parameter checks).

Each generated case may only end normally or with one of the project's errors (``ShmError``: a
message naming the file and field); any other exception fails the test, and every case runs under a
time limit (``CASE_LIMIT_S``, SIGALRM), so a hang fails too. Cases per parser: 100 in CI, and at
full size (``SHM_FULL=1``) enough for more than 10,000 in all; each test prints its count.
"""

from __future__ import annotations

import functools
import io
import math
import os
import shutil
import signal
import zipfile
from contextlib import contextmanager
from pathlib import Path

import numpy as np
import pytest
import yaml

hypothesis = pytest.importorskip("hypothesis")
from hypothesis import HealthCheck, given, settings  # noqa: E402
from hypothesis import strategies as st  # noqa: E402

from shm_ros.errors import ShmError  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
EXAMPLES = ROOT / "examples"
FULL = os.environ.get("SHM_FULL", "") not in ("", "0")
CASES = 1500 if FULL else 100  # per parser; the ROS parameter nodes take ~0.1 s each (fewer at full size)
CASE_LIMIT_S = 20.0
COUNTS: dict[str, int] = {}  # cases run per parser (hypothesis's shrinking included)
UNCAUGHT: dict[str, int] = {}  # cases that ended with anything but a ShmError
HANGS: dict[str, int] = {}  # cases stopped by the time limit

SETTINGS = settings(max_examples=CASES, deadline=None, derandomize=not FULL, database=None,
                    suppress_health_check=list(HealthCheck))


@contextmanager
def time_limit(what: str):
    def hang(signum, frame):
        raise TimeoutError(f"{what}: a case ran longer than {CASE_LIMIT_S} s")

    old = signal.signal(signal.SIGALRM, hang)
    signal.setitimer(signal.ITIMER_REAL, CASE_LIMIT_S)
    try:
        yield
    finally:
        signal.setitimer(signal.ITIMER_REAL, 0)
        signal.signal(signal.SIGALRM, old)


def case(parser: str, fn, *args, **kwargs):
    """Run one case: a result, or a ShmError; anything else (and a hang) is counted and propagates."""
    COUNTS[parser] = COUNTS.get(parser, 0) + 1
    try:
        with time_limit(parser):
            try:
                return fn(*args, **kwargs)
            except ShmError as exc:
                assert str(exc).strip(), f"{parser}: an error without a message"
                return exc
    except TimeoutError:
        HANGS[parser] = HANGS.get(parser, 0) + 1
        raise
    except BaseException:
        UNCAUGHT[parser] = UNCAUGHT.get(parser, 0) + 1
        raise


@pytest.fixture(autouse=True)
def _report_count(request):
    before = dict(COUNTS)
    yield
    for k, n in COUNTS.items():
        if n != before.get(k, 0):
            print(f"\nfuzz {k}: {n - before.get(k, 0)} cases, {UNCAUGHT.get(k, 0)} uncaught exceptions, "
                  f"{HANGS.get(k, 0)} hangs")


def _workdir(tmp_path_factory, name: str) -> Path:
    return tmp_path_factory.mktemp(name)


# -- values a careless or hostile file may hold ----------------------------------------------------

scalars = st.one_of(st.none(), st.booleans(), st.integers(-(10**30), 10**30),
                    st.floats(allow_nan=True, allow_infinity=True), st.text(max_size=12),
                    st.sampled_from(["1e400", "-0", "nan", "5e9", ".inf", "0x10", "", "1_000", "~"]))
values = st.recursive(scalars, lambda inner: st.one_of(st.lists(inner, max_size=4),
                                                       st.dictionaries(st.text(max_size=6), inner, max_size=3)),
                      max_leaves=8)


def _paths(node, path=()):
    yield path
    if isinstance(node, dict):
        for k, v in node.items():
            yield from _paths(v, (*path, k))
    elif isinstance(node, list):
        for i, v in enumerate(node):
            yield from _paths(v, (*path, i))


def _mutate(doc, edits):
    """Apply ``(path index, action, value)`` edits: replace a node, delete it, or add a key."""
    for index, action, value in edits:
        paths = [p for p in _paths(doc) if p]
        if not paths:
            return value
        path = paths[index % len(paths)]
        parent = doc
        for k in path[:-1]:
            parent = parent[k]
        last = path[-1]
        if action == "replace":
            parent[last] = value
        elif action == "delete":
            del parent[last]
        elif isinstance(parent, dict):
            parent[f"x{index}"] = value
        else:
            parent.append(value)
    return doc


edits = st.lists(st.tuples(st.integers(0, 10**6), st.sampled_from(["replace", "delete", "add"]), values),
                 min_size=1, max_size=4)
STRUCTURES = {name: (EXAMPLES / name).read_text() for name in ("girder.yaml", "building.yaml", "matrices.yaml")}


# -- structure files ------------------------------------------------------------------------------

@SETTINGS
@given(name=st.sampled_from(sorted(STRUCTURES)), changes=edits,
       raw=st.one_of(st.none(), st.text(max_size=200),
                     st.sampled_from(["&a [*a]", "a: &x {b: *x}", "!!python/object:os.system {}", "- - - -",
                                      "name: [" * 50, "kind: girder\nkind: girder\n"])))
def test_fuzz_structure_yaml(tmp_path_factory, name, changes, raw):
    from shm_ros.io.structure import load_structure

    d = _workdir(tmp_path_factory, "st")
    shutil.copy(EXAMPLES / "matrices.npz", d / "matrices.npz")
    if raw is not None:
        text = raw
    else:
        doc = _mutate(yaml.safe_load(STRUCTURES[name]), changes)
        try:
            text = yaml.safe_dump(doc)
        except (yaml.YAMLError, ValueError, OverflowError):
            return
    (d / "s.yaml").write_text(text, encoding="utf-8", errors="surrogatepass") if "\ud800" not in text else None
    if (d / "s.yaml").exists():
        case("structure YAML", load_structure, d / "s.yaml")


# -- matrices files -------------------------------------------------------------------------------

arrays = st.dictionaries(
    st.sampled_from(["M", "K0", "K_lower", "K_upper", "K9", "X"]),
    st.tuples(st.integers(0, 7), st.integers(0, 7), st.sampled_from(["f8", "f4", "i4", "?", "c16", "U3"]),
              st.floats(allow_nan=True, allow_infinity=True, width=32)),
    max_size=5)


@SETTINGS
@given(spec=arrays, damage=st.one_of(st.none(), st.tuples(st.integers(0, 10**6), st.binary(max_size=16))),
       truncate=st.one_of(st.none(), st.integers(0, 10**6)))
def test_fuzz_matrices_file(tmp_path_factory, spec, damage, truncate):
    from shm_ros.io.structure import load_structure

    d = _workdir(tmp_path_factory, "mx")
    shutil.copy(EXAMPLES / "matrices.yaml", d / "s.yaml")
    if spec:
        out = {}
        for k, (n, m, dt, v) in spec.items():
            a = np.full((n, m), v).astype(dt) if dt != "U3" else np.full((n, m), "ab")
            out[k] = a + a.T if n == m and dt in ("f8", "f4", "i4") else a
        buf = io.BytesIO()
        np.savez(buf, **out)
        data = bytearray(buf.getvalue())
    else:
        data = bytearray((EXAMPLES / "matrices.npz").read_bytes())
    if damage is not None:
        at, patch = damage
        at %= max(1, len(data))
        data[at:at + len(patch)] = patch
    if truncate is not None:
        data = data[: truncate % (len(data) + 1)]
    (d / "matrices.npz").write_bytes(bytes(data))
    case("matrices file", load_structure, d / "s.yaml")


# -- bags -------------------------------------------------------------------------------------------

@pytest.fixture(scope="module")
def small_bag(tmp_path_factory) -> tuple[Path, Path]:
    from shm_ros.io.importers import ImportedRecord, write_bag

    d = tmp_path_factory.mktemp("bag")
    rng = np.random.default_rng(0)
    rec = ImportedRecord(["s1", "s2"], rng.standard_normal((3000, 2)) * 0.01, 100.0, 1_714_521_600_000_000_000)
    write_bag([rec], d / "bag")
    (d / "s.yaml").write_text(
        "name: t\nkind: girder\ngirder:\n  spans: [10.0]\n  elements_per_span: 4\n"
        "  section: {E: 3.0e+10, I: 0.5, A: 2.0, rho: 2500}\n"
        "  bearings:\n    - {x: 0.0, k_vertical: 1.0e+9}\n    - {x: 10.0, k_vertical: 1.0e+9}\n"
        "sensors:\n  - {id: s1, at: {x: 3.0}, direction: vertical}\n"
        "  - {id: s2, at: {x: 6.0}, direction: vertical}\n")
    return d / "bag", d / "s.yaml"


@SETTINGS
@given(flips=st.lists(st.tuples(st.integers(0, 10**7), st.binary(min_size=1, max_size=8)), max_size=6),
       truncate=st.one_of(st.none(), st.integers(0, 10**7)),
       metadata=st.one_of(st.none(), st.text(max_size=80), st.sampled_from(["", "rosbag2_bagfile_information: 7"])))
def test_fuzz_damaged_bags(tmp_path_factory, small_bag, flips, truncate, metadata):
    from shm_ros.io.recording import ingest_bag
    from shm_ros.io.structure import load_structure

    src, structure = small_bag
    d = _workdir(tmp_path_factory, "bg")
    shutil.copytree(src, d / "bag")
    mcap = next((d / "bag").glob("*.mcap"))
    data = bytearray(mcap.read_bytes())
    for at, patch in flips:
        at %= len(data)
        data[at:at + len(patch)] = patch
    if truncate is not None:
        data = data[: truncate % (len(data) + 1)]
    mcap.write_bytes(bytes(data))
    if metadata is not None:
        (d / "bag" / "metadata.yaml").write_text(metadata)
    case("bag (MCAP)", ingest_bag, d / "bag", load_structure(structure), window_s=10.0)


# -- CDR decoding and ingest's message handlers -----------------------------------------------------

@functools.lru_cache(maxsize=1)
def _typestore():
    from rosbags.typesys import Stores, get_typestore

    return get_typestore(Stores.ROS2_HUMBLE)


def _imu_cdr(stamp_s: int, nanosec: int, frame: str, acc: tuple[float, float, float]) -> bytes:
    ts = _typestore()
    Imu = ts.types["sensor_msgs/msg/Imu"]
    Header, Time = ts.types["std_msgs/msg/Header"], ts.types["builtin_interfaces/msg/Time"]
    Quat, Vec = ts.types["geometry_msgs/msg/Quaternion"], ts.types["geometry_msgs/msg/Vector3"]
    msg = Imu(Header(Time(stamp_s, nanosec), frame), Quat(0.0, 0.0, 0.0, 1.0), np.zeros(9), Vec(0.0, 0.0, 0.0),
              np.zeros(9), Vec(*acc), np.zeros(9))
    return bytes(ts.serialize_cdr(msg, "sensor_msgs/msg/Imu"))


@SETTINGS
@given(messages=st.lists(st.one_of(
    st.binary(max_size=400),
    st.tuples(st.integers(-(2**31), 2**31 - 1), st.integers(0, 2**32 - 1), st.text(max_size=10),
              st.tuples(*[st.floats(allow_nan=True, allow_infinity=True)] * 3),
              st.lists(st.tuples(st.integers(0, 400), st.binary(min_size=1, max_size=4)), max_size=3),
              st.integers(0, 400))), min_size=1, max_size=8))
def test_fuzz_imu_cdr(messages):
    from shm_ros.io.imu_cdr import decode_imu_views

    datas = []
    for m in messages:
        if isinstance(m, bytes):
            datas.append(m)
            continue
        sec, nsec, frame, acc, patches, cut = m
        data = bytearray(_imu_cdr(sec, nsec, frame, acc))
        for at, patch in patches:
            data[at % len(data):at % len(data) + len(patch)] = patch
        datas.append(bytes(data[: max(0, len(data) - cut)] if cut < 40 else data))
    lengths = np.array([len(x) for x in datas], np.int64)
    starts = np.concatenate(([0], np.cumsum(lengths)[:-1])).astype(np.int64)
    buf = np.frombuffer(b"".join(datas), np.uint8)
    out = case("Imu CDR", decode_imu_views, buf, starts, lengths)
    assert out.stamps_ns.size + len(out.failures) == len(datas)


@SETTINGS
@given(blocks=st.lists(st.tuples(
    st.one_of(st.integers(-(2**70), 2**70), st.floats(allow_nan=True, allow_infinity=True)),
    st.one_of(st.floats(allow_nan=True, allow_infinity=True), st.integers(-5, 10**6), st.text(max_size=3)),
    st.lists(st.sampled_from(["s1", "s2", "zz", "", "s1"]), max_size=4),
    st.lists(st.floats(allow_nan=True, allow_infinity=True), max_size=40),
    st.sampled_from(["m/s^2", "g", "cm/s^2", "furlong", ""])), max_size=6),
    samples=st.lists(st.tuples(st.integers(-(2**63), 2**63 - 1), *[st.floats(allow_nan=True)] * 3), max_size=30),
    temps=st.lists(st.tuples(st.integers(-(2**70), 2**70), st.one_of(st.floats(allow_nan=True), st.text(max_size=3))),
                   max_size=5))
def test_fuzz_ingest_handlers(blocks, samples, temps):
    """What the ingest node's callbacks hand the core: AccelBlock fields, Imu samples, temperatures.
    The core rejects what it cannot use with a diagnostic; it never raises."""
    from shm_ros.core.ingest import ChannelMap, IngestConfig, IngestCore

    core = IngestCore(ChannelMap.simple(["s1", "s2"]), IngestConfig(window_s=1.0, max_latency_s=float("inf")))

    def feed():
        for stamp, rate, names, flat, units in blocks:
            core.add_block(stamp, rate, names, np.asarray(flat, float), units)
        for t, ax, ay, az in samples:
            core.add_accel_sample("s1", t, ax, ay, az)
        for t, v in temps:
            core.add_temperature("t1", t, v)
        return core.flush()

    windows = case("ingest handlers", feed)
    assert not isinstance(windows, ShmError)
    st_ = core.stats
    assert st_.samples_windowed <= st_.samples_in


# -- importers --------------------------------------------------------------------------------------

CSV_ALPHABET = st.sampled_from(list("0123456789,;.\t -+eE\n") + ["nan", "a", "time", "#", "inf", "\r\n", '"'])


@SETTINGS
@given(text=st.lists(CSV_ALPHABET, max_size=120).map("".join),
       header=st.sampled_from(["", "a,b\n", "time,a,b\n", "t;x\n"]),
       opts=st.fixed_dictionaries({}, optional={
           "sample_rate_hz": st.one_of(st.floats(allow_nan=True, allow_infinity=True), st.integers(-3, 1000)),
           "time_column": st.sampled_from(["time", "t", "a", "zz"]),
           "start": st.sampled_from(["0", "1e12", "-1", "inf", "2024-05-01T00:00:00Z", "x", "2038-01-20T00:00:00Z"]),
           "channels": st.lists(st.sampled_from(["a", "b", "time", "q"]), max_size=3),
           "units": st.sampled_from(["m/s^2", "g", "furlong"])}))
def test_fuzz_csv_import(tmp_path_factory, text, header, opts):
    from shm_ros.io.importers import read_csv, write_bag

    d = _workdir(tmp_path_factory, "csv")
    (d / "a.csv").write_text(header + text)

    def run():
        rec = read_csv(d / "a.csv", **opts)
        return write_bag([rec], d / "bag")

    case("CSV import", run)
    assert not [p for p in d.iterdir() if ".partial-" in p.name]


@SETTINGS
@given(shape=st.lists(st.integers(0, 6), max_size=3), dtype=st.sampled_from(["f8", "i2", "?", "c8", "U2", "u1"]),
       fill=st.floats(allow_nan=True, allow_infinity=True), damage=st.binary(max_size=12),
       at=st.integers(0, 400), rate=st.one_of(st.floats(allow_nan=True, allow_infinity=True), st.integers(-2, 10)),
       start=st.sampled_from([None, "0", "1e11", "bad"]))
def test_fuzz_npy_import(tmp_path_factory, shape, dtype, fill, damage, at, rate, start):
    from shm_ros.io.importers import read_npy, write_bag

    d = _workdir(tmp_path_factory, "npy")
    a = np.full(shape, fill).astype(dtype) if dtype != "U2" else np.full(shape, "x")
    buf = io.BytesIO()
    np.save(buf, a)
    data = bytearray(buf.getvalue())
    if damage:
        data[at % max(1, len(data)):at % max(1, len(data)) + len(damage)] = damage
    (d / "a.npy").write_bytes(bytes(data))

    def run():
        return write_bag([read_npy(d / "a.npy", sample_rate_hz=rate, start=start)], d / "bag")

    case("NPY import", run)


@pytest.fixture(scope="module")
def v2_text() -> str:
    with zipfile.ZipFile(ROOT / "test" / "data" / "csmip_v2_sample" / "Inglewood_17May2009_CE13795P.zip") as z:
        name = sorted(n for n in z.namelist() if n.upper().endswith(".V2"))[0]
        text = z.read(name).decode("latin-1")
    # one channel section, shortened: the header and a few data lines
    lines = text.split("\n")
    k = next(i for i, ln in enumerate(lines) if "points of accel data" in ln)
    return "\n".join(lines[:k] + [lines[k].replace(lines[k].split()[0], "20", 1)] + lines[k + 1:k + 4]) + "\n/&\n"


@SETTINGS
@given(edits=st.lists(st.tuples(st.integers(0, 10**6), st.text(max_size=6)), max_size=5),
       cut=st.one_of(st.none(), st.integers(0, 10**6)))
def test_fuzz_v2_import(tmp_path_factory, v2_text, edits, cut):
    from shm_ros.io.importers import read_v2

    text = v2_text
    for at, patch in edits:
        at %= len(text)
        text = text[:at] + patch + text[at + len(patch):]
    if cut is not None:
        text = text[: cut % (len(text) + 1)]
    d = _workdir(tmp_path_factory, "v2")
    (d / "a.V2").write_text(text, encoding="latin-1", errors="replace")
    case("CSMIP V2 import", read_v2, d / "a.V2")


@pytest.fixture(scope="module")
def mseed_bytes() -> bytes:
    obspy = pytest.importorskip("obspy")
    tr = obspy.Trace(np.arange(500, dtype=np.int32), header={"sampling_rate": 100.0, "network": "XX",
                                                             "station": "S1", "channel": "HNZ"})
    buf = io.BytesIO()
    obspy.Stream([tr]).write(buf, format="MSEED", reclen=512)
    return buf.getvalue()


@SETTINGS
@given(flips=st.lists(st.tuples(st.integers(0, 10**6), st.binary(min_size=1, max_size=4)), max_size=5),
       cut=st.one_of(st.none(), st.integers(0, 10**6)), scale=st.floats(allow_nan=True, allow_infinity=True))
def test_fuzz_miniseed_import(tmp_path_factory, mseed_bytes, flips, cut, scale):
    from shm_ros.io.importers import read_miniseed, write_bag

    data = bytearray(mseed_bytes)
    for at, patch in flips:
        data[at % len(data):at % len(data) + len(patch)] = patch
    if cut is not None:
        data = data[: cut % (len(data) + 1)]
    d = _workdir(tmp_path_factory, "ms")
    (d / "a.mseed").write_bytes(bytes(data))

    def run():
        return write_bag(read_miniseed(d / "a.mseed", scale=scale if math.isfinite(scale) else 1.0), d / "bag")

    case("MiniSEED import", run)


# -- ROS parameters -------------------------------------------------------------------------------

GRAPH = yaml.safe_load((ROOT / "config" / "pipeline.yaml").read_text())


@SETTINGS
@given(changes=edits, raw=st.one_of(st.none(), st.text(max_size=80)))
def test_fuzz_graph_parameters_file(tmp_path_factory, changes, raw):
    from shm_ros.ros.supervisor import load_graph_config

    d = _workdir(tmp_path_factory, "gr")
    if raw is None:
        try:
            raw = yaml.safe_dump(_mutate(yaml.safe_load(yaml.safe_dump(GRAPH)), changes))
        except (yaml.YAMLError, ValueError, OverflowError):
            return
    (d / "g.yaml").write_text(raw, encoding="utf-8", errors="replace")
    case("graph parameters file", load_graph_config, d / "g.yaml")


@settings(SETTINGS, max_examples=500 if FULL else 100)
@given(params=st.dictionaries(st.sampled_from(["window_s", "min_window_s", "sample_rate_hz", "snap_tolerance",
                                               "event_detector", "implausible_m_s2", "max_repeats", "spike_k",
                                               "settle_s", "clip_run", "unknown_one"]),
                              st.one_of(st.booleans(), st.integers(-5, 10**6), st.text(max_size=5),
                                        st.floats(allow_nan=True, allow_infinity=True),
                                        st.lists(st.text(max_size=3), max_size=2)), max_size=4))
def test_fuzz_node_parameters(ros_context, params):
    """A node's parameters as a parameters file gives them: accepted, or the node stops at start
    with one message naming itself and the parameter (SystemExit, what the supervisor reports);
    nothing else escapes."""
    from rclpy.node import Node

    from shm_ros.core.ingest import IngestConfig
    from shm_ros.ros.node_main import overrides
    from shm_ros.ros.params import load_config

    def start():
        node = Node("fuzz_ingest", parameter_overrides=overrides(params))
        try:
            return load_config(node, IngestConfig)
        except SystemExit as exc:
            assert str(exc.code).startswith("fuzz_ingest: ") and ("parameter" in str(exc.code)
                                                                   or "parameters:" in str(exc.code)), exc.code
            return exc
        finally:
            node.destroy_node()

    case("ROS node parameters", start)


@pytest.fixture(scope="module")
def ros_context():
    rclpy = pytest.importorskip("rclpy")
    rclpy.init()
    yield
    rclpy.try_shutdown()
