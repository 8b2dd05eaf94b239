"""Every countdown the app shows matches the SPaT, says to which change and of which light (issue 29, item 1).

A scripted drive on the imported corridor ``oakland_7th_westbound`` (its plausible time-of-day plan, served as
the shared SPaT): geolocation emulated in headless chromium, a car that drives at a steady speed and waits at
the stop line of a red light. The script is planned against the plan in force: when to start, where and how fast,
so that the drive has both a light green now but red on arrival (the advice stops the car while the lamp is
green) and a light red now. Every screen is checked against the truth, the plan at the fix's own instant
(``spat_feed.timing.plans``): the lamp's colour, the number to ±1 s, "s to red" / "s to green" naming the next
change, and the light's name. No timing is asserted: each screen is compared with the advisory it shows.
"""

from __future__ import annotations

import asyncio
import time
from dataclasses import dataclass

import pytest

from spat_feed.road.corridors import load_corridor
from spat_feed.timing.plans import STOP_STATES, seconds_to_next_green, seconds_to_next_red, state_at
from spat_feed.transport.simulator import shared_scenario

from tests.browser.cdp import Browser
from tests.browser.conftest import CHROMIUM, figure_dir, needs_chromium
from tests.browser.test_app import PHONE_VOICE, advisories, check_rendering, compose_figure, open_app, run, snapshot
from tests.procs import Proc

CORRIDOR = "oakland_7th_westbound"
DT_S = 0.5  # the script's step (the page sends the newest position once a second)
STOP_SHORT_M = 3.0  # the car waits this far before a red light's stop line
MARGIN_S = 3.0  # the planned situations hold this long on either side (fix times, a slow machine)


@pytest.fixture(scope="module")
def oakland_service(tmp_path_factory):
    log_dir = tmp_path_factory.mktemp("oakland_service")
    env = {"ECO_CORRIDORS": CORRIDOR, "ECO_DEFAULT_CORRIDOR": CORRIDOR, "ECO_SPEECH": "false", "ECO_TABLES_DIR": str(log_dir / "tables")}
    proc = Proc(["-m", "server", "--log-level", "warning", "--no-access-log"], log_dir / "service.log", env).start()
    yield proc
    proc.kill()


@dataclass(frozen=True)
class Light:
    id: int
    name: str
    line_m: float
    group: int


def lights_of(corridor) -> list[Light]:
    return [Light(ix.id, ix.name, ix.stop_line_m, ix.signal_groups[0].id) for ix in corridor.intersections]


def plan_of(corridor, light: Light, t_unix_s: float):
    """The light's plan in force at ``t_unix_s`` (the shared SPaT: the corridor's default plan, its pattern then)."""
    return shared_scenario(corridor, t_unix_s).fixed_plans()[(light.id, light.group)]


def red_at(plans, light: Light, t_unix_s: float) -> bool:
    return state_at(plans[(light.id, light.group)], t_unix_s) in STOP_STATES


def truth(corridor, light: Light, t_unix_s: float) -> tuple[bool, float]:
    """Red now, and the seconds to the light's next change (to green if red, else to red), from its plan."""
    plan = plan_of(corridor, light, t_unix_s)
    red = state_at(plan, t_unix_s) in STOP_STATES
    return red, (seconds_to_next_green if red else seconds_to_next_red)(plan, t_unix_s).likely_s


def script(corridor, plans, t0_unix_s: float, start_m: float, v_mps: float, until_s: float = 150.0) -> list[tuple[float, float, float]]:
    """(t since start, station, speed): drive at ``v_mps``; a light red when the car would reach its line stops the car
    ``STOP_SHORT_M`` short of it until green. Ends before the corridor does. ``plans``: the lights' plans then."""
    lights = lights_of(corridor)
    out, x, t = [], start_m, 0.0
    while t <= until_s and x < corridor.length_m - 30.0:
        out.append((t, x, v_mps if not out or out[-1][1] != x else 0.0))
        target = x + v_mps * DT_S
        for light in lights:
            if x < light.line_m <= target + STOP_SHORT_M and red_at(plans, light, t0_unix_s + t + DT_S):
                target = min(target, light.line_m - STOP_SHORT_M)
                break
        x, t = max(x, target), t + DT_S
    return out


def situations(corridor, plans, t0_unix_s: float, points) -> tuple[list[float], list[float]]:
    """Instants (since start) at which (a) the next light is green now and red when the car, going as it goes, gets
    there (with ``MARGIN_S`` each side), far enough out to be advised; (b) the next light is red now."""
    lights = lights_of(corridor)
    green_red, red_now = [], []
    for t, x, v in points:
        nxt = next((light for light in lights if light.line_m > x), None)
        if nxt is None:
            continue
        now = t0_unix_s + t
        d = nxt.line_m - x
        if red_at(plans, nxt, now):
            red_now.append(t)
        elif v > 0 and d >= 80.0:
            to_red = seconds_to_next_red(plans[(nxt.id, nxt.group)], now).likely_s
            arrive = now + d / v
            if to_red >= 2.0 and all(red_at(plans, nxt, arrive + k) for k in (-MARGIN_S, 0.0, MARGIN_S)):
                green_red.append(t)
    return green_red, red_now


START_M = tuple(float(x) for x in range(0, 451, 50))
"""Where the scripted drive may start: every 50 m up to 100 m before ``oakland_7th_westbound``'s second light."""
SPEED_MPS = (13.4, 10.0, 8.0, 6.0)


