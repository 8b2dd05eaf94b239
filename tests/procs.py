"""Real server processes for tests: start on a free loopback port, wait for /health (bounded), kill."""

from __future__ import annotations

import os
import random
import socket
import ssl
import subprocess
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path

import httpx

REPO = Path(__file__).resolve().parents[1]
START_TIMEOUT_S = 120.0  # generous: only there so a broken start cannot hang the suite


_HANDED: set[int] = set()


def _ephemeral_low() -> int:
    """The first port the kernel hands to outgoing connections (Linux ``ip_local_port_range``; 32768 elsewhere)."""
    try:
        return int(Path("/proc/sys/net/ipv4/ip_local_port_range").read_text().split()[0])
    except (OSError, ValueError, IndexError):
        return 32768


def free_port() -> int:
    """A loopback port free now and outside the kernel's range for outgoing connections: a port from that range (what
    binding port 0 gives) may be taken by any client socket of the suite before the server binds it, or while a
    killed server is restarted on it (seen as "address already in use" on a loaded machine, issue 29). Never the same
    port twice in one run; under ``pytest -n N`` (``make test``) each worker draws from its own slice of the range, so
    two workers never pick the same port between the check and the server's bind."""
    low = max(_ephemeral_low(), 10_001)
    workers = int(os.environ.get("PYTEST_XDIST_WORKER_COUNT", "1"))
    worker = int(os.environ.get("PYTEST_XDIST_WORKER", "gw0")[2:] or 0)
    width = (low - 10_000) // workers
    rng = random.Random()
    for _ in range(200):
        port = rng.randrange(10_000 + worker * width, 10_000 + (worker + 1) * width)
        if port in _HANDED:
            continue
        with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
            try:
                s.bind(("127.0.0.1", port))
            except OSError:
                continue
        _HANDED.add(port)
        return port
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:  # (no free port below the range: the kernel's pick)
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


@dataclass
class Proc:
    """A ``python <args> --port N`` subprocess serving HTTP on 127.0.0.1:N."""

    args: list[str]
    log_path: Path
    env: dict[str, str] = field(default_factory=dict)
    port: int = field(default_factory=free_port)
    proc: subprocess.Popen | None = None
    scheme: str = "http"
    verify: ssl.SSLContext | bool = True  # https: trust this context (e.g. a self-signed certificate's)

    @property
    def base_url(self) -> str:
        return f"{self.scheme}://127.0.0.1:{self.port}"

    def start(self) -> Proc:
        # TMPDIR beside the log: what the process leaves in its temporary folder when killed stays in pytest's tmp dirs.
        # A service's loop-lag shedding off unless a test sets it: on a loaded test machine a worker's loop runs late
        # (seen: a browser test's service refused its trip, "its queue is 279 ms long", with other jobs on 2 cores),
        # and only tests/server/test_overload.py tests shedding (on a Shedder of its own)
        env = {**os.environ, "PYTHONUNBUFFERED": "1", "TMPDIR": str(self.log_path.parent), "ECO_MAX_LOOP_LAG_S": "3600", **self.env}
        log = self.log_path.open("ab")
        self.proc = subprocess.Popen([sys.executable, *self.args, "--port", str(self.port)], cwd=REPO, env=env, stdout=log, stderr=subprocess.STDOUT)
        log.close()
        deadline = time.monotonic() + START_TIMEOUT_S
        while time.monotonic() < deadline:
            if self.proc.poll() is not None:
                raise RuntimeError(f"{self.args} exited with {self.proc.returncode}:\n{self.log_path.read_text()}")
            try:
                if httpx.get(self.base_url + "/health", timeout=1.0, verify=self.verify).status_code == 200:
                    return self
            except httpx.HTTPError:
                pass
            time.sleep(0.05)
        self.kill()
        raise RuntimeError(f"{self.args} did not answer /health within {START_TIMEOUT_S} s:\n{self.log_path.read_text()}")

    def kill(self) -> None:
        """SIGKILL: the process dies without closing its sockets politely."""
        if self.proc is not None and self.proc.poll() is None:
            self.proc.kill()
            self.proc.wait(timeout=10)
        self.proc = None


def redis_server_path() -> str | None:
    """``redis-server``, installed by ``scripts/system-deps.sh`` (apt-get, as root) when missing; None if it cannot be."""
    import shutil

    if shutil.which("redis-server") is None:
        subprocess.run(["sh", str(REPO / "scripts" / "system-deps.sh")], capture_output=True, timeout=900)
    return shutil.which("redis-server")


@dataclass
class RedisServer:
    """A real ``redis-server`` on a free loopback port with its files in ``folder`` (append-only file on, fsync per
    write by default: a killed and restarted server keeps what it acknowledged; ``everysec`` as deployed)."""

    folder: Path
    port: int = field(default_factory=free_port)
    fsync: str = "always"
    proc: subprocess.Popen | None = None
    unix_socket: bool = False
    """Also listen on ``folder/redis.sock`` (:attr:`unix_url`; the folder's path must be short: at most ~100 bytes)."""

    @property
    def url(self) -> str:
        return f"redis://127.0.0.1:{self.port}/0"

    @property
    def unix_url(self) -> str:
        return f"unix://{self.folder / 'redis.sock'}?db=0"

    def start(self) -> RedisServer:
        exe = redis_server_path()
        if exe is None:
            raise FileNotFoundError("redis-server")
        args = [exe, "--port", str(self.port), "--bind", "127.0.0.1", "--dir", str(self.folder), "--save", "", "--appendonly", "yes",
                "--appendfsync", self.fsync, "--logfile", str(self.folder / "redis.log")]  # fmt: skip
        if self.unix_socket:
            args += ["--unixsocket", str(self.folder / "redis.sock"), "--unixsocketperm", "700"]
        self.proc = subprocess.Popen(args, cwd=self.folder, stdout=subprocess.DEVNULL, stderr=subprocess.STDOUT)
        import redis

        deadline = time.monotonic() + START_TIMEOUT_S
        while time.monotonic() < deadline:
            if self.proc.poll() is not None:
                raise RuntimeError(f"redis-server exited with {self.proc.returncode}: {(self.folder / 'redis.log').read_text()}")
            try:
                with redis.Redis(port=self.port, socket_timeout=1) as r:
                    if r.ping():
                        return self
            except (redis.ConnectionError, redis.TimeoutError, redis.BusyLoadingError):
                time.sleep(0.02)
        self.kill()
        raise RuntimeError("redis-server did not answer PING")

    def kill(self) -> None:
        if self.proc is not None and self.proc.poll() is None:
            self.proc.kill()
            self.proc.wait(timeout=10)
        self.proc = None
