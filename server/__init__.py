"""The advisory web service: FastAPI only (config, deps, schemas, routes, wiring). ``create_app`` in ``server.app``."""
