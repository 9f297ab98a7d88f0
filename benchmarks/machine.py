"""The machine a benchmark ran on (printed next to every figure); importing it pins the BLAS kernel."""

from __future__ import annotations

import os
import platform
import sys
from pathlib import Path

# the project's package before numpy loads (every benchmark imports this module first): one BLAS
# kernel on every x86-64 machine, as the command line and the service use (analysis/blas.py)
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from analysis.blas import kernels, pin_kernel

pin_kernel()


def machine() -> str:
    """CPU model, core count, OS, Python version and the OpenBLAS kernels in use (analysis/blas.py)."""
    cpu = platform.processor() or platform.machine()
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                cpu = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    blas = "/".join(sorted(set(kernels().values()))) or "none found"
    return (f"{cpu}, {os.cpu_count()} cores, {platform.system()} {platform.release()}, "
            f"Python {platform.python_version()}, OpenBLAS {blas}")
