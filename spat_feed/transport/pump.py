"""Moves SPaT from a producer (the simulator, a log player) to its sinks (a store, an MQTT publisher, a
recorder, the feed's stream) on a timer: :class:`SpatPump`, and the timer itself, :func:`run_every`."""

from __future__ import annotations

import asyncio
import logging
from collections.abc import Callable, Sequence

from spat_feed.timing.messages import IntersectionState
from spat_feed.transport.store import Clock

log = logging.getLogger("spat_feed.transport.pump")

Producer = Callable[[float], list[IntersectionState]]
"""Given now (Unix s), the states to send now."""
Sink = Callable[[IntersectionState], object]


async def run_every(rate_hz: float, tick: Callable[[], object], name: str = "tick") -> None:
    """Call ``tick`` ``rate_hz`` times a second on the running loop, forever; a tick that falls behind by more
    than a period skips ahead instead of bursting; an exception is logged and the timer goes on."""
    loop = asyncio.get_running_loop()
    period_s = 1.0 / rate_hz
    next_s = loop.time()
    while True:
        next_s += period_s
        delay_s = next_s - loop.time()
        if delay_s < -period_s:
            next_s = loop.time()
            delay_s = 0.0
        await asyncio.sleep(max(delay_s, 0.0))
        try:
            tick()
        except Exception:  # pragma: no cover - keep the timer alive, log the bug
            log.exception("%s failed", name)


class SpatPump:
    """Each tick: ``producer(clock())`` -> every sink, state by state."""

    def __init__(self, producer: Producer, sinks: Sequence[Sink], rate_hz: float, clock: Clock) -> None:
        if not 0 < rate_hz <= 100:
            raise ValueError("rate_hz must be in (0, 100]")
        self.producer, self.sinks, self.rate_hz, self.clock = producer, list(sinks), rate_hz, clock
        self.sent = 0

    def tick(self) -> list[IntersectionState]:
        """One round; returns the states sent."""
        states = self.producer(self.clock())
        for state in states:
            for sink in self.sinks:
                sink(state)
        self.sent += len(states)
        return states

    async def run(self) -> None:
        await run_every(self.rate_hz, self.tick, "SPaT pump")
