"""A frozen screen must not look live (issue 29, item 2): the service killed mid-drive, then started again.

The demo drive runs in headless chromium (the phone's voice stands in for the OS's) against a real service process;
the test kills it (SIGKILL, as a crash or a redeploy does) mid-drive. Within 2 s of the kill the page says so:
the last advice greyed out, the lamp hatched, no countdown, "No connection", "Signal data: no service", and the
voice says "Connection to the service lost. Advice paused." once. The service comes back on the same port:

* with the trips in Redis (``ECO_STORE_URL``) the trip survived: the page goes on with the same trip (new
  advisories, the screen live again) and the drive ends with its score;
* with the trips in memory (the default) it did not: the page says so plainly on the score screen.

The 2 s are measured from the kill (this process's clock) to the instant the page marked itself stale (the page's
``Date.now()``, the same machine's clock); every other wait is a bounded poll.
"""

from __future__ import annotations

import asyncio
import time

import pytest

from tests.browser.cdp import Browser
from tests.browser.conftest import CHROMIUM, figure_dir, needs_chromium
from tests.browser.test_app import PHONE_VOICE, advisories, check_rendering, compose_figure, expected_units, open_app, response_json, run, snapshot
from tests.procs import Proc, RedisServer, redis_server_path

LOST = "Connection to the service lost. Advice paused."
PACE = 4  # the demo drive at 4x: fixes every 0.25 s, 23 s in all (at 2x the Redis case took 47 s of the suite)


def service(folder, store_url: str | None) -> Proc:
    env = {"ECO_CORRIDORS": "paper_s400", "ECO_DEFAULT_CORRIDOR": "paper_s400", "ECO_RATE_PER_S": "100", "ECO_RATE_BURST": "100",
           "ECO_SPEECH": "false", "ECO_TABLES_DIR": str(folder / "tables")}  # fmt: skip
    if store_url:
        env["ECO_STORE_URL"] = store_url
    return Proc(["-m", "server", "--log-level", "warning", "--no-access-log"], folder / "service.log", env)


@needs_chromium
@pytest.mark.parametrize("store", ["redis", "memory"])
def test_a_lost_service_shows_at_once_and_the_trip_comes_back_when_kept(store, tmp_path, shots):
    redis = None
    if store == "redis":
        if redis_server_path() is None:
            pytest.skip("redis-server is not installed (scripts/system-deps.sh installs it as root)")
        (tmp_path / "redis").mkdir()
        redis = RedisServer(tmp_path / "redis").start()
    proc = service(tmp_path, redis.url if redis else None).start()

    async def scenario():
        browser = await Browser.launch(CHROMIUM, tmp_path / "profile", tmp_path / "chromium.log")
        try:
            page = await open_app(browser, proc.base_url + f"/app/?pace={PACE}", script=PHONE_VOICE, language="en-US", scheme="light")
            await page.click("#demo")
            await page.wait_for("Number(document.getElementById('drive').dataset.seq) >= 16", 60, "advice before the outage")
            before = await snapshot(page)
            assert before["stale"] == "" and before["fresh"] == "live", before
            trip = await page.evaluate("document.body.dataset.trip")
            proc.kill()  # SIGKILL: no goodbye on any socket
            killed_at = time.time()
            await page.wait_for("document.body.dataset.stale === '1'", 30, "the page to say the service is gone")
            stale_since = float(await page.evaluate("document.body.dataset.staleSince"))
            stale = await snapshot(page)
            await page.screenshot(shots / "1_service_lost.png")
            await asyncio.sleep(2.5)  # fixes keep failing meanwhile: the page says it once, and stays stale
            still = await snapshot(page)
            spoken = [s["text"] for s in await page.evaluate("window.__spoken")]
            proc.start()  # the same port; with Redis, the same trips
            if store == "redis":
                await page.wait_for("document.body.dataset.recovered === '1' && document.body.dataset.stale === undefined", 60, "the trip to come back")
                back = await snapshot(page)
                await page.screenshot(shots / "2_service_back.png")
                await page.wait_for("document.body.dataset.state === 'score'", 90, "the score")
            else:
                await page.wait_for("document.body.dataset.state === 'score'", 60, "the page to say the trip is gone")
                back = None
            await page.screenshot(shots / "3_after.png")
            summary = await page.evaluate("document.getElementById('score-summary').textContent")
            score = await response_json(page, "/end")
            created = (await response_json(page, "/v1/trips"))[0]
            return trip, killed_at, stale_since, stale, still, spoken, back, summary, score, created, await advisories(page)
        finally:
            await browser.close()

    try:
        trip, killed_at, stale_since, stale, still, spoken, back, summary, score, created, received = run(scenario())
    finally:
        proc.kill()
        if redis is not None:
            redis.kill()
    assert stale_since - killed_at <= 2.0, stale_since - killed_at  # the 2 s (it was 25 s and never said)
    for shown in (stale, still):  # greyed, no countdown, said so
        assert (shown["stale"], shown["light"], shown["countdown"], shown["countdown-light"]) == ("1", "unknown", "", ""), shown
        assert shown["action"] == "No connection" and shown["message"] == LOST and shown["fresh"] == "no service", shown
    assert spoken.count(LOST) == 1, spoken  # once, not at every failed fix
    if store == "redis":
        # the same trip, answered again: the screen live and showing its advisory
        assert back["stale"] == "" and back["seq"] > stale["seq"] and created["trip_id"] == trip, back
        check_rendering(back, next(a for a in received if a["seq"] == back["seq"]), expected_units(created, "en-US"))
        assert len(score) == 1 and score[0]["trip_id"] == trip and score[0]["driven"] is not None
        assert summary and not summary.startswith(("No score", "The service restarted")), summary  # scored, whatever it says
        # the outage's gap in the fixes (stopped at light 1's red before it, past the line after it) is no red crossing
        # (it was: "crossed a red light", as the interpolation across the gap put the car over the line during the red)
        assert score[0]["red_light_crossings"] == [] and "red light was crossed" not in summary, (score[0], summary)
    else:
        assert score == [] and summary.startswith("The service restarted and did not keep this trip"), summary
    if (out := figure_dir()) is not None and store == "redis":
        compose_figure([shots / "1_service_lost.png", shots / "2_service_back.png"], out / "app_service_lost.png")
    if (out := figure_dir()) is not None and store == "memory":
        compose_figure([shots / "1_service_lost.png", shots / "3_after.png"], out / "app_trip_lost.png")
