"""Where the CPU time of the kernels goes, line by line: a sampling profile of the 10k rain.

    python bench/line_profile.py                              # 10k mixed rain, the slab sweep module
    python bench/line_profile.py --module terrain_contact --count 2000
    python bench/line_profile.py --scene spheres --module soft_step     # the fused terrain-only step
    python bench/line_profile.py --scene boxes --module terrain_contact  # boxes' terrain collision

Warp compiles CPU kernels in memory (LLVM JIT), so a profiler sees only anonymous addresses, and
timing launches (bench/versions.py) says which kernel is slow but not which line.  This script
runs the rain under ``perf record`` with the kernels built with line tables
(``-debug-info-kind=line-tables-only`` added to ``wp.config.cpu_compiler_flags``, in a kernel
cache of its own so the project's cache is untouched; the optimisation level is unchanged).
The child reports where each kernel's entry point was loaded (``wp_lookup``); each module's
object file in that cache says where the entry point sits in its ``.ltext`` section, which
gives the section's load address, and ``addr2line -i`` turns every sampled address into its
chain of generated C++ lines (inlined calls included).  Each generated line is shown with the
Python source comment Warp writes above it (``<L n>``).

Prints samples per kernel, then, for ``--module``, the lines with the most samples inclusive
(a call line counts what the call spends) and as the innermost line (the instruction's own),
and writes ``line_profile.csv`` (.json) under ``--out-dir``.  Needs ``perf`` (linux-perf) with
the cpu-clock event and binutils; says so and exits 2 where they are missing.  Sampling is
statistical: lines under about 1 % of the samples are noise.
"""

from __future__ import annotations

import argparse
import bisect
import collections
import json
import re
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))
from bench.common import RESULTS, machine_info, write_rows  # noqa: E402

ROOT = Path(__file__).resolve().parent.parent
CACHE = Path.home() / ".cache" / "warp_sim_line_profile"

CHILD = r"""
import json, sys
sys.path.insert(0, sys.argv[1])
import warp as wp
wp.config.quiet = True
wp.config.cpu_compiler_flags = wp.config.cpu_compiler_flags + " -debug-info-kind=line-tables-only -dwarf-version=4"
wp.config.kernel_cache_dir = sys.argv[2]
from warp._src import context
from warp_sim import cases
count, steps = int(sys.argv[3]), int(sys.argv[4])
if sys.argv[6] == "rain":
    sim = cases.terrain_drop(count, "mix", body_contact=True, broad_phase="grid", spacing=0.9, sleep=False,
                             rolling_resistance=0.2, contact_update="step", pair_schedule="domains")
else:  # spheres or boxes on the terrain alone, the fused step, as bench/terrain_drop.py times them
    sim = cases.terrain_drop(count, "sphere" if sys.argv[6] == "spheres" else "box", dt=1.0 / 240.0, substeps=1)
sim.step(steps, check=False)
entries = []
for module in list(context.user_modules.values()):
    for module_exec in getattr(module, "execs", {}).values():
        handle = getattr(module_exec, "handle", None)
        if not isinstance(handle, str):
            continue
        for kernel in module_exec.kernel_hooks:
            address = context.runtime.llvm.wp_lookup(handle.encode(), (kernel + "_cpu_forward").encode())
            entries.append({"module": module.name, "kernel": kernel, "address": address})
json.dump(entries, open(sys.argv[5], "w"))
"""


def missing_tools() -> list[str]:
    missing = [t for t in ("perf", "nm", "objdump", "addr2line") if shutil.which(t) is None]
    if "perf" not in missing:
        probe = subprocess.run(["perf", "record", "-e", "cpu-clock", "-o", "/dev/null", "--", "true"],
                               capture_output=True, text=True)
        if probe.returncode != 0:
            missing.append("perf record -e cpu-clock (" + (probe.stderr.strip().splitlines() or ["refused"])[-1] + ")")
    return missing


def module_layout(entry: dict, cache: Path):
    """(load address of .ltext, its size, object file, sorted (offset, name) symbols) of a module."""
    objects = sorted(cache.glob(f"*/wp_{entry['module']}_*/*.o"), key=lambda p: p.stat().st_mtime)
    if not objects:
        return None
    obj = objects[-1]
    symbols = []
    for line in subprocess.run(["nm", "--defined-only", str(obj)], capture_output=True, text=True).stdout.splitlines():
        parts = line.split()
        if len(parts) == 3 and parts[1] in "tTwW":
            symbols.append((int(parts[0], 16), parts[2]))
    symbols.sort()
    entry_name = entry["kernel"] + "_cpu_forward"
    offset = next((o for o, name in symbols if name == entry_name), None)
    sections = subprocess.run(["objdump", "-h", str(obj)], capture_output=True, text=True).stdout.splitlines()
    text = [line.split() for line in sections if ".ltext" in line or " .text " in line]
    text = [t for t in text if int(t[2], 16) > 0]
    if offset is None or not text:
        return None
    return entry["address"] - offset, int(text[0][2], 16), obj, text[0][1], symbols


