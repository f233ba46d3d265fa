"""Two structures on one ROS domain: girder graphs in the namespaces /a and /b, each replaying its own
recording at the same time, give each namespace exactly what a graph running alone gives (the same
tracked modes, the same posterior), and nothing of one graph reaches the other's topics: each
recorder holds only its own namespace's topics (and the global /diagnostics), with exactly its own
windows. The two recordings differ (seed, start day), so a window that crossed over would show.

Reduced size: three 20-s windows per girder (tracking's reference period), ingest -> identify -> track ->
update (a 100-step sampler: the equality is exact whatever its length);
the two namespaced graphs run one process per node (the deployment), the two references each in one
process.
"""

from __future__ import annotations

import multiprocessing
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np

from shm_ros.cli import main

N_WINDOWS, WINDOW_S = 3, 20.0
STARTS = {"a": "2024-03-01T00:00:00Z", "b": "2024-06-01T00:00:00Z"}


def _graph(sim: str, work: str, namespace: str, single_process: bool = False) -> dict:
    """One girder graph (node processes, or all nodes in one process; DDS either way) on the
    recording in ``sim``; what its recorder holds."""
    from shm_ros.io.bags import read_messages
    from shm_ros.ros.graph_run import replay_through_graph

    run = replay_through_graph(Path(sim) / "bag", Path(sim) / "structure.yaml", work, window_s=WINDOW_S,
                               expected_windows=N_WINDOWS, identify={"uncertainty": False},
                               track={"reference_windows": 3, "training_windows": 3, "store": "none"},
                               update={"min_windows": N_WINDOWS, "min_new_windows": N_WINDOWS, "evidence": False,
                                       "n_steps": 100, "max_steps": 100},
                               timeout_s=240.0, namespace=namespace, log=lambda s: None,
                               single_process=single_process)
    assert run.output_bag is not None
    return {"lost": run.replay.lost, "tracked": run.tracked, "posteriors": run.posteriors,
            "windows": sorted(w.window_id for w in run.windows),
            "topics": sorted({m.topic for m in read_messages(run.output_bag)}),
            "diagnostics": sorted({r["source"].split(":")[0] for r in run.diagnostic_rows})}


def _same_result(alone: dict, together: dict, name: str) -> None:
    assert [r["window_id"] for r in together["tracked"]] == [r["window_id"] for r in alone["tracked"]], name
    for x, y in zip(alone["tracked"], together["tracked"], strict=True):
        assert x["mode_numbers"] == y["mode_numbers"], name
        np.testing.assert_allclose(y["frequencies_hz"], x["frequencies_hz"], rtol=1e-12, err_msg=name)
    assert alone["posteriors"] and len(together["posteriors"]) == len(alone["posteriors"]), name
    p, q = alone["posteriors"][-1]["parameters"], together["posteriors"][-1]["parameters"]
    assert set(p) == set(q), name
    for k in p:
        assert q[k]["mean"] == p[k]["mean"] and q[k]["std"] == p[k]["std"], (name, k, p[k], q[k])


def test_two_namespaced_graphs_share_a_domain_without_crosstalk(tmp_path):
    sims = {}
    for ns, seed in (("a", 1), ("b", 2)):
        sims[ns] = tmp_path / f"sim_{ns}"
        assert main(["simulate", "girder", "--out", str(sims[ns]), "--windows", str(N_WINDOWS),
                     "--window-s", str(WINDOW_S), "--start", STARTS[ns], "--quiet", "--seed", str(seed)]) == 0
    spawn = multiprocessing.get_context("spawn")  # one ROS context per graph runner
    with ProcessPoolExecutor(2, mp_context=spawn) as pool:
        pair = {ns: pool.submit(_graph, str(sims[ns]), str(tmp_path / f"pair_{ns}"), f"/{ns}") for ns in sims}
        together = {ns: f.result(timeout=300) for ns, f in pair.items()}
    # each recording alone on the domain, at the root namespace, all its nodes in one process (less
    # start-up; the results do not depend on how the nodes are spread over processes)
    alone = {ns: _graph(str(sims[ns]), str(tmp_path / f"alone_{ns}"), "", True) for ns in sims}

    for ns, other in (("a", "b"), ("b", "a")):
        got, ref = together[ns], alone[ns]
        assert got["lost"] == 0 and len(got["windows"]) == N_WINDOWS, (ns, got["windows"])
        assert got["windows"] == ref["windows"], ns
        # only this namespace's topics (and the global /diagnostics) in its recorder's bag
        assert got["topics"] and all(t.startswith(f"/{ns}/shm/") or t == "/diagnostics" for t in got["topics"]), \
            got["topics"]
        assert f"/{ns}/shm/windows" in got["topics"] and f"/{ns}/shm/posterior" in got["topics"]
        # the graph's own statuses are told apart on the shared /diagnostics
        assert got["diagnostics"] and all(s.startswith(f"{ns}/") for s in got["diagnostics"]), got["diagnostics"]
        assert not set(got["windows"]) & set(together[other]["windows"]), "the two recordings share window ids"
        _same_result(ref, got, ns)
