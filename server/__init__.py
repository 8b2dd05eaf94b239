"""The FastAPI advisory service (to come; see the service issue)."""
