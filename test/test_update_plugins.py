"""Updating is a pipeline of plug-ins: a likelihood and a sampler are each one file, registered by name.

The two files in ``test/plugins/`` are loaded at test time (as a user's ``SHM_ROS_KINDS`` files are)
and ``update`` runs with them; the posterior must hold the truth the data were simulated from. And the
pipeline stays readable: no function in ``shm_ros/core/bayes/`` is longer than 60 lines.
"""

from __future__ import annotations

import ast
from pathlib import Path

import numpy as np
import pytest
from bayes_synth import building_dict, spec_and_model, synth_modal

from shm_ros.core.bayes.likelihood_kinds.base import LIKELIHOODS, LikelihoodName
from shm_ros.core.bayes.sampler_kinds.base import SAMPLERS, SamplerName
from shm_ros.core.bayes.update import UpdateConfig, update
from shm_ros.core.plugins import load_kind_module

HERE = Path(__file__).resolve().parent
BAYES = HERE.parent / "shm_ros" / "core" / "bayes"
TRUTH = np.array([0.93, 1.06, 0.97])


@pytest.fixture
def toys():
    for f in ("toy_likelihood.py", "toy_sampler.py"):
        load_kind_module(HERE / "plugins" / f)
    yield
    LIKELIHOODS.unregister("toy-frequencies")
    SAMPLERS.unregister("toy-random-walk")


def test_registries_are_keyed_by_the_enums():
    assert set(LIKELIHOODS.names()) >= {m.value for m in LikelihoodName}
    assert set(SAMPLERS.names()) >= {m.value for m in SamplerName}
    with pytest.raises(ValueError, match="update.likelihood must be one of .*gaussian.*got 'nope'"):
        UpdateConfig(likelihood="nope").validate()


def test_update_runs_with_a_likelihood_and_a_sampler_registered_at_test_time(toys):
    spec, model = spec_and_model(building_dict())
    obs = synth_modal(model, TRUTH, ["f2", "f4", "f6", "f8"], 30, np.random.default_rng(5))
    cfg = UpdateConfig(likelihood="toy-frequencies", sampler="toy-random-walk", n_steps=600, evidence=False,
                       rhat_target=1.1, ess_target=100, seed=4)
    post = update(model, obs, cfg, priors=spec.parameters)
    assert post.diagnostics["likelihood"] == "toy-frequencies"
    assert post.diagnostics["sampler"] == "toy-random-walk"
    assert post.diagnostics["pairing"]["model_modes"]  # the shared pairing step ran for it
    for name, truth in zip(post.parameter_names, TRUTH, strict=True):
        p = post.parameters[name]
        # 4 posterior standard deviations: a correct run fails this with probability < 1e-4
        assert abs(p.mean - truth) < 4 * p.std and p.std < 0.05, (name, p, truth)


def test_no_function_in_bayes_is_longer_than_60_lines():
    long = []
    for path in sorted(BAYES.rglob("*.py")):
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            if isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef):
                n = node.end_lineno - node.lineno + 1
                if n > 60:
                    long.append(f"{path.relative_to(HERE.parent)}:{node.lineno} {node.name} ({n} lines)")
    assert not long, "functions longer than 60 lines:\n" + "\n".join(long)


def test_no_comparison_of_likelihood_or_sampler_names_remains():
    names = {m.value for m in LikelihoodName} | {m.value for m in SamplerName}
    found = []
    for path in sorted(BAYES.rglob("*.py")):
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            if isinstance(node, ast.Compare):
                consts = [c.value for c in [node.left, *node.comparators] if isinstance(c, ast.Constant)]
                consts += [e.value for c in node.comparators if isinstance(c, ast.Tuple | ast.List | ast.Set)
                           for e in c.elts if isinstance(e, ast.Constant)]
                if any(c in names for c in consts):
                    found.append(f"{path.name}:{node.lineno}")
    assert not found, f"comparisons with likelihood or sampler names: {found}"
