"""Quiet Warp start-up, and one line on stderr when kernels are compiled rather than loaded.

Warp prints a banner and module-load lines through its logger, and its native library writes
"Warp CUDA warning: Could not find or load the NVIDIA CUDA driver" straight to file
descriptor 2 (so neither ``wp.config.quiet`` nor redirecting ``sys.stderr`` hides it).
``init_warp(verbose=False)`` lowers the logger to warnings and runs ``wp.init()`` with
descriptor 2 pointed at a temporary file, then passes on whatever else was written there.

A first run compiles every kernel module (about a minute on a 2-core CPU; later runs load them
from Warp's kernel cache in well under a second), during which a progress bar would sit at zero.
``announce_compiles`` makes the first module compile print one line saying so, with an estimate
from the number of this package's modules that are not loaded yet and ``SECONDS_PER_MODULE``.
"""

from __future__ import annotations

import os
import sys
import tempfile

import warp as wp

# Measured on the 2-core CI CPU (LLVM, -O2) from an empty kernel cache: the first step of
# mixed_rain.toml compiled 9 modules in 36 s while 16 of this package's imported modules were
# not loaded yet (the rest compile when first used), so 2.25 s per pending module.  CUDA (NVRTC)
# compiles faster, so this is an upper estimate there.
SECONDS_PER_MODULE = 2.25

CUDA_DRIVER_WARNING = "Could not find or load the NVIDIA CUDA driver"

_announced = False


def quiet_warp():
    """Silence Warp's start-up banner and module-load lines (call before Warp initialises)."""
    wp.config.quiet = True  # Warp releases that predate log_level
    if hasattr(wp.config, "log_level") and hasattr(wp, "LOG_WARNING"):
        wp.config.log_level = wp.LOG_WARNING


def init_warp(verbose: bool = False):
    """Initialise Warp: with its banner and warnings when ``verbose``, silently otherwise."""
    if verbose:
        wp.config.quiet = False
        if hasattr(wp, "LOG_INFO"):
            wp.config.log_level = wp.LOG_INFO
        wp.init()
        return
    quiet_warp()
    sys.stderr.flush()
    try:
        saved = os.dup(2)
    except OSError:  # no descriptor 2 (embedded interpreters): nothing to hide
        wp.init()
        return
    with tempfile.TemporaryFile() as captured:
        os.dup2(captured.fileno(), 2)
        try:
            wp.init()
        finally:
            os.dup2(saved, 2)
            os.close(saved)
        captured.seek(0)
        text = captured.read().decode(errors="replace")
    # anything but the driver warning (a CPU-only machine's normal state) still gets through
    rest = [line for line in text.splitlines() if CUDA_DRIVER_WARNING not in line and line.strip()]
    if rest:
        print("\n".join(rest), file=sys.stderr)


def pending_modules() -> int:
    """How many of this package's imported kernel modules are not loaded on any device yet."""
    from warp._src import context

    return sum(1 for name, m in context.user_modules.items()
               if name.startswith("warp_sim") and not m.execs)


def announce_compiles(stream=None):
    """Print one line before the first kernel module of this process is compiled (not loaded).

    Hooks ``Module._compile`` (Warp 1.10 to 1.19 pass the cache folder and binary name to it);
    on a Warp without that method this does nothing.
    """
    from warp._src import context

    original = getattr(context.Module, "_compile", None)
    if original is None or getattr(original, "_warp_sim_hook", False):
        return

    def _compile(self, device, output_dir=None, output_name=None, *args, **kwargs):
        global _announced
        if not _announced and output_dir and output_name and wp.config.cache_kernels \
                and not os.path.exists(os.path.join(output_dir, output_name)):
            _announced = True
            seconds = max(1, round(pending_modules() * SECONDS_PER_MODULE))
            print(f"compiling kernels (first run, ~{seconds} s)…", file=stream or sys.stderr, flush=True)
        return original(self, device, output_dir, output_name, *args, **kwargs)

    _compile._warp_sim_hook = True
    context.Module._compile = _compile
