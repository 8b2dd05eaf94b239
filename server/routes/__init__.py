"""One router per file: health/metrics, corridors, trips (REST), stream (WebSocket), audio."""
