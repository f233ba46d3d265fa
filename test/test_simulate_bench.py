"""The campaign benchmark at CI size (SHM_FULL=1: the full 8-day campaign); its 10-minute target is
checked by ``python -m bench.bench_simulate``, not here."""

from __future__ import annotations

import json

from conftest import full_size

from bench.bench_simulate import FULL_WINDOWS, run


def test_campaign_benchmark(tmp_path):
    n, window_s = (FULL_WINDOWS, 600.0) if full_size() else (6, 60.0)
    res = run(n_windows=n, window_s=window_s, out_dir=str(tmp_path), keep=True, progress=False)
    truth = json.loads((tmp_path / "campaign" / "truth.json").read_text())
    assert len(truth["windows"]) == n
    assert res["samples"] == n * int(window_s * 100) * 9
    # quantised 24-bit-like samples compress: well under the 8 bytes of a raw float64
    assert res["bag_bytes_per_sample"] < 4.5
