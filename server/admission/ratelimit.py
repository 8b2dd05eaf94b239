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


class KeyedBuckets:
    """One :class:`TokenBucket` per key (a client), at most ``max_keys`` of them: when full, the buckets that
    have refilled (their owners idle) are dropped, else the oldest half. Bounded memory under many clients."""

    __slots__ = ("rate_per_s", "burst", "max_keys", "_buckets")

    def __init__(self, rate_per_s: float, burst: float, max_keys: int = 10_000) -> None:
        self.rate_per_s, self.burst, self.max_keys = rate_per_s, burst, max_keys
        self._buckets: dict[str, TokenBucket] = {}

    def take(self, key: str, now_s: float | None = None, rate_per_s: float | None = None, burst: float | None = None) -> float:
        """:meth:`TokenBucket.take` on ``key``'s bucket; ``rate_per_s`` and ``burst``: this key's own (else the
        instance's).

        >>> b = KeyedBuckets(1.0, 1.0)
        >>> b.take("a", 0.0), b.take("a", 0.0), b.take("b", 0.0), b.take("c", 0.0, 1.0, 2.0), b.take("c", 0.0, 1.0, 2.0)
        (0.0, 1.0, 0.0, 0.0, 0.0)
        """
        bucket = self._buckets.get(key)
        if bucket is None:
            if len(self._buckets) >= self.max_keys:
                self._evict(time.monotonic() if now_s is None else now_s)
            bucket = self._buckets[key] = TokenBucket(rate_per_s or self.rate_per_s, burst or self.burst, now_s)
        else:
            bucket.rate_per_s, bucket.burst = rate_per_s or bucket.rate_per_s, burst or bucket.burst
        return bucket.take(now_s)

    def _evict(self, now_s: float) -> None:
        full = [k for k, b in self._buckets.items() if b.tokens + (now_s - b.stamp_s) * b.rate_per_s >= b.burst]
        for k in full or list(self._buckets)[: len(self._buckets) // 2]:
            del self._buckets[k]
