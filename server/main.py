"""``ecodrive serve``: run the advisory service with uvicorn (settings from ``ECO_*`` environment variables)."""

from __future__ import annotations

import argparse
import logging
from collections.abc import Sequence

import uvicorn

from server.app import create_app
from server.config import Settings


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        prog="ecodrive serve",
        description="Eco-driving advisory service (REST + WebSocket). Settings come from ECO_* environment variables (docs/SERVICE.md).",
    )
    parser.add_argument("--host", default="127.0.0.1", help="bind address (default 127.0.0.1; 0.0.0.0 in a container)")
    parser.add_argument("--port", type=int, default=8000)
    parser.add_argument("--log-level", default="info", choices=["critical", "error", "warning", "info", "debug"])
    parser.add_argument("--ws", default="websockets-sansio", choices=["auto", "websockets", "websockets-sansio", "wsproto"], help="uvicorn WebSocket implementation")
    parser.add_argument("--no-access-log", action="store_true", help="do not log every request")
    parser.add_argument("--ssl-certfile", help="serve HTTPS with this certificate (PEM): phones give a page GPS only over https (docs/APP.md)")
    parser.add_argument("--ssl-keyfile", help="the certificate's private key (PEM)")
    args = parser.parse_args(argv)
    logging.basicConfig(level=args.log_level.upper(), format="%(asctime)s %(name)s %(levelname)s %(message)s")
    settings = Settings()
    app = create_app(settings)
    uvicorn.run(
        app,
        host=args.host,
        port=args.port,
        log_level=args.log_level,
        access_log=not args.no_access_log,
        ws=args.ws,
        ws_max_size=settings.ws_max_message_bytes,
        ws_per_message_deflate=False,
        timeout_graceful_shutdown=5,
        ssl_certfile=args.ssl_certfile,
        ssl_keyfile=args.ssl_keyfile,
    )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
