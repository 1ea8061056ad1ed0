"""The numeric environment of a flight, recorded in its setup record.

Float64 results of the same code differ in their last bits between machines
and library builds: fused multiply-add or not, SIMD reduction order, the
BLAS/LAPACK kernel OpenBLAS picks for the CPU (``architecture``), numpy's
own SIMD dispatch. Bit-for-bit replay of a recorded flight is therefore only
promised where the replaying environment is the recording's
(``docs/replay.md``, "Comparison"). ``fingerprint()`` says what that
environment is: CPU vendor, model and the floating-point relevant flags,
platform and C library, Python, numpy and scipy with their BLAS builds and
the kernels chosen at run time. It reads ``/proc/cpuinfo`` and the loaded
libraries (an edge function: the CLI calls it, the cores receive its dict).

``differences(recorded, current)`` names the keys that differ; a recording
without a fingerprint (made before it existed) is an unknown environment.
"""

from __future__ import annotations

import copy
import platform
import sys
from functools import lru_cache

#: CPU flags that change floating-point results (FMA contraction, vector widths of reductions).
FP_FLAGS = ("sse4_2", "avx", "avx2", "fma", "fma4", "avx512f", "avx512dq", "avx512vl", "avx512bw",
            "avx512_fp16", "amx_tile", "asimd", "sve")
#: Format of the fingerprint (a key of the setup record, ``environment``).
FINGERPRINT_FORMAT = "env/1"


def _cpu() -> dict:
    vendor = model = None
    flags: set = set()
    try:
        with open("/proc/cpuinfo", encoding="ascii", errors="replace") as f:
            for line in f:
                key, _, value = line.partition(":")
                key, value = key.strip(), value.strip()
                if key == "vendor_id" and vendor is None:
                    vendor = value
                elif key in ("model name", "Model") and model is None:
                    model = value
                elif key in ("flags", "Features") and not flags:
                    flags = set(value.split())
                elif not line.strip() and vendor is not None:
                    break                   # the first processor is enough
    except OSError:
        pass
    return {"vendor": vendor or platform.processor() or None, "model": model,
            "flags": [f for f in FP_FLAGS if f in flags]}


def _blas(config: dict) -> dict:
    b = (config.get("Build Dependencies") or {}).get("blas") or {}
    return {"name": b.get("name"), "version": b.get("version"), "config": b.get("openblas configuration")}


def _libraries() -> dict:
    import numpy
    import scipy
    import scipy.linalg  # noqa: F401  (loads scipy's BLAS, so that threadpoolctl sees it)
    from threadpoolctl import threadpool_info

    try:
        np_cfg = numpy.show_config(mode="dicts")
        sp_cfg = scipy.show_config(mode="dicts")
    except (TypeError, ValueError, AttributeError):     # an older build without mode="dicts"
        np_cfg, sp_cfg = {}, {}
    simd = np_cfg.get("SIMD Extensions") or {}
    kernels = sorted({f"{i.get('internal_api')} {i.get('version')} {i.get('architecture')}"
                      for i in threadpool_info() if i.get("user_api") == "blas"})
    return {"numpy": numpy.__version__, "numpy_blas": _blas(np_cfg), "numpy_simd": list(simd.get("found") or []),
            "scipy": scipy.__version__, "scipy_blas": _blas(sp_cfg), "blas_kernels": kernels}


def fingerprint() -> dict:
    """The environment of this process (JSON-ready dict, a few hundred bytes).

    Keys: ``format``, ``cpu`` {vendor, model, flags}, ``platform`` (OS and
    machine), ``libc``, ``python`` (implementation and version), ``numpy``,
    ``numpy_blas``, ``numpy_simd`` (the SIMD targets numpy dispatches to
    here), ``scipy``, ``scipy_blas``, ``blas_kernels`` (the loaded BLAS
    libraries and the CPU kernel each picked at run time).
    """
    return copy.deepcopy(_fingerprint())


@lru_cache(maxsize=1)
def _fingerprint() -> dict:
    libc = platform.libc_ver()
    return {"format": FINGERPRINT_FORMAT, "cpu": _cpu(), "platform": f"{platform.system()} {platform.machine()}",
            "libc": " ".join(x for x in libc if x) or None,
            "python": f"{platform.python_implementation()} {'.'.join(map(str, sys.version_info[:3]))}",
            **_libraries()}


def differences(recorded: dict | None, current: dict) -> list[str]:
    """The keys (``cpu.model``, ``numpy``, ...) in which two fingerprints differ; ``["unknown"]``
    when the recording has none (then nothing promises bit-for-bit equality)."""
    if not isinstance(recorded, dict):
        return ["unknown"]
    out = []
    for key in sorted(set(recorded) | set(current)):
        a, b = recorded.get(key), current.get(key)
        if isinstance(a, dict) and isinstance(b, dict):
            out += [f"{key}.{k}" for k in sorted(set(a) | set(b)) if a.get(k) != b.get(k)]
        elif a != b:
            out.append(key)
    return out
