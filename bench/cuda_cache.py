"""Compile every kernel module to sm_90 cubins on this machine (no GPU needed) and pack them.

    python bench/cuda_cache.py --out cuda_cache.tar.xz [--arch 90] [--workers 2]

NVRTC took 141 s to compile the package on an H200 machine's first launch; a machine that unpacks
this archive into Warp's kernel cache (``tar -xJf cuda_cache.tar.xz -C ~/.cache/warp/<version>``,
which ``bench/gpu_session.sh`` does when ``CUDA_CACHE`` names the archive) loads them instead.
Warp finds a cubin by the module's content hash, so the archive fits exactly the sources it was
built from.  Cubins, not PTX: a driver older than Warp's CUDA toolkit cannot load newer PTX, and
Warp then asks for cubins (the H200's driver 13.0 against toolkit 13.4 did).
"""

from __future__ import annotations

import argparse
import concurrent.futures
import importlib
import multiprocessing
import os
import sys
import tarfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))


def compile_module(name: str, arch: int) -> tuple[str, float, list[str]]:
    """In a fresh process: (module, seconds, cubin paths), or seconds -1 and the error."""
    import warp as wp

    wp.config.log_level = wp.LOG_WARNING
    wp.config.quiet = True
    start = time.perf_counter()
    try:
        paths = wp.compile_aot_module(importlib.import_module(name), arch=arch, use_ptx=False)
    except Exception as e:  # reported, and the archive is not written
        return name, -1.0, [f"{type(e).__name__}: {e}"]
    return name, round(time.perf_counter() - start, 1), [str(p) for p in paths]


def main(argv=None, modules=None) -> int:
    """``modules``: the module names to compile (default: every kernel module of the package)."""
    from bench.registers import kernel_modules

    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--out", type=Path, required=True, help="the .tar.xz to write")
    p.add_argument("--arch", type=int, default=90)
    p.add_argument("--workers", type=int, default=os.cpu_count() or 1)
    args = p.parse_args(argv)
    names = modules or [n for n in kernel_modules() if n.startswith("warp_sim.")]
    # largest first, so that the slow modules do not meet in one worker at the end
    names.sort(key=lambda n: -(ROOT / Path(*n.split("."))).with_suffix(".py").stat().st_size)
    ctx = multiprocessing.get_context("spawn")
    cubins, failed = [], []
    with concurrent.futures.ProcessPoolExecutor(max(1, args.workers), mp_context=ctx) as pool:
        for name, seconds, paths in pool.map(compile_module, names, [args.arch] * len(names)):
            print(f"{name}: {'failed: ' + paths[0] if seconds < 0 else f'{seconds} s'}", flush=True)
            (failed if seconds < 0 else cubins).extend([name] if seconds < 0 else paths)
    if failed:
        print(f"not written: {len(failed)} modules failed", file=sys.stderr)
        return 1
    with tarfile.open(args.out, "w:xz") as tar:
        for cubin in map(Path, cubins):
            # the cache keeps one folder per module: its cubin and the meta file beside it
            for member in (cubin, cubin.with_name(cubin.name.rsplit(".", 2)[0] + ".meta")):
                if member.exists():
                    tar.add(member, arcname=f"{member.parent.name}/{member.name}")
    print(f"wrote {args.out} ({args.out.stat().st_size / 1e6:.1f} MB, {len(cubins)} modules)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
