"""warp_sim: rigid spheres and boxes on a procedural Fourier terrain, on NVIDIA Warp kernels.

The layout follows Newton: a static ``Model`` built by ``ModelBuilder``, a double-buffered
``State``, a preallocated ``Contacts`` buffer, and a solver whose ``step(model, state_in,
state_out, contacts, dt)`` advances one substep.  ``Simulator`` owns all of them and runs
whole frames.  Nothing here imports OpenGL.
"""

from .builder import ModelBuilder
from .contacts import ContactOverflowError, Contacts
from .model import Model
from .simulator import NonFiniteStateError, SimConfig, Simulator
from .state import State
from .terrain import FourierTerrain, NoTerrain, PlaneTerrain

__all__ = [
    "ContactOverflowError",
    "Contacts",
    "FourierTerrain",
    "Model",
    "ModelBuilder",
    "NoTerrain",
    "NonFiniteStateError",
    "PlaneTerrain",
    "SimConfig",
    "Simulator",
    "State",
]
