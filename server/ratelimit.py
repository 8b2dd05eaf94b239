"""A token bucket: ``rate_per_s`` tokens a second up to ``burst``; one request takes one token."""

from __future__ import annotations

import time


class TokenBucket:
    __slots__ = ("rate_per_s", "burst", "tokens", "stamp_s")

    def __init__(self, rate_per_s: float, burst: float, now_s: float | None = None) -> None:
        self.rate_per_s = rate_per_s
        self.burst = burst
        self.tokens = burst
        self.stamp_s = time.monotonic() if now_s is None else now_s

    def take(self, now_s: float | None = None) -> float:
        """0.0 if a token was taken, else the seconds until one will be available.

        >>> b = TokenBucket(1.0, 2.0, now_s=0.0)
        >>> b.take(0.0), b.take(0.0), b.take(0.0), b.take(1.0)
        (0.0, 0.0, 1.0, 0.0)
        """
        now = time.monotonic() if now_s is None else now_s
        self.tokens = min(self.burst, self.tokens + (now - self.stamp_s) * self.rate_per_s)
        self.stamp_s = now
        if self.tokens >= 1.0:
            self.tokens -= 1.0
            return 0.0
        return (1.0 - self.tokens) / self.rate_per_s
