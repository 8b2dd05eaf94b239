"""Who creates a trip and what it may hold: an API key's own quota, or (trips created without a key) the
address's; a per-device limit inside either (docs/SERVICE.md, "Who may create trips, quotas, overload").

A trip is counted against its **client** (``key-<8 hex>`` for an API key, ``addr-<address>`` without one) and,
when it was created with a ``device_id``, against that device within the client. A device id is what the phone
says it is (the app keeps a random one in its storage): it keeps one phone from taking its fleet's share by
mistake (a retry loop), it is no security boundary (the key's quota is).
"""

from __future__ import annotations

import hashlib
from dataclasses import dataclass

from server.config import Settings

ANONYMOUS_PREFIX = "addr-"
"""Clients of trips created without an API key: ``addr-<address>``; shed first when the service is full."""


def key_id(key: str) -> str:
    """The name an API key goes by in logs, metrics, the store and ``ECO_API_KEY_QUOTAS``: never the key itself.

    >>> key_id("k-app")  # printf k-app | sha256sum
    'key-b7dc470b'
    """
    return "key-" + hashlib.sha256(key.encode()).hexdigest()[:8]


@dataclass(frozen=True, slots=True)
class Quota:
    """A client's limits. ``max_trips``, ``max_trips_per_device``: open trips (0 = no limit); the creation
    bucket: ``create_rate_per_s`` [1/s] up to ``create_burst``."""

    max_trips: int
    create_rate_per_s: float
    create_burst: float
    max_trips_per_device: int


@dataclass(frozen=True, slots=True)
class Creator:
    """Who asks for a trip: ``client`` (``key-...`` or ``addr-...``), ``device`` ("" when none was named), the
    ``quota`` they are held to, and whether they came without an API key (``anonymous``: their trips are shed
    first when the service is full)."""

    client: str
    device: str
    quota: Quota
    anonymous: bool = False


def anonymous_allowed(settings: Settings) -> bool:
    """Trips without an API key: ``ECO_ANONYMOUS_TRIPS``, by default only when no key is configured."""
    return settings.anonymous_trips if settings.anonymous_trips is not None else not settings.api_keys


def key_quotas(settings: Settings) -> dict[str, Quota]:
    """Every configured key's quota, by key id: the ``ECO_KEY_*`` defaults, overridden field by field by
    ``ECO_API_KEY_QUOTAS`` (which names a key by itself or by its id)."""
    s = settings
    out = {}
    for key in s.api_keys:
        kid = key_id(key)
        own = s.api_key_quotas.get(key) or s.api_key_quotas.get(kid)
        given = {} if own is None else own.model_dump(exclude_none=True)
        out[kid] = Quota(
            max_trips=given.get("max_trips", s.key_max_trips),
            create_rate_per_s=given.get("create_rate_per_s", s.key_create_rate_per_s),
            create_burst=given.get("create_burst", s.key_create_burst),
            max_trips_per_device=given.get("max_trips_per_device", s.max_trips_per_device),
        )
    return out


def address_quota(settings: Settings) -> Quota:
    """The quota of each address creating trips without a key."""
    s = settings
    return Quota(s.max_trips_per_client, s.create_rate_per_client_per_s, s.create_burst_per_client, s.max_trips_per_device)
