"""Simulated monitoring campaigns whose truth is known (``shm-ros simulate``).

``Scenario`` / ``named_scenario`` -> ``simulate_campaign`` -> :class:`Campaign` (windows on demand)
-> ``shm_ros.io.campaign.write_campaign`` (bag, nominal structure file, ``truth.json``).
"""

from shm_ros.core.simulate.campaign import Campaign, SimulatedWindow, simulate_campaign, simulate_window
from shm_ros.core.simulate.effects import EFFECTS, EffectError, parse_effects
from shm_ros.core.simulate.scenario import NAMED, EffectRequest, Scenario, named_scenario, scenario_from_dict
from shm_ros.core.simulate.sensors import FAULT_KINDS, FaultSpec, parse_faults

__all__ = ["Campaign", "SimulatedWindow", "simulate_campaign", "simulate_window", "EFFECTS", "EffectError",
           "parse_effects", "NAMED", "EffectRequest", "Scenario", "named_scenario", "scenario_from_dict",
           "FAULT_KINDS", "FaultSpec", "parse_faults"]
