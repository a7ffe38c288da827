"""Registers and local memory of every kernel, from sm_90 cubins built without a GPU.

    python bench/registers.py                 # all kernel modules (minutes on 2 cores)
    python bench/registers.py --modules warp_sim.collide.narrow_phase

NVRTC compiles each kernel module (found by scanning the sources for ``@wp.kernel``, as
tests/test_cuda_compile.py does) to an sm_90 cubin, in a temporary folder, one process per
module.  The figures are read from the cubin itself, an ELF file whose ``.nv.info`` section
holds, per kernel symbol, records of (format, attribute, size, value) (read by cubin_kernels):

    EIATTR_REGCOUNT (0x2f)     registers per thread
    EIATTR_FRAME_SIZE (0x11)   local-memory frame per thread [bytes]: register spills and local
                               arrays the compiler could not keep in registers
    EIATTR_MAX_STACK_SIZE      (0x23) and MIN_STACK_SIZE (0x12): call stack [bytes]

and ``.nv.constant0.<kernel>`` is the parameter block [bytes].  What it means on an H200:
65,536 registers per SM, so a kernel of r registers runs at most 65536 / r threads per SM
(2048 at most): occupancy falls below 100 % above 32 registers and below 50 % above 64; every
frame byte is per-thread traffic to local memory (L1/L2), which the byte model
(bench/byte_model.py) does not count.  Results: bench/results/registers_sm90.{csv,json,png}.
"""

from __future__ import annotations

import argparse
import concurrent.futures
import importlib
import multiprocessing
import re
import struct
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

REGCOUNT, FRAME_SIZE, MIN_STACK, MAX_STACK = 0x2F, 0x11, 0x12, 0x23
EIFMT_NVAL, EIFMT_BVAL, EIFMT_HVAL, EIFMT_SVAL = 1, 2, 3, 4
REGISTERS_PER_SM, THREADS_PER_SM = 65536, 2048  # sm_90


def kernel_modules() -> list[str]:
    """Dotted names of every module of warp_sim/ and render/ that defines a kernel."""
    names = []
    for package in ("warp_sim", "render"):
        for path in sorted((ROOT / package).rglob("*.py")):
            if "@wp.kernel" in path.read_text():
                names.append(".".join(path.relative_to(ROOT).with_suffix("").parts))
    return names


def elf_sections(data: bytes) -> dict[str, tuple[int, int, int]]:
    """Section name -> (offset, size, link) of a 64-bit little-endian ELF file."""
    if data[:4] != b"\x7fELF" or data[4] != 2 or data[5] != 1:
        raise ValueError("not a 64-bit little-endian ELF file")
    (shoff,) = struct.unpack_from("<Q", data, 0x28)
    shentsize, shnum, shstrndx = struct.unpack_from("<HHH", data, 0x3A)
    raw = []
    for k in range(shnum):
        name, _type, _flags, _addr, offset, size, link, _info, _align, _entsize = struct.unpack_from(
            "<IIQQQQIIQQ", data, shoff + k * shentsize)
        raw.append((name, offset, size, link))
    names_at = raw[shstrndx][1]

    def cstring(at: int) -> str:
        return data[at: data.index(b"\0", at)].decode()

    return {cstring(names_at + name): (offset, size, link) for name, offset, size, link in raw}


def cubin_kernels(data: bytes) -> dict[str, dict]:
    """Per kernel symbol of a cubin: registers, frame, stack and parameter bytes."""
    sections = elf_sections(data)
    symtab_offset, symtab_size, symtab_link = sections[".symtab"]
    strtab_offset = list(sections.values())[symtab_link][0]

    def symbol(index: int) -> str:
        (name,) = struct.unpack_from("<I", data, symtab_offset + 24 * index)
        at = strtab_offset + name
        return data[at: data.index(b"\0", at)].decode()

    kernels: dict[str, dict] = {}
    for name, (offset, size, _link) in sections.items():
        if name.startswith(".nv.constant0."):
            kernels.setdefault(name[len(".nv.constant0."):], {})["param_bytes"] = size
    for name, (offset, size, _link) in sections.items():
        if name != ".nv.info":
            continue  # the per-kernel .nv.info.<kernel> sections hold parameter layouts, not these
        pos, end = offset, offset + size
        while pos < end:
            fmt, attr = data[pos], data[pos + 1]
            pos += 2
            if fmt == EIFMT_SVAL:
                (length,) = struct.unpack_from("<H", data, pos)
                value = data[pos + 2: pos + 2 + length]
                pos += 2 + length
                if attr in (REGCOUNT, FRAME_SIZE, MIN_STACK, MAX_STACK) and length == 8:
                    index, amount = struct.unpack("<II", value)
                    kernel = symbol(index)
                    if kernel in kernels:
                        key = {REGCOUNT: "registers", FRAME_SIZE: "frame_bytes", MIN_STACK: "min_stack_bytes",
                               MAX_STACK: "max_stack_bytes"}[attr]
                        kernels[kernel][key] = amount
            elif fmt == EIFMT_HVAL:
                pos += 2
            elif fmt == EIFMT_BVAL:
                pos += 1
            elif fmt != EIFMT_NVAL:
                raise ValueError(f"unknown .nv.info record format {fmt} in {name}")
    return kernels