def source_comment(cpp_lines: list[str], line: int) -> str:
    """The Python source comment Warp wrote nearest above a generated line."""
    for k in range(line - 1, max(line - 12, 0), -1):
        match = re.search(r"//\s*(.*?)\s*<L (\d+)>", cpp_lines[k - 1] if k - 1 < len(cpp_lines) else "")
        if match:
            return f"L{match.group(2)}: {match.group(1)[:70]}"
    return ""


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--count", type=int, default=10000)
    p.add_argument("--steps", type=int, default=130, help="steps simulated (the rain lands and piles)")
    p.add_argument("--module", default="solvers.domains", help="module whose lines are listed (a name's tail)")
    p.add_argument("--scene", default="rain", choices=["rain", "spheres", "boxes"],
                   help="rain: the 10k mixed rain with body contact; spheres, boxes: those on the terrain alone "
                        "(dt 1/240 s, the fused step, bench/terrain_drop.py's case)")
    p.add_argument("--top", type=int, default=30)
    p.add_argument("--frequency", type=int, default=499, help="samples a second")
    p.add_argument("--out-dir", type=Path, default=RESULTS)
    args = p.parse_args(argv)
    if args.count < 1 or args.steps < 1 or args.top < 1 or args.frequency < 1:
        p.error(f"--count, --steps, --top and --frequency must be >= 1, got {args.count}, {args.steps}, "
                f"{args.top}, {args.frequency}")
    import warp as wp

    wp.config.quiet = True
    missing = missing_tools()
    if missing:
        print("line_profile needs: " + ", ".join(missing), file=sys.stderr)
        return 2
    CACHE.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory() as tmp:
        data, entries_path = Path(tmp) / "perf.data", Path(tmp) / "entries.json"
        run = subprocess.run(["perf", "record", "-F", str(args.frequency), "-e", "cpu-clock", "-o", str(data), "--",
                              sys.executable, "-c", CHILD, str(ROOT), str(CACHE), str(args.count), str(args.steps),
                              str(entries_path), args.scene], capture_output=True, text=True)
        if run.returncode != 0 or not entries_path.exists():
            print("the profiled run failed: " + (run.stderr.strip().splitlines() or ["no output"])[-1], file=sys.stderr)
            return 1
        entries = json.loads(entries_path.read_text())
        script = subprocess.run(["perf", "script", "-i", str(data), "-F", "ip"], capture_output=True, text=True)
        samples = [int(s, 16) for s in script.stdout.split()]
    layouts = {}
    for entry in entries:
        if entry["module"] not in layouts:
            layouts[entry["module"]] = module_layout(entry, CACHE)
    per_symbol = collections.Counter()
    offsets = collections.defaultdict(collections.Counter)
    outside = 0
    for address in samples:
        for module, layout in layouts.items():
            if layout and layout[0] <= address < layout[0] + layout[1]:
                offset = address - layout[0]
                symbols = layout[4]
                k = bisect.bisect_right(symbols, (offset, "\uffff")) - 1
                per_symbol[(module, symbols[k][1] if k >= 0 else "?")] += 1
                offsets[module][offset] += 1
                break
        else:
            outside += 1
    total = len(samples)
    print(f"{total} samples, {outside} outside the kernels (Python, NumPy, the build, the scene set-up)")
    rows = []
    for (module, symbol), count in per_symbol.most_common(15):
        print(f"{count:7d} {100 * count / total:5.1f} %  {module}  {symbol[:80]}")
        rows.append({"kind": "function", "module": module, "where": symbol, "source": "", "samples": count,
                     "innermost": ""})
    chosen = [m for m in offsets if m.endswith(args.module)]
    for module in chosen:
        layout = layouts[module]
        counts = offsets[module]
        spots = sorted(counts)
        out = subprocess.run(["addr2line", "-a", "-i", "-e", str(layout[2]), "-j", layout[3]] + [hex(o) for o in spots],
                             capture_output=True, text=True).stdout.splitlines()
        chains, current = {}, None
        for line in out:
            if line.startswith("0x"):
                current = int(line, 16)
                chains[current] = []
            elif current is not None:
                chains[current].append(line.rsplit("/", 1)[-1].split(" ")[0])
        inclusive, innermost = collections.Counter(), collections.Counter()
        for offset, count in counts.items():
            chain = chains.get(offset) or ["?"]
            innermost[chain[0]] += count
            for where in set(chain):
                inclusive[where] += count
        cpp = sorted(layout[2].parent.glob("*.cpp"))
        cpp_lines = cpp[0].read_text().splitlines() if cpp else []
        module_total = sum(counts.values())
        print(f"\n{module}: {module_total} samples; generated lines by samples inclusive (innermost)")
        for where, count in inclusive.most_common(args.top):
            file_name, _, number = where.rpartition(":")
            comment = source_comment(cpp_lines, int(number)) if file_name.endswith(".cpp") and number.isdigit() else ""
            print(f"{count:7d} {100 * count / module_total:5.1f} % ({innermost[where]:6d})  {where:40s} {comment}")
            rows.append({"kind": "line", "module": module, "where": where, "source": comment, "samples": count,
                         "innermost": innermost[where]})
    write_rows("line_profile", rows, {**machine_info("cpu"), "count": args.count, "steps": args.steps,
                                      "samples": total, "outside": outside}, args.out_dir)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