def plan_drive(corridor, now_unix_s: float) -> tuple[float, float, float, float]:
    """(wait before starting, start station, speed, drive duration): the shortest wait + drive whose script has
    both situations for at least 3 s each. Starts every 50 m and four speeds: wait + drive 10-55 s, 29 s on average
    over 150 s of start times (three starts up to 200 m and three speeds: 13-100 s, 52 s; the test's time is mostly
    this wait and drive, in real time)."""
    best = None
    plans = shared_scenario(corridor, now_unix_s).fixed_plans()
    for wait_s in range(0, 91):
        for start_m in START_M:
            for v in SPEED_MPS:
                t0 = now_unix_s + wait_s
                points = script(corridor, plans, t0, start_m, v)
                a, b = situations(corridor, plans, t0, points)
                if len(a) >= 6 and len(b) >= 6:
                    end_s = max(a[5], b[5]) + 4.0
                    if best is None or wait_s + end_s < best[0] + best[3]:
                        best = (float(wait_s), start_m, v, end_s)
        if best is not None and best[0] + best[3] <= wait_s:
            break
    assert best is not None, "no drive through both situations within a cycle"
    return best


def position_at(points, t_s: float) -> tuple[float, float]:
    """Station and speed of the script at ``t_s`` (the step before it)."""
    i = min(max(int(t_s / DT_S), 0), len(points) - 1)
    return points[i][1], points[i][2]


@needs_chromium
def test_every_countdown_on_an_imported_corridor_matches_the_spat(oakland_service, tmp_path, shots):
    corridor = load_corridor(CORRIDOR)
    lights = {light.id: light for light in lights_of(corridor)}

    async def scenario():
        browser = await Browser.launch(CHROMIUM, tmp_path / "profile", tmp_path / "chromium.log")
        try:
            page = await open_app(browser, oakland_service.base_url + "/app/", script=PHONE_VOICE, language="en-US", scheme="light")
            await browser.send("Browser.grantPermissions", {"permissions": ["geolocation"], "origin": oakland_service.base_url, "browserContextId": page.context_id})

            async def move(station_m: float, speed_mps: float) -> None:
                lat, lon = corridor.position(station_m)
                await page.send("Emulation.setGeolocationOverride", latitude=lat, longitude=lon, accuracy=4.0, speed=speed_mps, heading=290.0)

            wait_s, start_m, v, end_s = plan_drive(corridor, time.time())
            await move(start_m, v)
            await asyncio.sleep(wait_s)  # the plan's start: the lights where the script expects them
            t0 = time.time()
            points = script(corridor, shared_scenario(corridor, t0).fixed_plans(), t0, start_m, v)  # on the instant it really starts
            await page.click("#start")
            await page.wait_for("document.body.dataset.state === 'drive'", 20, "the drive screen")
            seen, shot = [], {}
            while (t := time.time() - t0) < end_s:
                await move(*position_at(points, t))
                state = await snapshot(page)
                if state["seq"] and (not seen or state["seq"] != seen[-1]["seq"]):
                    seen.append(state)
                    # the screens of the figure: a green lamp counting down to red while the advice slows or stops the car
                    # for it (a target below the speed, or STOP), and a red lamp counting down to green
                    slowing = state["action"] in ("Slow down", "Brake", "Coast", "Ease off")
                    kind = "green_stop" if state["light"] == "green" and state["target"] == "STOP" else "green_slow" if state["light"] == "green" and slowing else None
                    if state["light"] == "red":
                        kind = "red" if state["target"] == "STOP" else "red_any"
                    if kind and kind not in shot and state["countdown"]:
                        shot[kind] = shots / f"countdown_{kind}.png"
                        await page.screenshot(shot[kind])
                await asyncio.sleep(DT_S / 2)
            await page.click("#end")
            await page.wait_for("document.body.dataset.state === 'score'", 30, "the score")
            return seen, await advisories(page), shot
        finally:
            await browser.close()

    seen, received, shot = run(scenario())
    by_seq = {a["seq"]: a for a in received}
    green_red = red_now = 0
    for shown in seen:
        a = by_seq[shown["seq"]]
        check_rendering(shown, a, "mph")
        if a["light_red"] is None:
            continue
        light = lights[a["light_intersection_id"]]
        red, to_change = truth(corridor, light, a["t_unix_s"])
        assert a["light_red"] == red and shown["light"] == ("red" if red else "green"), (shown, a)
        assert shown["countdown-light"] == light.name, shown  # which light
        if shown["countdown"]:
            assert abs(int(shown["countdown"]) - to_change) <= 1.0, (shown, a, to_change)  # the SPaT, ±1 s
            assert shown["countdown-label"] == f"s to {'green' if red else 'red'}", shown  # to which change
        if not red and a["speed_mps"] and a["light_distance_m"] / a["speed_mps"] > to_change + 1.0:
            green_red += 1  # green now, red on arrival: the lamp green, counting down to that red (was: to the green after it)
            assert shown["countdown-label"] == "s to red" and "Green in" not in a["message"], (shown, a)
        red_now += red
    assert green_red >= 1 and red_now >= 1, seen
    green, red = shot.get("green_stop", shot.get("green_slow")), shot.get("red", shot.get("red_any"))
    if (out := figure_dir()) is not None and green and red:
        compose_figure([green, red], out / "app_countdown.png")
