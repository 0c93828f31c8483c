"""Where the benchmarks put what they measured: ``results/<stem>.json`` (the numbers) and
``results/<stem>.md`` (the report), each written atomically."""

from __future__ import annotations

import json
import os
import platform
import sys

sys.path.insert(0, os.path.join(os.path.dirname(__file__), ".."))

from skyref.io.atomic import atomic_write  # noqa: E402
from skyref.io.json_numpy import numpy_default  # noqa: E402

RESULTS = os.path.join(os.path.dirname(__file__), "..", "results")


def machine() -> str:
    """The machine a benchmark ran on, for its report: architecture, CPU model (Linux's
    /proc/cpuinfo: on 2026-12-06 the test suite took 37 min on a 2-core AMD EPYC machine and 11
    on a 2-core Intel Xeon one) and core count, e.g. "x86_64, Intel(R) Xeon(R) Processor, 2 cores"."""
    model = platform.processor()
    try:
        with open("/proc/cpuinfo") as f:
            model = next((line.split(":", 1)[1].strip() for line in f if line.startswith("model name")), model)
    except OSError:
        pass
    return ", ".join(part for part in (platform.machine(), model, f"{os.cpu_count()} cores") if part)


def write_results(stem: str, report: dict, markdown: str) -> str:
    """Write ``report`` as ``results/<stem>.json`` and ``markdown`` as ``results/<stem>.md``;
    returns the markdown's path."""
    os.makedirs(RESULTS, exist_ok=True)
    with atomic_write(os.path.join(RESULTS, f"{stem}.json")) as f:
        json.dump(report, f, indent=1, default=numpy_default)
    path = os.path.join(RESULTS, f"{stem}.md")
    with atomic_write(path) as f:
        f.write(markdown)
    return path
