"""How far ahead the advisor advises (issue 29, item 3): never a speed that aims past the light's next green.

A normal drive (speeding up to the limit, no advice) that reaches the line only after the light's next green has
ended means any plan aims two greens ahead or more: no speed advice ("far_ahead"), the light's true countdown kept,
nothing spoken. The next light sets the horizon (a second light out of reach is still planned for: measured).
"""

from __future__ import annotations

import pytest

from advisory.advice.advisor import advise
from advisory.advice.views import REASONS, AdvisorMemory, AdvisorParams, LightView, Observation

V = 50 / 3.6
P = AdvisorParams(units="kmh")


def cycle_light(ident: int, distance_m: float, red_in_s: float, red_s: float = 42.0, cycle_s: float = 90.0) -> LightView:
    """A fixed-time light whose next red starts ``red_in_s`` from now (negative: red since then)."""
    start = red_in_s
    while start > -red_s:
        start -= cycle_s
    windows = []
    while start < 150.0:
        if start + red_s > 0.0:
            windows.append((max(start, 0.0), start + red_s))
        start += cycle_s
    return LightView(ident, distance_m, True, 1.0, tuple(windows))


def test_no_speed_advice_two_cycles_out():
    """The issue's drive: red now, green in 24 s, the light 1.8 km ahead at 50 km/h (130 s at the limit, the next
    green ends at 72 s): it said "Green in 24 seconds. Ease off to 43 km/h". Now no speed, the countdown kept."""
    light = cycle_light(7001, 1800.0, -18.0)  # red since 18 s: green in 24 s, red again at 72 s
    assert light.red_windows_s[:2] == ((0.0, 24.0), (72.0, 114.0))
    advice, memory = advise(Observation(V, V, (light,), position_m=0.0), AdvisorMemory(), P)
    assert (advice.action, advice.reason, advice.target_speed_mps) == ("none", "far_ahead", None)
    assert (advice.light_red, advice.seconds_to_change_s, advice.light_id, advice.counts_down_to) == (True, 24.0, 7001, "green")
    assert not advice.speak and "far_ahead" in REASONS
    # in reach of the next green: advice again (a plan for that green, not a later one)
    near = cycle_light(7001, 700.0, -18.0)
    advice, _ = advise(Observation(V, V, (near,), position_m=1100.0), memory, P)
    assert advice.reason != "far_ahead" and advice.target_speed_mps is not None and advice.speak


@pytest.mark.parametrize("red_in_s", [-40.0, -20.0, -1.0, 1.0, 10.0, 30.0, 47.0])
def test_the_horizon_is_the_end_of_the_next_green(red_in_s):
    """Whatever the phase: advised exactly while a normal drive reaches the line before the next green to begin ends
    (the start of the second red window); a green now counts as reachable too."""
    for distance_m in (200.0, 500.0, 900.0, 1300.0, 1800.0, 2500.0):
        light = cycle_light(1, distance_m, red_in_s)
        advice, _ = advise(Observation(V, V, (light,), position_m=0.0), AdvisorMemory(), P)
        horizon_s = light.red_windows_s[1][0]
        assert (advice.reason == "far_ahead") == (distance_m / V > horizon_s), (red_in_s, distance_m, advice)


def test_the_next_light_sets_the_horizon():
    """Light 1 is 150 m ahead and green for 20 s; light 2 is 1.5 km farther, out of reach of its next green: the
    advice is for light 1 (only the next light's horizon stops advice; the second is still planned for: dropping it
    from the plan when out of reach cost on the recorded controller, 05-17 pairs 26.3 -> 26.2 % saving and 4 -> 6
    approaches over +10 %, issue 29)."""
    first = cycle_light(1, 150.0, 20.0)
    second = cycle_light(2, 1650.0, -30.0)
    assert 1650.0 / V > second.red_windows_s[1][0]
    advice, _ = advise(Observation(V, V, (first, second), position_m=0.0), AdvisorMemory(), P)
    assert advice.reason == "green_wave" and advice.light_id == 1 and advice.light_ahead == 1
