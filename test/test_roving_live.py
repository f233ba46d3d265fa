"""The robot's interface through a live graph: the roving node in its own process, a test node as the
robot (test/roving_robot.py), real DDS. The robot hears "continue" while its setup is short and
"enough" once it is not; doubled sensor noise makes "enough" come later; the suggested point's
expected uncertainty reduction matches a brute-force search over the points; a roving bag replayed
through the graph gives the offline global modes."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("rclpy")

from roving_robot import Robot, start_node, stop_node  # noqa: E402

from shm_ros.core.modal import mac  # noqa: E402
from shm_ros.core.models import build_model  # noqa: E402
from shm_ros.core.roving.pipeline import RovingConfig, roving_modes  # noqa: E402
from shm_ros.core.simulate.roving import RovingOptions, simulate_roving  # noqa: E402
from shm_ros.io.roving_bag import read_roving_bag, write_roving_bag  # noqa: E402
from shm_ros.io.structure import load_structure  # noqa: E402

EXAMPLE = Path(__file__).resolve().parents[1] / "examples" / "girder_roving.yaml"
SPEC = load_structure(EXAMPLE)
FS = 50.0
# One mode of interest (mode 1, cleanly separated) and a threshold at which a setup at p01 (near a
# node of mode 1, so its component is small against the noise) is limited by the sensors' noise.
PARAMS = dict(n_modes=1, shape_std_max=0.007)
NOISE = 2.0e-3


@pytest.fixture(scope="module")
def ros():
    import rclpy
    rclpy.init()
    yield
    rclpy.shutdown()


def _first_setup(noise: float):
    rec = simulate_roving(SPEC, RovingOptions(seed=1, dwell_s=120.0, n_points=2, fs=FS, noise_rms_m_s2=noise))
    node = start_node(EXAMPLE, **PARAMS)
    robot = Robot(SPEC)
    try:
        robot.load(rec)
        robot.wait_for_node()
        assert not robot.goal_accepted("p99")  # not a measurement point: refused, the node lives on
        _, t0, t1, point = rec.phases[0]
        i0, i1 = np.searchsorted(rec.times_ns * 1e-9, [t0, t1 + 1e-6])
        return robot.record_at(point, int(i0), int(i1))
    finally:
        robot.close()
        log = stop_node(node)
        print(log[-3000:])


def _brute_force(measured, candidates):
    """trace(cov) of the modal coordinates before and after each candidate, by inversion."""
    model = build_model(SPEC)
    shapes = model.modes(n_modes=PARAMS["n_modes"]).shapes
    at = {s.id: s.at for s in SPEC.sensors} | {p.id: p.at for p in SPEC.measurement_points}
    rows = {k: model.location_row(a) @ shapes for k, a in at.items()}
    sigma = PARAMS["shape_std_max"] * np.max(np.abs(np.array(list(rows.values()))))
    m = np.array([rows[i] for i in measured])
    before = np.trace(np.linalg.inv(m.T @ m / sigma ** 2))
    return {c: before - np.trace(np.linalg.inv((m.T @ m + np.outer(rows[c], rows[c])) / sigma ** 2))
            for c in candidates}


def test_continue_then_enough_later_with_more_noise_and_the_next_point(ros):
    base, noisy = _first_setup(NOISE), _first_setup(2 * NOISE)

    def first_enough(goal):
        return next((t for s, t, _ in goal.feedback if s == "enough"), np.inf)

    for g in (base, noisy):
        assert g.feedback and g.feedback[0][0] == "continue", g.feedback  # a short setup is not enough
    t_base, t_noisy = first_enough(base), first_enough(noisy)
    print("feedback", [(s, t, np.round(v, 4).tolist()) for s, t, v in base.feedback], "doubled noise",
          [(s, t, np.round(v, 4).tolist()) for s, t, v in noisy.feedback])
    assert np.isfinite(t_base) and base.result.enough, base.feedback  # ... a long one is
    assert all(s == "continue" for s, t, _ in base.feedback if t < t_base)
    assert t_noisy > t_base, (base.feedback, noisy.feedback)
    # the suggested point: the largest expected reduction, within 1 % of a brute-force search
    res = base.result
    cands = [p.id for p in SPEC.measurement_points if p.id != "p01"]
    brute = _brute_force(["s_ref1", "s_ref2", "p01"], cands)
    best = max(brute, key=brute.get)
    assert res.next_point_id == best and abs(res.expected_reduction / brute[best] - 1) < 0.01, (res, brute)
    pos = next(p.position for p in SPEC.measurement_points if p.id == best)
    assert res.next_pose.header.frame_id == SPEC.frame
    assert (res.next_pose.pose.position.x, res.next_pose.pose.position.y) == pytest.approx(pos[:2])


def test_a_bag_replayed_through_the_live_graph_gives_the_offline_modes(ros, tmp_path):
    rec = simulate_roving(SPEC, RovingOptions(seed=2, dwell_s=40.0, n_points=3, fs=FS, tf_static=True))
    bag = write_roving_bag(rec, tmp_path / "roving_bag")
    node = start_node(EXAMPLE, idle_flush_s=5.0)
    robot = Robot(SPEC)
    try:
        robot.wait_for_node()
        robot.replay_bag(bag)
        b = read_roving_bag(bag, SPEC)
        robot.spin_until(lambda: robot.modes is not None and robot.modes["roving"]["samples"] == b.times_ns.size,
                         120.0, "the global modes of the whole bag")
    finally:
        robot.close()
        log = stop_node(node)
        print(log[-3000:])
    offline = roving_modes(SPEC, b.times_ns, b.fs, b.references, b.roving, b.buffer, RovingConfig()).to_dict()
    live = robot.modes
    assert live is not None
    assert len(live["setups"]) == len(offline["setups"]) == 3
    assert len(live["global_modes"]) == len(offline["global_modes"])
    for g_live, g_off in zip(live["global_modes"], offline["global_modes"], strict=True):
        assert abs(g_live["frequency_hz"] / g_off["frequency_hz"] - 1) < 1e-3
        keys = [k for k, v in g_off["shape"].items() if v is not None]
        assert mac(np.array([g_live["shape"][k] for k in keys]), np.array([g_off["shape"][k] for k in keys])) >= 0.999
