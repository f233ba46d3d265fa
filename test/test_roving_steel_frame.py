"""Real multi-setup data: the laboratory steel frame's four setups (a roving laser vibrometer, a fixed
reference accelerometer) merged offline from arrays, both ways, against pyOMA2's PreGER on the same
data (its result stored by ``python -m bench.bench_roving --write-reference``;
test/data/pyoma_steel_frame/README.md)."""

from __future__ import annotations

import json

import numpy as np
import pytest
import steel_frame_setups as sf
import synthetic_oma as so

from shm_ros.core.modal import mac


@pytest.mark.parametrize("method", ["post", "pre"])
def test_steel_frame_merged_like_pyoma2_preger(method):
    peer = json.loads((sf.DATA / "pyoma2_preger.json").read_text())
    keys = peer["channels"]
    assert keys == sf.channel_keys()
    with so.single_blas_thread():
        modes = sf.ours(method)
    f = np.array([m.frequency_hz for m in modes])
    roving = np.array([k not in sf.REFS for k in keys])
    assert len(peer["frequency_hz"]) == 4
    for fp, shape in zip(peer["frequency_hz"], np.array(peer["shapes"]), strict=True):
        j = int(np.argmin(np.abs(f - fp)))
        assert abs(f[j] / fp - 1) < 0.01, (fp, f)
        v = modes[j].vector(keys)
        assert np.isfinite(v).all(), f"mode at {f[j]:.3f} Hz lacks points: {modes[j].notes}"
        assert mac(v, shape) >= 0.9 and mac(v[roving], shape[roving]) >= 0.9, (fp, mac(v, shape))
    if method == "post":  # every setup found the four modes: nothing merged from fewer
        assert all(modes[int(np.argmin(np.abs(f - fp)))].setups_found == 4 for fp in peer["frequency_hz"])
