"""Candidate physics of explain, one file each (see :mod:`.base`)."""

from .base import CANDIDATES, Candidate, Context, Modification, ParamSpec

__all__ = ["CANDIDATES", "Candidate", "Context", "Modification", "ParamSpec"]
