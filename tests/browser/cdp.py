"""A small Chrome DevTools Protocol client (over ``websockets``) and a headless chromium launcher.

Enough to drive the phone app as a user would: a fresh browser context per page, real mouse clicks
(``Input.dispatchMouseEvent``, so the page gets a user gesture), emulated geolocation, locale, colour
scheme and viewport, script injection before the page's own, network events (WebSocket frames included)
and screenshots. Every wait is bounded; nothing measures speed.
"""

from __future__ import annotations

import asyncio
import base64
import contextlib
import itertools
import json
import os
import shutil
import signal
import subprocess
import tempfile
import time
from pathlib import Path
from typing import Any

from websockets.asyncio.client import connect

CHROMIUM_FLAGS = (
    "--headless",
    "--disable-gpu",
    "--disable-quic",
    "--no-first-run",
    "--no-default-browser-check",
    "--disable-background-networking",
    "--disable-component-update",
    "--disable-sync",
    "--disable-extensions",
    "--disable-dev-shm-usage",
    "--mute-audio",
)
"""Headless, and quiet: on a closed network the background services would flood refused connections."""

START_TIMEOUT_S = 60.0
CALL_TIMEOUT_S = 30.0


def find_chromium() -> str | None:
    """Debian's ``chromium`` (``scripts/system-deps.sh`` installs it), or None."""
    for name in ("chromium", "chromium-browser"):
        if path := shutil.which(name):
            return path
    return None


class CdpError(RuntimeError):
    pass


class Browser:
    """A headless chromium process with a fresh profile, and one DevTools connection to it."""

    def __init__(self, proc: subprocess.Popen, ws, log_path: Path) -> None:
        self.proc = proc
        self.ws = ws
        self.log_path = log_path
        self._ids = itertools.count(1)
        self._calls: dict[int, asyncio.Future] = {}
        self.pages: dict[str, Page] = {}
        self._reader = asyncio.create_task(self._read())

    @classmethod
    async def launch(cls, executable: str, profile_dir: Path, log_path: Path) -> Browser:
        profile_dir.mkdir(parents=True, exist_ok=True)
        args = [executable, *CHROMIUM_FLAGS, f"--user-data-dir={profile_dir}", "--remote-debugging-port=0", "about:blank"]
        if os.geteuid() == 0:
            args.insert(1, "--no-sandbox")  # chromium refuses to run as root with its sandbox
        port_file = profile_dir / "DevToolsActivePort"
        port_file.unlink(missing_ok=True)  # a reused profile's is stale
        with log_path.open("ab") as log:
            proc = subprocess.Popen(args, stdout=log, stderr=subprocess.STDOUT, stdin=subprocess.DEVNULL, start_new_session=True)
        deadline = time.monotonic() + START_TIMEOUT_S
        while True:
            lines = port_file.read_text().split() if port_file.exists() else []
            if len(lines) >= 2:
                break
            if proc.poll() is not None or time.monotonic() > deadline:
                _kill(proc)
                raise CdpError(f"chromium did not open its DevTools port (exit {proc.returncode}):\n{log_path.read_text()[-3000:]}")
            await asyncio.sleep(0.05)
        try:
            ws = await connect(f"ws://127.0.0.1:{lines[0]}{lines[1]}", max_size=None, ping_interval=None, open_timeout=CALL_TIMEOUT_S)
        except BaseException:
            _kill(proc)
            raise
        return cls(proc, ws, log_path)

    async def _read(self) -> None:
        async for raw in self.ws:
            message = json.loads(raw)
            if "id" in message:
                future = self._calls.pop(message["id"], None)
                if future is not None and not future.done():
                    future.set_result(message)
            elif (page := self.pages.get(message.get("sessionId", ""))) is not None:
                page.events.append((message["method"], message.get("params", {})))

    async def send(self, method: str, params: dict | None = None, session_id: str | None = None) -> dict:
        call_id = next(self._ids)
        message: dict[str, Any] = {"id": call_id, "method": method, "params": params or {}}
        if session_id is not None:
            message["sessionId"] = session_id
        future = asyncio.get_running_loop().create_future()
        self._calls[call_id] = future
        await self.ws.send(json.dumps(message))
        reply = await asyncio.wait_for(future, CALL_TIMEOUT_S)
        if "error" in reply:
            raise CdpError(f"{method}: {reply['error']}")
        return reply.get("result", {})

    async def new_page(self) -> Page:
        """A tab in its own browser context (fresh storage and permissions)."""
        context = (await self.send("Target.createBrowserContext", {"disposeOnDetach": True}))["browserContextId"]
        target = (await self.send("Target.createTarget", {"url": "about:blank", "browserContextId": context}))["targetId"]
        session = (await self.send("Target.attachToTarget", {"targetId": target, "flatten": True}))["sessionId"]
        page = Page(self, session, context)
        self.pages[session] = page
        for domain in ("Page", "Runtime", "Network"):
            await page.send(f"{domain}.enable")
        return page

    async def close(self) -> None:
        with contextlib.suppress(Exception):
            await asyncio.wait_for(self.ws.close(), 5)
        self._reader.cancel()
        with contextlib.suppress(asyncio.CancelledError, Exception):
            await self._reader
        _kill(self.proc)


