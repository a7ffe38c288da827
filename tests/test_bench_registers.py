"""bench/registers.py reads registers and local frames from real sm_90 cubins (NVRTC, no GPU)."""

import ast
from pathlib import Path

import pytest

from bench.registers import compile_module, elf_sections, kernel_modules

ROOT = Path(__file__).resolve().parent.parent


def test_every_kernel_module_is_found():
    names = kernel_modules()
    assert "warp_sim.sleep" in names and "warp_sim.collide.narrow_phase" in names


def test_a_module_compiles_to_a_cubin_whose_kernels_all_report_registers(tmp_path):
    name, rows, note = compile_module("warp_sim.sleep", str(tmp_path))
    assert rows, note
    tree = ast.parse((ROOT / "warp_sim" / "sleep.py").read_text())
    kernels = {n.name for n in ast.walk(tree) if isinstance(n, ast.FunctionDef)
               and any("wp.kernel" in ast.unparse(d) for d in n.decorator_list)}
    # enable_backward is off in the module: forward kernels only, each with its registers
    assert {r["kernel"] for r in rows} == kernels
    assert all(0 < r["registers"] <= 255 and 0 < r["register_occupancy"] <= 1 for r in rows)
    assert all(r["param_bytes"] > 0 and r["frame_bytes"] >= 0 for r in rows)


def test_the_elf_reader_refuses_what_is_not_a_cubin():
    with pytest.raises(ValueError, match="ELF"):
        elf_sections(b"\x7fELF\x01\x01" + bytes(64))
