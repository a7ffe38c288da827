"""Where a result came from: scene text, resolved settings, versions, device and machine.

Every run file's ``metadata`` (recording.load_run(path)["metadata"]) is this dict, so a result
can be traced to the exact inputs and software that made it.
"""

from __future__ import annotations

import os
import platform
import sys
from dataclasses import asdict
from importlib import metadata as importlib_metadata


def package_version() -> str:
    try:
        return importlib_metadata.version("warp_sim")
    except importlib_metadata.PackageNotFoundError:
        return "unknown"


def cpu_name() -> str:
    """The CPU model from /proc/cpuinfo (Linux), else what platform reports."""
    try:
        with open("/proc/cpuinfo", encoding="utf-8", errors="replace") as f:
            for line in f:
                if line.lower().startswith("model name"):
                    return line.partition(":")[2].strip()
    except OSError:
        pass
    return platform.processor() or platform.machine()


def machine() -> dict:
    return {"platform": platform.platform(), "python": sys.version.split()[0], "cpu": cpu_name(),
            "cpu_count": os.cpu_count(), "hostname": platform.node()}


def provenance(scene_text: str | None, config, device: str, extra: dict | None = None) -> dict:
    """JSON-ready provenance of a run of ``config`` (a SimConfig) on ``device``."""
    import warp as wp

    settings = asdict(config)
    settings["device"] = str(device)
    info = {
        "scene_text": scene_text,
        "settings": settings,
        "seed": int(config.seed),
        "warp_sim_version": package_version(),
        "warp_version": getattr(wp, "__version__", "unknown"),
        "numpy_version": __import__("numpy").__version__,
        "device": str(device),
        "machine": machine(),
        "threads": os.environ.get("WARP_SIM_CPU_THREADS") or str(os.cpu_count()),
        "argv": list(sys.argv),
    }
    if extra:
        info.update(extra)
    return info
