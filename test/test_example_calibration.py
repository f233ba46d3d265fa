"""The example building's calibration settings (no graph): the time-domain step's prior is the modal
posterior, and ``calibrate_on_earlier_events`` must leave earthquakes to predict."""

from __future__ import annotations

from types import SimpleNamespace

import pytest

from shm_ros.commands.example import calibration_files
from shm_ros.core.bayes.modal_prior import modal_priors
from shm_ros.core.simulate.scenario import named_scenario
from shm_ros.core.structure import structure_from_dict
from shm_ros.errors import InputError


def test_the_modal_posterior_is_the_prior():
    from shm_ros.core.simulate.scenario import BUILDING_STRUCTURE

    spec = structure_from_dict(BUILDING_STRUCTURE)
    name = spec.parameters[0].name
    params = modal_priors(spec, {name: {"mean": 1.08, "std": 0.03, "map": 1.09}})
    assert params[0].prior.dist == "normal" and params[0].prior.params == {"mean": 1.08, "std": 0.03}
    assert all(p.prior == q.prior for p, q in zip(params[1:], spec.parameters[1:], strict=True))
    assert spec.parameters[0].prior.params != {"mean": 1.08, "std": 0.03}  # the structure's own is untouched


@pytest.mark.parametrize("n", [1, 3])
def test_earlier_events_leave_later_ones(n, tmp_path):
    quakes = [{"window": i, "pga_m_s2": 1.0, "onset_s": 10.0} for i in (2, 3, 4)]
    part = {"scenario": named_scenario("building", n_windows=5, earthquakes=quakes),
            "files": SimpleNamespace(bag=tmp_path / "none", structure=tmp_path / "none.yaml"),
            "settings": {"update": {"min_windows": 5}, "predict": {"calibrate_on_earlier_events": n}}}
    with pytest.raises(InputError, match="calibrate_on_earlier_events"):
        calibration_files(part, tmp_path)


def test_no_calibration_events_change_nothing(tmp_path):
    settings = {"update": {"min_windows": 5}, "predict": {"calibrate_on_earlier_events": 0}}
    part = {"scenario": named_scenario("building", n_windows=5), "settings": settings}
    assert calibration_files(part, tmp_path) == [] and settings == {"update": {"min_windows": 5}, "predict": {}}
