"""An independent truth generator for shm_ros test campaigns, built on OpenSeesPy (see README.md).

Test-only: not installed with shm_ros. ``make_campaign(kind, seed, size)`` is the entry point.
"""

from .registry import KINDS, Campaign, make_campaign

__all__ = ["KINDS", "Campaign", "make_campaign"]
