"""Collision detection: terrain contact now; body-body broad and narrow phase plug in here."""

from .terrain_contact import collide_terrain

__all__ = ["collide_terrain"]
