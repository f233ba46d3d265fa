"""IngestCore.add_blocks (a recorded run of AccelBlocks fed together) gives what add_block gives
block by block: the same windows, flags, diagnostics and counts, also with gaps, implausible
values, unknown channels and rates whose period is not a whole number of nanoseconds."""

from __future__ import annotations

import numpy as np
import pytest

from shm_ros.core.ingest import ChannelMap, IngestConfig, IngestCore

T0 = 1_714_521_600_000_000_000  # 2024-05-01T00:00:00Z


def _blocks(rate: float, n_blocks: int, per_block: int, names: list[str], seed: int):
    rng = np.random.default_rng(seed)
    period = 1e9 / rate
    stamps, samples = [], []
    for b in range(n_blocks):
        if b == 7:  # a block lost: the stream has a gap there
            continue
        x = rng.normal(0.0, 0.05, (per_block, len(names)))
        if b == 11:
            x[3, 1] = 500.0  # implausible (beyond 20 g): set to NaN and reported for this block
        if b == 15:
            x[:, 0] = np.nan  # a channel without finite values in one block
        stamps.append(T0 + int(round(b * per_block * period)))
        samples.append(x.reshape(-1))
    return stamps, samples


def _run(rate: float, names: list[str], together: bool, units: str = "m/s^2") -> tuple[IngestCore, list, int]:
    core = IngestCore(ChannelMap.simple(["a", "b", "c"]), IngestConfig(window_s=4.0, max_latency_s=float("inf")))
    calls = []
    add_block = core.add_block

    def counted(*args, **kwargs):
        calls.append(1)
        add_block(*args, **kwargs)

    core.add_block = counted  # type: ignore[method-assign]
    stamps, samples = _blocks(rate, 40, int(rate / 4), names, seed=3)
    if together:
        for lo in range(0, len(stamps), 9):  # runs of nine blocks, as a bag reader's batches give them
            core.add_blocks(stamps[lo:lo + 9], rate, names, samples[lo:lo + 9], units, topic="daq")
    else:
        for t0, x in zip(stamps, samples, strict=True):
            core.add_block(t0, rate, names, x, units, topic="daq")
    return core, core.flush(), len(calls)


@pytest.mark.parametrize(("rate", "names", "units", "joined"), [
    (100.0, ["a", "b", "c"], "m/s^2", True),
    (200.0, ["a", "b", "c"], "g", True),
    (300.0, ["a", "b", "c"], "m/s^2", False),  # a period of 3,333,333.3 ns: fed block by block
    (100.0, ["a", "b", "zz"], "m/s^2", False),  # an unknown channel: fed block by block
])
def test_a_run_of_blocks_gives_what_each_block_gives(rate, names, units, joined):
    (one, w1, n1), (run, w2, n2) = _run(rate, names, False, units), _run(rate, names, True, units)
    assert (n2 < n1 / 2) if joined else (n2 == n1)
    assert len(w1) >= 2 and len(w1) == len(w2)
    for a, b in zip(w1, w2, strict=True):
        assert a.start_ns == b.start_ns and a.channel_status == b.channel_status and a.notes == b.notes
        assert np.array_equal(a.samples, b.samples, equal_nan=True)
        assert (a.flags is None) == (b.flags is None)
        assert a.flags is None or np.array_equal(a.flags, b.flags)
    assert one.diagnostic_counts == run.diagnostic_counts
    assert [(d.code, d.source, d.message) for d in one.diagnostics] == \
        [(d.code, d.source, d.message) for d in run.diagnostics]
    assert one.stats == run.stats and one.dropped == run.dropped
    assert ("implausible", "daq.samples[b]") in one.diagnostic_counts
