"""advisory.signals: a fixed-time light answers consistently at the very instants it reports."""

import numpy as np
import pytest

from advisory.drivers.closed_loop import DriverModel, simulate
from advisory.signals import FixedTimeSignal, paper_scenario


def _lights(n: int, seed: int = 0):
    rng = np.random.default_rng(seed)
    for _ in range(n):
        cycle = rng.uniform(40, 120)
        share = rng.uniform(0.3, 0.7)
        yield FixedTimeSignal(500.0, rng.uniform(-cycle, cycle), cycle * share, cycle * (1 - share)), rng.uniform(0.0, 300.0)


def test_the_instant_a_red_ends_is_green_and_the_next_red_is_a_cycle_later():
    """Before the fix ``next_red_start_s(next_green_start_s(t))`` read red at the green instant in ~13 % of lights
    (the phase, recomputed by a modulo, fell a rounding error short of ``red_s``)."""
    for light, t in _lights(3000):
        green = light.next_green_start_s(t)
        red = light.next_red_start_s(green)
        assert not light.is_red(green)
        assert red > green
        if light.is_red(t):
            assert red - green == pytest.approx(light.green_s, abs=1e-9)
        for start, end in light.red_intervals(t, t + 300.0):
            assert light.is_red(start) and not light.is_red(end)
            assert light.next_green_start_s(start) == end and light.next_red_start_s(end) > end


def test_is_red_vectorised_agrees_with_scalar():
    light = FixedTimeSignal(100.0, -12.3, 27.7, 31.1)
    t = np.linspace(-200.0, 200.0, 4001)
    assert np.array_equal(light.is_red(t), np.array([light.is_red(float(x)) for x in t]))


def test_virtual_driver_does_not_brake_hard_for_a_green_it_misread_as_red():
    """A random run of the bench (seed 75): past light 1 the driver, committed to light 2, read the light
    as red at the instant of green and braked at 3.5 m/s²; its comfortable rates are 1.5 (firm 3)."""
    red_s, green_s = 20.614221966351653, 36.44911255574418
    sc = paper_scenario(18.745357035579758, 21.037169622643646, 943.189741967923, red_s=red_s, green_s=green_s)
    run = simulate(sc, driver=DriverModel(noise_mps=0.7514899958268387, seed=75))
    traj = run.trajectory
    past_light_1 = traj.x_m[:-1] > sc.signals[0].position_m + 1.0
    assert traj.accel_mps2[past_light_1].min() >= -3.0 - 1e-9
