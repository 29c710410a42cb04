"""Run a command as on another CPU: numpy without its SIMD dispatch, OpenBLAS on another kernel.

``python tools/other_cpu.py COMMAND [ARG ...]`` asks a fresh Python which SIMD groups numpy
dispatches to on this CPU (``numpy.show_runtime()``'s "found") and which kernel OpenBLAS picked,
in numpy's and in scipy's copy of it. It then sets ``NPY_DISABLE_CPU_FEATURES`` to every group
found (numpy runs its baseline code: X86_V2 on x86-64 instead of X86_V3 or X86_V4) and
``OPENBLAS_CORETYPE`` to another kernel (Sandybridge on x86-64, ARMV8 on arm64, Nehalem where
Sandybridge is this CPU's own), asks again, prints both, and runs the command in that
environment only if numpy's groups and both OpenBLAS kernels changed; otherwise it exits 1.
The record tests (docs/results.md, "Reproducibility") must pass in both configurations.
"""

from __future__ import annotations

import json
import os
import platform
import subprocess
import sys

VARIABLES = ("NPY_DISABLE_CPU_FEATURES", "NPY_ENABLE_CPU_FEATURES", "OPENBLAS_CORETYPE")

PROBE = r"""
import ctypes, glob, json, os
import numpy, scipy, scipy.linalg
from numpy._core._multiarray_umath import __cpu_dispatch__, __cpu_features__

def core(package, pattern, symbol):
    libs = os.path.join(os.path.dirname(os.path.dirname(package.__file__)),
                        package.__name__ + ".libs")
    found = sorted(glob.glob(os.path.join(libs, pattern)))
    if not found:
        return None
    get = getattr(ctypes.CDLL(found[0]), symbol)
    get.restype = ctypes.c_char_p
    return get().decode()

# the lists numpy.show_runtime() prints as "simd_extensions": "found"
found = [f for f in __cpu_dispatch__ if __cpu_features__.get(f)]
print(json.dumps({
    "found": found,
    "numpy_openblas": core(numpy, "libscipy_openblas64_*.so", "scipy_openblas_get_corename64_"),
    "scipy_openblas": core(scipy, "libscipy_openblas*.so", "scipy_openblas_get_corename"),
}))
"""


def probe(env: dict[str, str]) -> dict:
    """numpy's dispatched SIMD groups and the OpenBLAS kernels, as a fresh Python sees them."""
    done = subprocess.run(
        [sys.executable, "-c", PROBE], env=env, capture_output=True, text=True, check=False
    )
    if done.returncode != 0:
        sys.exit(f"other_cpu: probing numpy and OpenBLAS failed:\n{done.stderr.strip()}")
    return json.loads(done.stdout.strip().splitlines()[-1])


def other_coretype(current: str | None) -> str:
    machine = platform.machine().lower()
    if machine in ("aarch64", "arm64"):
        return "ARMV8"
    return "Nehalem" if current == "Sandybridge" else "Sandybridge"


def main(argv: list[str]) -> int:
    if not argv:
        print("usage: python tools/other_cpu.py COMMAND [ARG ...]", file=sys.stderr)
        return 2
    base = {k: v for k, v in os.environ.items() if k not in VARIABLES}
    before = probe(base)
    other = dict(base)
    if before["found"]:
        other["NPY_DISABLE_CPU_FEATURES"] = " ".join(before["found"])
    other["OPENBLAS_CORETYPE"] = other_coretype(before["numpy_openblas"])
    after = probe(other)
    print(f"this CPU:      numpy SIMD found {before['found']}, OpenBLAS kernels "
          f"{before['numpy_openblas']} (numpy), {before['scipy_openblas']} (scipy)")  # fmt: skip
    print(f"other config:  NPY_DISABLE_CPU_FEATURES={other.get('NPY_DISABLE_CPU_FEATURES', '')!r} "
          f"OPENBLAS_CORETYPE={other['OPENBLAS_CORETYPE']}")  # fmt: skip
    print(f"               numpy SIMD found {after['found']}, OpenBLAS kernels "
          f"{after['numpy_openblas']} (numpy), {after['scipy_openblas']} (scipy)")  # fmt: skip
    unchanged = []
    if not before["found"] or set(after["found"]) & set(before["found"]):
        unchanged.append("numpy's SIMD dispatch")
    for lib in ("numpy_openblas", "scipy_openblas"):
        if before[lib] is None or after[lib] == before[lib]:
            unchanged.append(f"{lib.split('_')[0]}'s OpenBLAS kernel")
    if unchanged:
        print(f"other_cpu: not another configuration: {', '.join(unchanged)} did not change",
              file=sys.stderr)  # fmt: skip
        return 1
    sys.stdout.flush()
    return subprocess.run(argv, env=other, check=False).returncode


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
