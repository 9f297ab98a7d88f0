"""analysis/blas.py: one OpenBLAS kernel on every x86-64 machine (answers independent of the CPU)."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

from analysis.blas import KERNEL, _has_avx2, kernels, pin_kernel

ROOT = Path(__file__).resolve().parents[2]
X86_AVX2 = os.uname().machine in ("x86_64", "AMD64") and _has_avx2()


@pytest.mark.skipif(not X86_AVX2, reason="the kernel is pinned on x86-64 CPUs with AVX2 only")
def test_this_test_run_uses_the_pinned_kernel() -> None:
    """The suite itself (pytest imports the project before numpy through -p plan_fixtures)."""
    assert os.environ.get("OPENBLAS_CORETYPE") == KERNEL
    found = kernels()
    assert found and set(found.values()) == {KERNEL}, found


@pytest.mark.skipif(not X86_AVX2, reason="the kernel is pinned on x86-64 CPUs with AVX2 only")
@pytest.mark.parametrize("package", ["analysis", "planner", "sim", "api", "ctp"])
def test_importing_any_package_first_pins_the_kernel(package: str) -> None:
    env = {k: v for k, v in os.environ.items() if k != "OPENBLAS_CORETYPE"}
    code = (f"import {package}, numpy, scipy.linalg; from analysis.blas import kernels; "
            "print(sorted(set(kernels().values())))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env, cwd=ROOT, timeout=120)
    assert out.returncode == 0, out.stderr[-400:]
    assert out.stdout.strip() == f"['{KERNEL}']"


def test_a_users_choice_and_a_late_call_are_left_alone(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("OPENBLAS_CORETYPE", "Zen")
    assert pin_kernel() is False and os.environ["OPENBLAS_CORETYPE"] == "Zen"
    monkeypatch.delenv("OPENBLAS_CORETYPE")
    assert "numpy" in sys.modules  # loaded already: too late to choose, so nothing is set
    assert pin_kernel() is False and "OPENBLAS_CORETYPE" not in os.environ