def readable(symbol: str) -> str:
    """Warp's ``<kernel>_<hash>_cuda_kernel_forward`` -> ``<kernel>`` (an adjoint, which a module
    compiles unless it sets enable_backward False, keeps its suffix ``backward``)."""
    return re.sub(r"_[0-9a-f]{8}_cuda_kernel_(forward|backward)$", lambda m: "" if m.group(1) == "forward"
                  else " (backward)", symbol)


def compile_module(name: str, folder: str) -> tuple[str, list[dict], str]:
    """In a fresh process: compile ``name`` for sm_90 to a cubin and read its kernels."""
    import warp as wp

    wp.config.quiet = True
    wp.config.log_level = wp.LOG_WARNING
    start = time.perf_counter()
    try:
        module = importlib.import_module(name)
    except ImportError as e:  # render needs OpenGL bindings
        return name, [], f"skipped: not importable here ({e})"
    paths = wp.compile_aot_module(module, arch=90, use_ptx=False, module_dir=folder)
    rows = []
    for path in paths:
        if path.suffix == ".cubin":
            for symbol, figures in cubin_kernels(path.read_bytes()).items():
                registers = figures.get("registers", 0)
                occupancy = min(THREADS_PER_SM, REGISTERS_PER_SM // max(registers, 1)) / THREADS_PER_SM
                rows.append({"module": name, "kernel": readable(symbol), "registers": registers,
                             "frame_bytes": figures.get("frame_bytes", 0),
                             "max_stack_bytes": figures.get("max_stack_bytes", 0),
                             "param_bytes": figures.get("param_bytes", 0),
                             "register_occupancy": round(occupancy, 3)})
    return name, rows, f"{time.perf_counter() - start:.0f} s"


def chart(rows: list[dict], path: Path):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    rows = sorted(rows, key=lambda r: r["registers"])
    fig, (ax_r, ax_f) = plt.subplots(1, 2, figsize=(13, max(4, 0.22 * len(rows))), sharey=True)
    labels = [r["kernel"] for r in rows]
    y = range(len(rows))
    ax_r.barh(y, [r["registers"] for r in rows], color="tab:blue")
    for limit, text in ((32, "100 %"), (64, "50 %"), (128, "25 %")):
        ax_r.axvline(limit, color="grey", lw=0.8, ls="--")
        ax_r.text(limit, len(rows) - 0.5, f" occupancy {text}", fontsize=7, color="grey", va="bottom")
    ax_r.set_yticks(list(y), labels, fontsize=7)
    ax_r.set_xlabel("registers per thread (sm_90)")
    ax_f.barh(y, [r["frame_bytes"] for r in rows], color="tab:red")
    ax_f.set_xlabel("local-memory frame per thread [bytes] (spills, local arrays)")
    fig.suptitle("Kernels compiled for sm_90 (NVRTC cubin, bench/registers.py)")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def main(argv=None) -> int:
    import warp as wp

    from bench.common import RESULTS, machine_info, write_rows

    wp.config.quiet = True

    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--modules", nargs="+", metavar="NAME", help="kernel modules (default: all)")
    p.add_argument("--out-dir", type=Path, default=RESULTS)
    p.add_argument("--workers", type=int, default=0, help="compile processes (default: CPU count)")
    args = p.parse_args(argv)
    names = kernel_modules()
    if args.modules:
        unknown = sorted(set(args.modules) - set(names))
        if unknown:
            p.error(f"--modules: no kernel module named {', '.join(unknown)} (known: {', '.join(names)})")
        names = args.modules
    workers = args.workers or max(1, min(len(names), multiprocessing.cpu_count()))
    rows, started = [], time.perf_counter()
    with tempfile.TemporaryDirectory(prefix="warp_sim_cubin_") as folder:
        ctx = multiprocessing.get_context("spawn")
        with concurrent.futures.ProcessPoolExecutor(workers, mp_context=ctx) as pool:
            jobs = [pool.submit(compile_module, name, folder) for name in names]
            for done, job in enumerate(concurrent.futures.as_completed(jobs), 1):
                name, found, note = job.result()
                rows += found
                print(f"[{done}/{len(names)}] {name}: {len(found)} kernels ({note}), "
                      f"{time.perf_counter() - started:.0f} s in all", flush=True)
    if not rows:
        print("no kernels compiled", file=sys.stderr)
        return 1
    rows.sort(key=lambda r: (-r["registers"], r["kernel"]))
    meta = {**machine_info("cpu"), "target": "sm_90 cubin (NVRTC)", "command": "python bench/registers.py"}
    csv_path, json_path = write_rows("registers_sm90", rows, meta, args.out_dir)
    chart(rows, Path(args.out_dir) / "registers_sm90.png")
    width = max(len(r["kernel"]) for r in rows)
    print(f"{'kernel':<{width}}  registers  occupancy  frame B  params B")
    for r in rows:
        print(f"{r['kernel']:<{width}}  {r['registers']:>9}  {r['register_occupancy']:>9.0%}  {r['frame_bytes']:>7}  "
              f"{r['param_bytes']:>8}")
    print(f"wrote {csv_path}, {json_path} and registers_sm90.png")
    return 0


if __name__ == "__main__":
    sys.exit(main())
