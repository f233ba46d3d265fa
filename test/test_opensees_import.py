"""``shm-ros import opensees``: a user's OpenSeesPy model becomes a ``kind: matrices`` structure file.

The script ``test/data/opensees/girder.py`` builds the same girder as the built-in kind below (spans
16, 24, 16 m, 8 elements per span, bearing springs). Imported: its modes 1-5 equal the built-in kind's
and OpenSees's own eigen to 0.5 %; and ``update`` on modal data simulated from a finer built-in girder
(16 elements per span: truth outside the analysis model) puts the truth inside its 95 % interval.

OpenSeesPy is optional for users but installed by the test set-up (requirements/test.txt): under CI
(``CI=true``, as ``.ci/run`` sets) its absence fails the tests instead of skipping them.
"""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from bayes_synth import synth_modal

from shm_ros.cli import main
from shm_ros.core.bayes.update import UpdateConfig, priors_from_structure, update
from shm_ros.core.models import build_model
from shm_ros.core.structure import structure_from_dict
from shm_ros.io.structure import load_structure

SCRIPT = Path(__file__).resolve().parent / "data" / "opensees" / "girder.py"
SENSOR_X = {"s1": 8.0, "s2": 19.0, "s3": 28.0, "s4": 37.0, "s5": 48.0, "s6": 52.0}
TRUTH = np.array([0.92, 1.12])  # E_scale, k_bearing
N_SEEDS = 3
PRIOR = {"dist": "lognormal", "mean": 1.0, "std": 0.1}  # what the import writes

try:
    import openseespy.opensees  # noqa: F401

    HAVE_OPENSEES = True
except ImportError:
    HAVE_OPENSEES = False

if not HAVE_OPENSEES:
    if os.environ.get("CI", "").lower() == "true":
        pytest.fail("OpenSeesPy is missing under CI (requirements/test.txt installs it)", pytrace=False)
    pytest.skip("OpenSeesPy not installed (pip install 'openseespy<3.8')", allow_module_level=True)


def builtin_girder(elements_per_span: int) -> dict:
    return {
        "name": "girder", "kind": "girder",
        "girder": {"spans": [16.0, 24.0, 16.0], "elements_per_span": elements_per_span,
                   "section": {"E": 3.4e10, "I": 2.1, "A": 5.2, "rho": 2500.0},
                   "bearings": [{"x": x, "k_vertical": 4.0e8, "k_rotation": 0.0} for x in (0.0, 16.0, 40.0, 56.0)]},
        "sensors": [{"id": s, "at": {"x": x}, "direction": "vertical"} for s, x in SENSOR_X.items()],
        "parameters": [
            {"name": "E_scale", "applies_to": "girder.section.E", "prior": dict(PRIOR)},
            {"name": "k_bearing", "applies_to": "girder.bearings[*].k_vertical", "prior": dict(PRIOR)},
        ],
    }


def _node(x: float) -> int:
    """OpenSees node tag at deck position x in the script (nodes numbered along the deck from 1)."""
    xs = np.unique(np.concatenate([np.linspace(0, 16, 9), np.linspace(16, 40, 9), np.linspace(40, 56, 9)]))
    return int(np.argmin(np.abs(xs - x))) + 1


@pytest.fixture(scope="module")
def imported(tmp_path_factory):
    out = tmp_path_factory.mktemp("opensees") / "girder.yaml"
    sensors = ",".join(f"{s}={_node(x)}:2" for s, x in SENSOR_X.items())
    code = main(["import", "opensees", str(SCRIPT), "--parameters", "E_scale=1,k_bearing=2", "--sensors", sensors,
                 "--out", str(out)])
    assert code == 0 and out.with_suffix(".npz").is_file()
    return load_structure(out)


def test_modes_equal_the_builtin_kind_and_opensees_eigen(imported):
    assert imported.kind == "matrices" and [p.name for p in imported.parameters] == ["E_scale", "k_bearing"]
    f_imported = build_model(imported).modes(n_modes=5).frequencies_hz
    f_builtin = build_model(structure_from_dict(builtin_girder(8))).modes(n_modes=5).frequencies_hz
    eigen = subprocess.run(  # OpenSees's own eigen, in a fresh process
        [sys.executable, "-c", f"import runpy, openseespy.opensees as ops; runpy.run_path({str(SCRIPT)!r}); "
         "print(repr(list(ops.eigen(5))))"], capture_output=True, text=True, timeout=120)
    assert eigen.returncode == 0, eigen.stderr
    f_opensees = np.sqrt(np.array(eval(eigen.stdout.strip().splitlines()[-1]))) / (2 * np.pi)
    np.testing.assert_allclose(f_imported, f_builtin, rtol=5e-3)
    np.testing.assert_allclose(f_imported, f_opensees, rtol=5e-3)
    # the parameters act as in the built-in kind: a softer deck, stiffer bearings
    theta = np.array([0.8, 1.3])
    builtin = build_model(structure_from_dict(builtin_girder(8)))
    np.testing.assert_allclose(build_model(imported).modes(theta, n_modes=5).frequencies_hz,
                               builtin.modes(theta, n_modes=5).frequencies_hz, rtol=5e-3)


def test_update_on_the_imported_model_recovers_the_truth(imported):
    """Three seeds x two parameters: at least 4 of the 6 95 % intervals hold the truth (a correct
    method passes with probability 0.998 for independent intervals: binomial(6, 0.95) >= 4)."""
    truth_model = build_model(structure_from_dict(builtin_girder(16)))
    model = build_model(imported)
    covered = []
    for seed in range(N_SEEDS):
        obs = synth_modal(truth_model, TRUTH, list(SENSOR_X), 40, np.random.default_rng(100 + seed))
        cfg = UpdateConfig(n_steps=400, rhat_target=1.05, ess_target=300, evidence=False, seed=seed)
        post = update(model, obs, cfg, priors=priors_from_structure(imported))
        for name, t in zip(post.parameter_names, TRUTH, strict=True):
            lo, hi = post.parameters[name].ci95
            covered.append(lo <= t <= hi)
    assert sum(covered) >= 4, covered


def test_a_parameter_the_script_does_not_declare_is_named(tmp_path):
    code = main(["import", "opensees", str(SCRIPT), "--parameters", "E_scale=7", "--sensors", "s1=5:2",
                 "--out", str(tmp_path / "x.yaml")])
    assert code == 2 and not (tmp_path / "x.yaml").exists()
