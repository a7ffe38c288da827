"""Every Warp kernel module compiles for CUDA sm_90 (NVRTC, no GPU or driver needed), so a
CUDA-only compile error fails CI on a CPU-only machine.

PTX rather than cubin: the errors live in NVRTC's front end and optimiser, ptxas would only add
register allocation (minutes more on 2 cores).  The modules are found by scanning the sources
for ``@wp.kernel``, so a new kernel module is covered without editing this test.  Compiled
into Warp's kernel cache, keyed by content: an unchanged module is not compiled again.
Measured on 2 shared cores: ~5 min cold in all (broad_phase_grid alone ~2 min: its neighbour
loops unroll into 450 kB of CUDA source), seconds warm.
"""

import concurrent.futures
import importlib
import multiprocessing
import os
from pathlib import Path

from bench.registers import kernel_modules

ROOT = Path(__file__).resolve().parents[1]


def compile_module(name: str) -> tuple[str, str, list[str]]:
    """In a fresh process: ('ok' | 'skip' | 'error', message, artefacts)."""
    import warp as wp

    wp.config.log_level = wp.LOG_WARNING
    wp.config.quiet = True
    try:
        module = importlib.import_module(name)
    except ImportError as e:  # render needs OpenGL bindings
        return "skip", f"{name} not importable here: {e}", []
    try:
        paths = wp.compile_aot_module(module, arch=90, use_ptx=True)
    except Exception as e:
        return "error", f"{name}: {type(e).__name__}: {e}", []
    return "ok", name, [p.name for p in paths]


def test_every_kernel_module_compiles_for_sm90():
    import warp as wp

    names = kernel_modules()
    assert "warp_sim.schedule.coloring" in names and len(names) >= 12
    workers = max(1, min(len(names), os.cpu_count() or 1))
    ctx = multiprocessing.get_context("spawn")
    env_path = os.environ.get("PYTHONPATH", "")
    os.environ["PYTHONPATH"] = os.pathsep.join(p for p in (str(ROOT), env_path) if p)
    # longest first, so the two slow modules do not end up in one worker at the end
    order = sorted(names, key=lambda n: -(ROOT / Path(*n.split("."))).with_suffix(".py").stat().st_size)
    with concurrent.futures.ProcessPoolExecutor(workers, mp_context=ctx) as pool:
        results = list(pool.map(compile_module, order))
    errors = [msg for status, msg, _ in results if status == "error"]
    assert not errors, "\n".join(errors)
    compiled = [(msg, paths) for status, msg, paths in results if status == "ok"]
    assert all(any(p.endswith(".sm90.ptx") for p in paths) for _, paths in compiled)
    skipped = [msg for status, msg, _ in results if status == "skip"]
    # only the OpenGL renderer may be missing its bindings
    assert all(msg.startswith("render.") for msg in skipped), skipped
