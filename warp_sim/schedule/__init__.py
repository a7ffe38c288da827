"""How the body-body sweeps are made parallel without races: the GPU's colouring of the contact
graph (coloring.py) and the CPU's slabs (slabs.py).  Computed once per collision pass from the
pairs; the solver (warp_sim/solvers/) consumes either, and collide/ builds them without knowing
the solver."""
