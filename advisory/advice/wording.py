"""The wording: an advisory as the driver hears and sees it (:func:`phrase`), the advised speed as the API publishes it
(:func:`published_speed_mps`) and as it is spoken and shown (:func:`spoken_speed`), and a countdown in words
(:func:`say_seconds`). The number heard is the number seen.
"""

from __future__ import annotations

import math

import numpy as np

from advisory.advice.views import Advice

MPH_PER_MPS = 1 / 0.44704
KMH_PER_MPS = 3.6
SLOW_FIRST_FRAC = 0.97
"""A "coast" advice whose target is below this share of the current speed is worded "Slow to X, then coast";
otherwise the braking part is negligible and it is "Lift off and coast". [-]"""


def published_speed_mps(speed_mps: float) -> float:
    """An advised speed as the API publishes it (``target_speed_mps``): rounded down to 0.01 m/s, so never above
    the limit. [m/s]

    Examples
    --------
    >>> published_speed_mps(24.5872)  # 55 mph
    24.58
    """
    return math.floor(speed_mps * 100.0 + 1e-9) / 100.0


def spoken_speed(speed_mps: float, units: str) -> int:
    """The whole km/h or mph heard, and shown by the app (``speedIn`` in ``server/static/lib/units.js``, the same
    operations): the published speed (:func:`published_speed_mps`) converted, halves rounded up. One rounding for
    both, so the number heard is the number seen (before: the voice rounded the exact speed, 55 mph -> "89 km/h",
    the screen the published one, 88).

    Examples
    --------
    >>> spoken_speed(24.5872, "kmh"), spoken_speed(24.5872, "mph"), spoken_speed(12.5, "kmh")
    (88, 55, 45)
    """
    x = published_speed_mps(speed_mps) * (MPH_PER_MPS if units == "mph" else KMH_PER_MPS)
    n = math.floor(x)
    return n + 1 if x - n >= 0.5 else n  # JavaScript's Math.round, to the bit


def _say_speed(speed_mps: float, units: str) -> str:
    return f"{spoken_speed(speed_mps, units):d}"


def say_seconds(t_s: float | None) -> str:
    """"1 second", "12 seconds"; "" when unknown, infinite or under half a second. Whole seconds as a display shows
    the API's ``seconds_to_change_s`` (0.1 s, then halves up): the number heard is the number seen."""
    if t_s is None or not math.isfinite(t_s):
        return ""
    n = math.floor(round(t_s, 1) + 0.5)
    if n < 1:
        return ""
    return "1 second" if n == 1 else f"{n:d} seconds"


def phrase(advice: Advice, units: str = "mph", current_speed_mps: float | None = None) -> str:
    """Short, voice-ready English for an advisory (numbers rounded, speed in mph or km/h). ``current_speed_mps``: the
    car's speed, where the advice does not carry it yet (``Advice.current_speed_mps``; the advisor words its advice
    before it builds the advisory that carries the words).

    The countdown is about the light the speed is chosen for (``advice.light_ahead``): "Second light: green in
    20 seconds. Slow to 40 kilometers per hour." when the next light is passed on green anyway. A speed held for the
    traffic behind (reason ``traffic_behind``) names no countdown: it is not chosen for a green; lifting off for it, it
    says how far only ("Keep up with the traffic. Ease off only to 20 miles per hour.").

    Examples
    --------
    >>> paced = Advice("cruise", "traffic_behind", 11.17, light_red=True, seconds_to_change_s=40.0)
    >>> phrase(paced, "kmh"), phrase(paced, "mph")
    ('Keep up with the traffic. Hold 40 kilometers per hour.', 'Keep up with the traffic. Hold 25 miles per hour.')
    >>> from dataclasses import replace
    >>> phrase(replace(paced, action="ease_off", target_speed_mps=8.94), "mph")
    'Keep up with the traffic. Ease off only to 20 miles per hour.'
    """
    unit_word = "miles per hour" if units == "mph" else "kilometers per hour"
    when = say_seconds(advice.seconds_to_change_s)
    speed = "" if advice.target_speed_mps is None else f"{_say_speed(advice.target_speed_mps, units)} {unit_word}"
    if advice.reason == "stale_spat" and advice.action != "none":  # a dropout: the last advice, held
        return f"Signal data delayed. Keep to {speed}." if advice.action != "stop" else "Signal data delayed. Prepare to stop."
    if advice.action == "none":
        if advice.reason == "red_ahead":
            if advice.light_red is False:  # green now, red before the car gets there: the countdown is to that red
                return f"Red in {when}." if when else "Red light ahead."
            return f"Red light ahead. Green in {when}." if when else "Red light ahead."
        if advice.reason == "tight_green":
            return f"Red in {when}. Drive normally." if when else "Drive normally."
        if advice.reason == "stale_spat" and advice.light_red is not None:
            return "Signal data delayed."  # a short dropout: no new advice, and no push back to the limit
        return {
            "no_spat": "No signal data. Drive normally.",
            "stale_spat": "Signal data is out of date. Drive normally.",
            "low_confidence": "Signal timing uncertain. Drive normally.",
            "off_route": "Off the route. Advice paused.",
            "past_lights": "Last light passed. Advice ends.",
            "far_ahead": "Next light too far ahead for advice.",
        }.get(advice.reason, "")
    if advice.reason == "traffic_behind":
        # a speed held for the cars behind (:func:`advisory.advice.behind.paced_for_behind`), not one that makes a green:
        # no countdown, which would promise the green at that speed; a lift-off says how far only (the advisor's own plan
        # was slower: "Keep up with the traffic. Ease off to 14 mph." told a driver two things at once)
        verb = {"accelerate": "Speed up to", "ease_off": "Ease off only to"}.get(advice.action, "Hold")
        return f"Keep up with the traffic. {verb} {speed}."
    light = ""
    if when:
        light = f"Green in {when}. " if advice.light_red else f"Red in {when}. "
        if advice.light_ahead == 2:
            light = f"Second light: {light[0].lower()}{light[1:]}"
    if advice.action == "stop":
        if advice.light_red is False and when:  # green now, red on arrival: the number is the time to that red
            return f"Red in {when}. Prepare to stop."
        return f"Red light ahead. Prepare to stop. Green in {when}." if when else "Red light ahead. Prepare to stop."
    if advice.action == "resume":
        return f"Last light passed. Resume {speed}."
    if advice.action == "coast":
        if advice.reason == "red_ahead":  # a red whose end is uncertain, far ahead: lift off, no stop yet
            if advice.light_red is False and when:
                return f"Red in {when}. Lift off and coast."
            return f"Red light ahead. Green in {when}. Lift off and coast." if when else "Red light ahead. Lift off and coast."
        speed_now = current_speed_mps if current_speed_mps is not None else advice.current_speed_mps if advice.current_speed_mps is not None else np.inf
        if advice.target_speed_mps is not None and advice.target_speed_mps < SLOW_FIRST_FRAC * speed_now:
            return f"{light}Slow to {speed}, then coast."
        return f"{light}Lift off and coast."
    verb = {"ease_off": "Ease off to", "slow_down": "Slow down to", "brake_to": "Brake to", "accelerate": "Speed up to", "cruise": "Hold"}[advice.action]
    return f"{light}{verb} {speed}."
