"""A roving recording through a rosbag2 bag (Imu per sample, /tf as tf2_msgs/msg/TFMessage) gives
the same setups and global modes as the arrays it was written from."""

from __future__ import annotations

import numpy as np
import roving_acceptance as ra
import synthetic_oma as so

from shm_ros.core.roving.pipeline import RovingConfig, roving_modes
from shm_ros.core.simulate.roving import RovingOptions, simulate_roving
from shm_ros.io.roving_bag import read_roving_bag, write_roving_bag
from shm_ros.report.inputs import ReportInputs
from shm_ros.report.sections.roving import RovingSection


def test_bag_round_trip_gives_the_same_global_modes(tmp_path):
    with so.single_blas_thread():
        rec = simulate_roving(ra.SPEC, RovingOptions(seed=5, dwell_s=40.0, n_points=3, fs=50.0, tf_static=True))
        write_roving_bag(rec, tmp_path / "bag")
        bag = read_roving_bag(tmp_path / "bag", ra.SPEC)
        assert bag.fs == 50.0 and bag.buffer.is_static("rover/accel_link")
        np.testing.assert_array_equal(bag.roving["r1"], rec.roving["r1"])
        cfg = RovingConfig(min_dwell_s=20.0)
        a = roving_modes(ra.SPEC, rec.times_ns, 50.0, rec.references, rec.roving, ra.buffer_of(rec), cfg)
        b = roving_modes(ra.SPEC, bag.times_ns, bag.fs, bag.references, bag.roving, bag.buffer, cfg)
    assert [s.points for s in b.cut.setups] == [{"r1": p} for k, _, _, p in rec.phases if k == "dwell"]
    assert b.to_dict() == a.to_dict()
    assert b.to_dict()["setups"][0]["start"].startswith("1970-01-01T00:00:00")
    # the report's section: setups, global modes and the glued shapes' figure
    doc = b.to_dict()
    doc["roving"]["positions"] = {p.id: list(p.position) for p in ra.SPEC.measurement_points} | {
        s.id: [s.at["x"], 0.0, 0.0] for s in ra.SPEC.sensors}
    sec = RovingSection().build(ReportInputs(roving=doc), tmp_path / "fig")
    assert sec is not None and len(sec.tables[0].rows) == 3 and len(sec.tables[1].rows) == len(b.global_modes)
    assert sec.figures[0].png.exists() and "s_ref1" in sec.figures[0].data.read_text()


def test_identification_section_leaves_a_roving_campaign_to_its_own_section(tmp_path):
    from shm_ros.report.inputs import IdentifyInputs
    from shm_ros.report.sections.identify import IdentifySection

    doc = {"setups": [], "global_modes": [], "roving": {}}
    empty = IdentifyInputs(estimates=[], method="ssi-cov")
    assert IdentifySection().build(ReportInputs(identify=empty, roving=doc), tmp_path) is None
    assert IdentifySection().build(ReportInputs(identify=empty), tmp_path) is not None