def _kill(proc: subprocess.Popen) -> None:
    """Chromium and all its helper processes (its own session: the group has its pid), and the singleton
    folder it keeps in /tmp (``org.chromium.Chromium.*``, which a killed chromium cannot remove; the socket
    path inside it must stay short, so it cannot live under pytest's tmp dirs)."""
    with contextlib.suppress(ProcessLookupError):
        os.killpg(proc.pid, signal.SIGKILL)
    with contextlib.suppress(subprocess.TimeoutExpired):
        proc.wait(timeout=10)
    profile = Path(next(a for a in proc.args if a.startswith("--user-data-dir=")).removeprefix("--user-data-dir="))
    for link in ("SingletonSocket", "SingletonLock"):
        with contextlib.suppress(OSError):
            target = Path(os.readlink(profile / link)).parent
            if target.name.startswith("org.chromium.") and target.parent == Path(tempfile.gettempdir()):
                shutil.rmtree(target, ignore_errors=True)


class Page:
    """One tab: commands, JavaScript evaluation, bounded waits, clicks, screenshots; ``events`` holds every
    CDP event of this tab as ``(method, params)``."""

    def __init__(self, browser: Browser, session_id: str, context_id: str) -> None:
        self.browser = browser
        self.session_id = session_id
        self.context_id = context_id
        self.events: list[tuple[str, dict]] = []

    async def send(self, method: str, **params) -> dict:
        return await self.browser.send(method, params, self.session_id)

    async def evaluate(self, expression: str) -> Any:
        result = await self.send("Runtime.evaluate", expression=expression, returnByValue=True, awaitPromise=True)
        if "exceptionDetails" in result:
            details = result["exceptionDetails"]
            raise CdpError(f"{expression!r} threw: {details.get('exception', {}).get('description') or details.get('text')}")
        return result["result"].get("value")

    async def wait_for(self, expression: str, timeout_s: float, what: str = "") -> Any:
        """Evaluate ``expression`` until it is truthy (every 0.1 s, at most ``timeout_s``); its value."""
        deadline = time.monotonic() + timeout_s
        while True:
            value = await self.evaluate(expression)
            if value:
                return value
            if time.monotonic() > deadline:
                state = await self.evaluate("JSON.stringify({state: document.body?.dataset.state, status: document.getElementById('status')?.textContent,"
                                            " error: document.getElementById('setup-error')?.textContent, action: document.getElementById('action')?.textContent})")  # fmt: skip
                raise AssertionError(f"waited {timeout_s} s for {what or expression}; page: {state}")
            await asyncio.sleep(0.1)

    async def goto(self, url: str, timeout_s: float = 30.0) -> None:
        await self.send("Page.navigate", url=url)
        await self.wait_for("document.readyState === 'complete'", timeout_s, f"{url} to load")

    async def click(self, selector: str) -> None:
        """A real mouse click at the element's centre (the page receives a user gesture)."""
        box = await self.evaluate(
            f"(() => {{ const el = document.querySelector({json.dumps(selector)}); if (!el) return null; el.scrollIntoView({{block: 'center'}});"
            " const r = el.getBoundingClientRect(); return {x: r.x + r.width / 2, y: r.y + r.height / 2}; })()"
        )
        if box is None:
            raise AssertionError(f"no element {selector}")
        for kind in ("mousePressed", "mouseReleased"):
            await self.send("Input.dispatchMouseEvent", type=kind, x=box["x"], y=box["y"], button="left", clickCount=1)

    async def screenshot(self, path: Path) -> Path:
        data = (await self.send("Page.captureScreenshot", format="png"))["data"]
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_bytes(base64.b64decode(data))
        return path

    def received_frames(self, url_part: str) -> list[dict]:
        """JSON messages the page received on WebSockets whose URL contains ``url_part``, in order."""
        sockets = {p["requestId"] for m, p in self.events if m == "Network.webSocketCreated" and url_part in p["url"]}
        out = []
        for method, params in self.events:
            if method == "Network.webSocketFrameReceived" and params["requestId"] in sockets:
                with contextlib.suppress(ValueError):
                    out.append(json.loads(params["response"]["payloadData"]))
        return out

    def responses(self, url_part: str) -> list[dict]:
        """``Network.responseReceived`` params of the responses whose URL contains ``url_part``."""
        return [p for m, p in self.events if m == "Network.responseReceived" and url_part in p["response"]["url"]]
