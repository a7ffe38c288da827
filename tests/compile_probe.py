"""A one-kernel Warp module for test_commands.py's kernel-compile notice (run as a script)."""

import sys

import warp as wp

from warp_sim.quiet import announce_compiles, init_warp


@wp.kernel
def add_one(a: wp.array(dtype=float)):
    i = wp.tid()
    a[i] = a[i] + 1.0


if __name__ == "__main__":
    init_warp()
    announce_compiles()
    values = wp.zeros(4, dtype=float, device="cpu")
    wp.launch(add_one, dim=4, inputs=[values], device="cpu")
    print(values.numpy().sum())
    sys.exit(0)
