"""Helpers shared by the benchmarks: timing, and for those that run real server processes, Linux /proc readings."""

from __future__ import annotations

import os
import socket
import time
from pathlib import Path


def best_of(fn, repeats: int = 3) -> float:
    """The shortest of ``repeats`` timed calls of ``fn()``. [s]"""
    best = float("inf")
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        best = min(best, time.perf_counter() - t0)
    return best


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def cpu_seconds(pid: int) -> float:
    """User + system CPU time of a process, from /proc (Linux). [s]"""
    fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def counters(pid: int) -> dict[str, float]:
    """What a process has done so far, from /proc (Linux): ``user_s`` and ``system_s`` of CPU, context switches
    ``voluntary`` (it slept: waited for I/O) and ``involuntary`` (preempted), system calls ``reads`` and ``writes``
    (``read``/``recv`` and ``write``/``send`` families: /proc/<pid>/io ``syscr``, ``syscw``)."""
    fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    hz = os.sysconf("SC_CLK_TCK")
    out = {"user_s": int(fields[11]) / hz, "system_s": int(fields[12]) / hz}
    names = {"voluntary_ctxt_switches": "voluntary", "nonvoluntary_ctxt_switches": "involuntary", "syscr": "reads", "syscw": "writes"}
    for line in Path(f"/proc/{pid}/status").read_text().splitlines() + Path(f"/proc/{pid}/io").read_text().splitlines():
        name, _, value = line.partition(":")
        if name in names:
            out[names[name]] = float(value)
    return out


def tree_counters(pid: int) -> dict[str, float]:
    """:func:`counters` summed over a process and its children (uvicorn's supervisor and its workers); a child gone
    meanwhile counts nothing."""
    total = counters(pid)
    for task in Path(f"/proc/{pid}/task").iterdir():
        for child in (task / "children").read_text().split():
            try:
                for name, value in counters(int(child)).items():
                    total[name] += value
            except OSError:
                pass
    return total


def rss_mib(pid: int) -> float:
    """Resident memory of a process, from /proc (Linux). [MiB]"""
    for line in Path(f"/proc/{pid}/status").read_text().splitlines():
        if line.startswith("VmRSS:"):
            return int(line.split()[1]) / 1024
    return float("nan")


def machine_cpu_s() -> dict[str, float]:
    """CPU seconds of the whole machine since boot, summed over its CPUs (Linux /proc/stat): ``busy`` (user,
    nice, system, irq, softirq), ``idle`` (idle, iowait) and ``steal`` (taken by the hypervisor for other guests)."""
    ticks = [int(x) for x in Path("/proc/stat").read_text().split("\n", 1)[0].split()[1:9]]
    hz = os.sysconf("SC_CLK_TCK")
    user, nice, system, idle, iowait, irq, softirq, steal = ticks
    return {"busy": (user + nice + system + irq + softirq) / hz, "idle": (idle + iowait) / hz, "steal": steal / hz}


def wait_healthy(proc, port: int, log_path: Path, limit_s: float = 120.0) -> None:
    """Wait until the service ``proc`` started answers ``GET /health`` on ``port`` with 200; RuntimeError with its
    log (``log_path``) if it exits or does not within ``limit_s``."""
    import httpx

    deadline = time.monotonic() + limit_s
    while True:
        if proc.poll() is not None or time.monotonic() > deadline:
            raise RuntimeError(log_path.read_text())
        try:
            if httpx.get(f"http://127.0.0.1:{port}/health", timeout=1).status_code == 200:
                return
        except httpx.HTTPError:
            time.sleep(0.1)
