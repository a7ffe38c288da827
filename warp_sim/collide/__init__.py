"""Collision detection: terrain contact, body-body broad phase (narrow phase and the pair solver
build on these)."""

from .broad_phase import BROAD_PHASES, BroadPhaseOverflowError, make_broad_phase
from .terrain_contact import collide_terrain

__all__ = ["BROAD_PHASES", "BroadPhaseOverflowError", "collide_terrain", "make_broad_phase"]
