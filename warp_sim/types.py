"""Enumerations shared by the builder, the kernels and the scene files.

Kernels receive these as plain ints so one compiled kernel serves every method; the dicts map
the names used in scene files and on the command line to those ints.
"""

SHAPE_SPHERE = 0
SHAPE_BOX = 1
SHAPES = {"sphere": SHAPE_SPHERE, "box": SHAPE_BOX}

INTEGRATOR_EXPLICIT_EULER = 0
INTEGRATOR_SEMI_IMPLICIT = 1
INTEGRATOR_VERLET = 2
INTEGRATOR_RK4 = 3
INTEGRATORS = {
    "explicit_euler": INTEGRATOR_EXPLICIT_EULER,
    "semi_implicit": INTEGRATOR_SEMI_IMPLICIT,
    "verlet": INTEGRATOR_VERLET,
    "rk4": INTEGRATOR_RK4,
}

ROTATION_QUATERNION = 0
ROTATION_MATRIX = 1
ROTATION_MATRIX_CROSS = 2
ROTATION_MATRIX_GRAM_SCHMIDT = 3
ROTATIONS = {
    "quaternion": ROTATION_QUATERNION,
    "matrix": ROTATION_MATRIX,
    "matrix_cross": ROTATION_MATRIX_CROSS,
    "matrix_gram_schmidt": ROTATION_MATRIX_GRAM_SCHMIDT,
}

FRICTION_COULOMB = 0
FRICTION_SLIPPERINESS = 1
FRICTION_MODELS = {"coulomb": FRICTION_COULOMB, "slipperiness": FRICTION_SLIPPERINESS}
