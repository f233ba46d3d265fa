"""update: modal estimates in, posterior summary out (re-run as new windows arrive).

Accumulates ``/shm/modal_estimates``; once ``min_new_windows`` new windows have arrived (or on the
first ``min_windows``), warm-starts from the last posterior, pairs every window's modes with the nominal model by MAC and calls
:func:`shm_ros.core.bayes.update.update`; publishes ``/shm/posterior`` (latched) and writes
``posterior.json`` to ``output_dir`` when set.
"""

from __future__ import annotations

import json
import time
from pathlib import Path
from typing import Any

from rclpy.node import Node

from shm_ros.core.bayes.pairing import observations_for_model
from shm_ros.core.bayes.update import UpdateConfig, update
from shm_ros.ros import topics
from shm_ros.ros.convert import estimate_from_msg, posterior_to_msg
from shm_ros.ros.diagnostics import Diagnostics
from shm_ros.ros.node_main import overrides, spin
from shm_ros.ros.qos import latched_qos, stream_qos


class UpdateNode(Node):
    def __init__(self, name: str = "update", parameters: dict[str, Any] | None = None) -> None:
        super().__init__(name, parameter_overrides=overrides(parameters))
        defaults = UpdateConfig()
        for key, value in (("structure", ""), ("min_windows", 10), ("min_new_windows", 10),
                           ("likelihood", "gaussian"), ("sampler", defaults.sampler),
                           ("n_steps", defaults.n_steps), ("evidence", False), ("seed", 0),
                           ("output_dir", "")):
            self.declare_parameter(key, value)
        get = lambda n: self.get_parameter(n).value  # noqa: E731
        from shm_ros.core.models import build_model
        from shm_ros.io.structure import load_structure

        if not get("structure"):
            raise SystemExit("update: parameter 'structure' (path of the structure YAML) is required")
        self.spec = load_structure(get("structure"))
        self.model = build_model(self.spec)
        self.config = UpdateConfig(likelihood=str(get("likelihood")), sampler=str(get("sampler")),
                                   n_steps=int(get("n_steps")), evidence=bool(get("evidence")),
                                   seed=int(get("seed")))
        self.config.validate()
        self.min_windows = int(get("min_windows"))
        self.min_new = int(get("min_new_windows"))
        self.output_dir = Path(get("output_dir")) if get("output_dir") else None
        self.estimates: list = []
        self.posterior = None  # the last one: warm start of the next run
        self.used = 0
        self.diag = Diagnostics(self, "update")
        self.pub = self.create_publisher(topics.message_class(topics.TYPES[topics.POSTERIOR]),
                                         topics.POSTERIOR, latched_qos())
        self.create_subscription(topics.message_class(topics.TYPES[topics.MODAL_ESTIMATES]),
                                 topics.MODAL_ESTIMATES, self._on_estimate, stream_qos())

    def _on_estimate(self, msg) -> None:
        self.estimates.append(estimate_from_msg(msg))
        n = len(self.estimates)
        if n >= self.min_windows and n - self.used >= (self.min_new if self.used else 0):
            self.run_update()

    def run_update(self) -> None:
        t0 = time.perf_counter()
        n = len(self.estimates)
        try:
            obs = observations_for_model(self.model, self.estimates, self.spec.sensor_ids)
            posterior = update(self.model, obs, self.config, self.spec.parameters,
                               warm_start=self.posterior)
        except Exception as exc:  # a failed update must not take the node down
            self.diag.report("error", f"update with {n} windows failed: {exc}", "posterior")
            self.diag.publish()
            self.used = n
            return
        self.used = n
        self.posterior = posterior
        self.pub.publish(posterior_to_msg(posterior.summary_record(self.spec.name)))
        if self.output_dir is not None:
            from shm_ros.core.provenance import stamp_output

            self.output_dir.mkdir(parents=True, exist_ok=True)
            (self.output_dir / "posterior.json").write_text(json.dumps(
                stamp_output(posterior.to_dict(), self.config.__dict__ | {"n_windows": n},
                             self.config.seed), indent=1, default=float))
        summary = ", ".join(f"{k} {v.mean:.4f}±{v.std:.4f}" for k, v in posterior.parameters.items())
        level = "ok" if posterior.diagnostics.get("converged", False) else "warn"
        self.diag.report(level, f"{n} windows in {time.perf_counter() - t0:.1f} s: {summary}",
                         "posterior")
        self.diag.publish()
        self.get_logger().info(f"posterior from {n} windows: {summary}")


def make_node(name: str, parameters: dict[str, Any]) -> UpdateNode:
    return UpdateNode(name, parameters)


def main(args: list[str] | None = None) -> int:
    return spin(lambda: UpdateNode(), args)


if __name__ == "__main__":
    raise SystemExit(main())
