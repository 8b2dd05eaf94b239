"""Schemathesis against the live service's OpenAPI schema: no generated request may get a 5xx."""

from __future__ import annotations

import shutil
import subprocess
import sys
from pathlib import Path

import pytest


def test_openapi_fuzz_no_server_errors(service, tmp_path):
    import httpx

    created = httpx.post(f"{service.base_url}/v1/trips", json={"corridor": "paper_s200"}, timeout=10).json()
    # a real trip for the trip routes, so the fuzzer reaches the fix handling rather than only 404s
    (tmp_path / "schemathesis.toml").write_text(f'[parameters]\n"path.trip_id" = "{created["trip_id"]}"\n')
    exe = Path(sys.executable).with_name("schemathesis")
    if not exe.exists():
        exe = shutil.which("schemathesis")
    if exe is None:
        pytest.skip("schemathesis CLI not installed")
    cmd = [
        str(exe), "run", f"{service.base_url}/openapi.json",
        "--checks", "not_a_server_error",
        "--phases", "examples,fuzzing",  # the coverage phase trips a CPython 3.11 AST bug inside hypothesis
        "-H", f"Authorization: Bearer {created['token']}",
        "--max-examples", "20",
        "--workers", "2",
        "--exclude-path", "/v1/trips/{trip_id}/advice.wav",  # speech rendering is covered elsewhere; slow to fuzz
        "--exclude-path", "/v1/trips/{trip_id}/end",  # would end the shared trip; covered in test_live
        "--seed", "1",
        "--no-color",
    ]  # fmt: skip
    r = subprocess.run(cmd, capture_output=True, text=True, timeout=120, cwd=tmp_path)
    print(r.stdout[-3000:])
    assert r.returncode == 0, r.stdout[-6000:] + r.stderr[-2000:]
