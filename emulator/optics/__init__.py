"""Beams against the scene at time t: the only place that talks to Embree."""

from emulator.optics.hits import BeamHits, PreparedBeams, RegionCrossing
from emulator.optics.world import World

__all__ = ["BeamHits", "PreparedBeams", "RegionCrossing", "World"]
