r"""J2735 TimeMark: tenths of a second since the start of the current UTC hour, and back to Unix time.

J2735 DE_TimeMark is an INTEGER (0..36001) [1]_:

* ``0..35999``: tenths of a second since the top of the current UTC hour;
* ``35991..35999`` are also the values a sender uses during a leap second;
* ``36000``: "more than an hour from now" (or "beyond the hour");
* ``36001``: undefined / unknown.

What this module does with them:

* **Encoding** rounds to the nearest tenth (half away from zero) and wraps at the hour, so
  ``xx:59:59.96`` encodes as ``0``, the top of the next hour. An instant more than an hour ahead of the
  reference encodes as ``TIMEMARK_BEYOND_HOUR``; ``None`` encodes as ``TIMEMARK_UNKNOWN``. Unix time has
  no leap seconds, so we never send 35991..35999 as leap values.
* **Decoding** needs a reference instant (the message's own timestamp, or the receiver's clock). A mark
  names one instant per hour; we pick the one inside a one-hour window placed around the reference,
  which is how the hour rollover is resolved. Change times (minEndTime, maxEndTime, likelyTime,
  nextTime) lie ahead, so their window is ``[ref - 5 min, ref + 55 min)``; ``startTime`` lies behind,
  so its window is ``[ref - 55 min, ref + 5 min)``. Leap-second values decode as ordinary tenths in
  the hour's last second (the leap second folds onto 59.1..59.9 s, as POSIX time does).
  ``36000`` and ``36001`` decode as ``None``: the caller decides what an unknown bound means.

References
----------
.. [1] SAE International, "V2X Communications Message Set Dictionary," SAE J2735_202309, 2023
   (DE_TimeMark).
"""

from __future__ import annotations

import math

TENTHS_PER_HOUR = 36_000
SECONDS_PER_HOUR = 3_600.0
TIMEMARK_BEYOND_HOUR = 36_000
TIMEMARK_UNKNOWN = 36_001
TIMEMARK_LEAP_FIRST = 35_991

FUTURE_WINDOW_START_S = -300.0
"""Decoding window for change times: they lie in ``[ref - 300 s, ref + 3300 s)``. [s]"""
PAST_WINDOW_START_S = -3_300.0
"""Decoding window for start times: they lie in ``[ref - 3300 s, ref + 300 s)``. [s]"""


def unix_to_timemark(t_unix_s: float | None, ref_unix_s: float | None = None) -> int:
    """Encode a Unix instant as a J2735 TimeMark.

    Parameters
    ----------
    t_unix_s : float or None
        The instant to encode; ``None`` for unknown. [s since 1970-01-01 UTC]
    ref_unix_s : float, optional
        The message's time. If given and ``t_unix_s`` is more than one hour after it, the result is
        ``TIMEMARK_BEYOND_HOUR``. [s]

    Returns
    -------
    int
        ``0..35999``, or 36000 (beyond the hour), or 36001 (unknown). [0.1 s]

    Examples
    --------
    >>> unix_to_timemark(1_700_000_000.0)          # 2023-11-14 22:13:20 UTC: 13 min 20 s into the hour
    8000
    >>> unix_to_timemark(1_699_999_199.96)         # 21:59:59.96 rounds up to the next hour's 0
    0
    >>> unix_to_timemark(None), unix_to_timemark(10_000.0, ref_unix_s=0.0)
    (36001, 36000)
    """
    if t_unix_s is None or not math.isfinite(t_unix_s):
        return TIMEMARK_BEYOND_HOUR if t_unix_s == math.inf else TIMEMARK_UNKNOWN
    if ref_unix_s is not None and t_unix_s - ref_unix_s > SECONDS_PER_HOUR:
        return TIMEMARK_BEYOND_HOUR
    tenths = math.floor(t_unix_s * 10.0 + 0.5)
    return tenths % TENTHS_PER_HOUR


def timemark_to_unix(timemark: int, ref_unix_s: float, window_start_s: float = FUTURE_WINDOW_START_S) -> float | None:
    r"""Decode a J2735 TimeMark to the Unix instant it names near ``ref_unix_s``.

    Parameters
    ----------
    timemark : int
        ``0..36001``. [0.1 s]
    ref_unix_s : float
        A nearby known instant (the message timestamp). [s since 1970-01-01 UTC]
    window_start_s : float
        Where the one-hour decoding window starts relative to ``ref_unix_s``; see the module notes. [s]

    Returns
    -------
    float or None
        The unique instant ``t`` with ``t ≡ timemark / 10 (mod 3600)`` in
        ``[ref + window_start_s, ref + window_start_s + 3600)``; ``None`` for 36000 and 36001. [s]

    Notes
    -----
    .. math:: t = h_0 + \tfrac{m}{10} + 3600\,\left\lceil \frac{w - h_0 - m/10}{3600} \right\rceil,
       \quad h_0 = 3600 \lfloor r / 3600 \rfloor,\; w = r + \text{window\_start}

    Examples
    --------
    >>> ref = 1_699_999_199.0                      # 21:59:59 UTC
    >>> timemark_to_unix(50, ref) - ref            # "5.0 s into the hour" is 6 s ahead, across the rollover
    6.0
    >>> timemark_to_unix(35_980, ref, PAST_WINDOW_START_S) - ref   # a start time 1 s ago, same hour
    -1.0
    """
    if not isinstance(timemark, int) or not 0 <= timemark <= TIMEMARK_UNKNOWN:
        raise ValueError(f"TimeMark must be an int in 0..36001, got {timemark!r}")
    if timemark >= TIMEMARK_BEYOND_HOUR:
        return None
    hour_start_s = math.floor(ref_unix_s / SECONDS_PER_HOUR) * SECONDS_PER_HOUR
    t_s = hour_start_s + timemark / 10.0
    window_s = ref_unix_s + window_start_s
    n_hours = math.ceil((window_s - t_s) / SECONDS_PER_HOUR)
    return t_s + n_hours * SECONDS_PER_HOUR
