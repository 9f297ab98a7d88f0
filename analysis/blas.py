"""One BLAS kernel on every x86-64 machine, so that answers do not depend on the CPU.

numpy's and scipy's OpenBLAS pick their kernels at load time from the CPU (``DYNAMIC_ARCH``): on an
AVX-512 machine (e.g. AMD Zen 4) the ``SkylakeX`` kernels, on others ``Haswell`` or ``Zen``. The
kernels round differently in the last bits, and where a result is not unique, the basis of a null
space of dimension > 1 (:func:`analysis.linalg.null_space`), the first of several equal members,
the cheaper of two plans of nearly equal cost, those bits choose it. On an AVX-512 machine the
palm's FFFFF row printed the example direction ``-e_6`` where the machines before printed ``+e_6``,
and the nine-contact wrap planned a different lift (its replay 7.3 % off the plan, not within 5 %).

:func:`pin_kernel` sets ``OPENBLAS_CORETYPE`` to :data:`KERNEL` (AVX2, every x86-64 CPU since 2013)
unless the user set it; it must run before numpy is first imported, so every package of the
project (``analysis``, ``planner``, ``sim``, ``api``, ``ctp``) calls it first (and ``benchmarks/machine.py``
for the benchmarks); child processes (the enumeration's workers, Ray's) inherit the variable.
:func:`kernels` says which kernels the loaded libraries use.
"""

from __future__ import annotations

import ctypes
import glob
import os
import platform
import sys
from pathlib import Path

#: The OpenBLAS kernel used on x86-64 machines with AVX2.
KERNEL = "Haswell"


def _has_avx2() -> bool:
    """Whether the CPU has AVX2 (Linux: /proc/cpuinfo; elsewhere assumed, as on any x86-64 CPU since 2013)."""
    try:
        with open("/proc/cpuinfo", encoding="utf-8", errors="replace") as f:
            for line in f:
                if line.startswith("flags"):
                    return "avx2" in line.split()
    except OSError:
        return True
    return False


def pin_kernel() -> bool:
    """Set ``OPENBLAS_CORETYPE`` to :data:`KERNEL` (x86-64 with AVX2, the variable not set yet).

    Returns whether the loaded numpy will use it: False when numpy was imported before this call (its
    OpenBLAS has chosen already), on other CPUs, or when the user chose another kernel."""
    if platform.machine().lower() not in ("x86_64", "amd64") or not _has_avx2():
        return False
    if "OPENBLAS_CORETYPE" not in os.environ and "numpy" not in sys.modules:
        os.environ["OPENBLAS_CORETYPE"] = KERNEL
    return os.environ.get("OPENBLAS_CORETYPE") == KERNEL


def kernels() -> dict[str, str]:
    """The kernel of each OpenBLAS library numpy and scipy ship (file name -> core name, e.g.
    ``"Haswell"``), loaded as they load them (the same process shares one copy)."""
    import numpy  # the libraries sit next to numpy's and scipy's packages

    site = Path(numpy.__file__).resolve().parents[1]
    out: dict[str, str] = {}
    for lib in sorted(glob.glob(str(site / "*.libs" / "*openblas*"))):
        handle = ctypes.CDLL(lib)
        for name in ("scipy_openblas_get_corename64_", "scipy_openblas_get_corename", "openblas_get_corename"):
            fn = getattr(handle, name, None)
            if fn is not None:
                fn.restype = ctypes.c_char_p
                out[Path(lib).name] = fn().decode()
                break
    return out


__all__ = ["KERNEL", "kernels", "pin_kernel"]
