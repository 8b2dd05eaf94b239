"""``ecodrive serve``: run the advisory service with uvicorn (settings from ``ECO_*`` environment variables)."""

from __future__ import annotations

import argparse
import logging
import os
import re
from collections.abc import Sequence
from urllib.parse import unquote_plus

import uvicorn

from server.app import create_app
from server.config import Settings
from server.web.protocol import protocol_class
from server.admission.quotas import anonymous_allowed, key_quotas
from server.web.ws import IMPLEMENTATION as WS_IMPLEMENTATION

log = logging.getLogger("server")

SECRET_WORDS = ("token", "key", "secret", "passw", "pwd", "auth", "signature", "session", "credential", "jwt", "bearer")
"""A query parameter whose name, percent-decoded, contains one of these (any case, any punctuation: ``X-API-Key``,
``api_key``, ``apiKey``, ``access_token``, ``X%2DAPI%2DKey``) carries a credential: its value never reaches a log."""
_QUERY_PARAM = re.compile(r"(?:^|(?<=[?&;]))([^=&;?#\s\"'<>]+)=([^&;#\s\"'<>]*)")


def _secret_name(name: str) -> bool:
    plain = re.sub(r"[^a-z0-9]", "", unquote_plus(name).lower())
    return any(word in plain for word in SECRET_WORDS)


def redact(text: str) -> str:
    """A URL or log line with credential values in its query replaced by ``***``.

    >>> redact("/v1/trips/abc/stream?token=abc.def&x=1")
    '/v1/trips/abc/stream?token=***&x=1'
    >>> redact('"GET /health?X-API-Key=k1&x%2Dapi%2Dkey=k2&a=1 HTTP/1.1" 200')
    '"GET /health?X-API-Key=***&x%2Dapi%2Dkey=***&a=1 HTTP/1.1" 200'
    """
    if "=" not in text:
        return text
    return _QUERY_PARAM.sub(lambda m: f"{m.group(1)}=***" if m.group(2) and m.group(2) != "***" and _secret_name(m.group(1)) else m.group(0), text)


class RedactSecrets(logging.Filter):
    """Rewrites a record's message, arguments and traceback text with :func:`redact` (uvicorn's access and
    WebSocket lines carry the full path with its query; an exception's text may quote a URL)."""

    def filter(self, record: logging.LogRecord) -> bool:
        if isinstance(record.msg, str) and "=" in record.msg:
            record.msg = redact(record.msg)
        if isinstance(record.args, tuple):
            record.args = tuple(redact(a) if isinstance(a, str) and "=" in a else a for a in record.args)
        elif isinstance(record.args, dict):
            record.args = {k: redact(v) if isinstance(v, str) and "=" in v else v for k, v in record.args.items()}
        if record.exc_info and record.exc_info[0] is not None and not record.exc_text:
            record.exc_text = _FORMATTER.formatException(record.exc_info)
        if record.exc_text and "=" in record.exc_text:
            record.exc_text = redact(record.exc_text)
        return True


_FORMATTER = logging.Formatter()


def install_log_redaction() -> None:
    """:class:`RedactSecrets` on every handler of the root and uvicorn loggers (a handler's filter sees every
    record it writes, whichever logger made it: ``server``, ``uvicorn.error``, ``uvicorn.access``, a library's),
    and on those loggers themselves."""
    loggers = [logging.getLogger(name) for name in ("", "uvicorn", "uvicorn.error", "uvicorn.access")]
    for owner in loggers + [h for logger in loggers for h in logger.handlers]:
        if not any(isinstance(f, RedactSecrets) for f in owner.filters):
            owner.addFilter(RedactSecrets())


def warn_if_open(settings: Settings) -> None:
    """A loud WARNING when trips can be created without an API key; each key's quota, by its id, in the log."""
    if anonymous_allowed(settings):
        besides = (f"ECO_ANONYMOUS_TRIPS is on besides {len(settings.api_keys)} API key(s): trips without a key are shed first when the service is full"
                   if settings.api_keys else "no ECO_API_KEYS set")  # fmt: skip
        log.warning(
            "\n" + "!" * 100 + "\nTRIP CREATION IS OPEN: %s, so anyone who reaches this service can create trips "
            "(up to %d per client address, %d in all).\nSet ECO_API_KEYS=<key1,key2> to require 'X-API-Key' (or 'Authorization: Bearer <key>') on POST /v1/trips.\n"
            + "!" * 100,
            besides, settings.max_trips_per_client, settings.max_trips,
        )  # fmt: skip
    for kid, q in key_quotas(settings).items():
        log.info("API key %s: %s open trips, %g created/s (burst %g), %s per device", kid, q.max_trips or "unlimited", q.create_rate_per_s,
                 q.create_burst, q.max_trips_per_device or "unlimited")  # fmt: skip


def app_from_env():
    """The app of one worker process of ``ecodrive serve --workers N`` (uvicorn's factory): settings from the
    environment, which every worker inherits."""
    logging.basicConfig(level=os.environ.get("ECODRIVE_LOG_LEVEL", "info").upper(), format="%(asctime)s %(name)s %(levelname)s %(message)s")
    install_log_redaction()
    return create_app(Settings())


def __getattr__(name: str):
    """``server.main:EnvProtocol``: the guarded HTTP protocol (``server.web.protocol``) with the environment's limits,
    named by import string so that uvicorn's worker processes can build it."""
    if name == "EnvProtocol":
        s = Settings()
        return protocol_class(s.read_timeout_s, s.max_connections, s.max_connections_per_client)
    raise AttributeError(name)


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        prog="ecodrive serve",
        description="Eco-driving advisory service (REST + WebSocket). Settings come from ECO_* environment variables (docs/SERVICE.md).",
    )
    parser.add_argument("--host", default="127.0.0.1", help="bind address (default 127.0.0.1; 0.0.0.0 in a container)")
    parser.add_argument("--port", type=int, default=8000)
    parser.add_argument("--workers", type=int, default=1, help="worker processes (default 1); more need ECO_STORE_URL (trips in Redis, shared by the workers)")
    parser.add_argument("--log-level", default="info", choices=["critical", "error", "warning", "info", "debug"])
    parser.add_argument("--ws", default="ecodrive", choices=["ecodrive", "auto", "websockets", "websockets-sansio", "wsproto"],
                        help="WebSocket implementation: ecodrive (default: uvicorn's websockets-sansio reading a few messages ahead, server.web.ws) or one of uvicorn's")  # fmt: skip
    parser.add_argument("--no-access-log", action="store_true", help="do not log every request")
    parser.add_argument("--ssl-certfile", help="serve HTTPS with this certificate (PEM): phones give a page GPS only over https (docs/APP.md)")
    parser.add_argument("--ssl-keyfile", help="the certificate's private key (PEM)")
    args = parser.parse_args(argv)
    logging.basicConfig(level=args.log_level.upper(), format="%(asctime)s %(name)s %(levelname)s %(message)s")
    settings = Settings()
    if args.workers < 1:
        parser.error("--workers must be at least 1")
    if args.workers > 1 and not settings.store_url:
        parser.error("--workers > 1 needs ECO_STORE_URL=redis://host:6379/0: with trips in process memory each worker would hold only its own trips (docs/SERVICE.md, Scaling)")
    warn_if_open(settings)
    common = dict(
        host=args.host,
        port=args.port,
        log_level=args.log_level,
        access_log=not args.no_access_log,
        ws=WS_IMPLEMENTATION if args.ws == "ecodrive" else args.ws,
        ws_max_size=max(settings.ws_max_frame_bytes, settings.ws_max_message_bytes),  # above ws_max_message_bytes: a 413 message (server.routes.stream)
        ws_per_message_deflate=False,
        timeout_keep_alive=settings.keep_alive_s,
        timeout_graceful_shutdown=5,
        ssl_certfile=args.ssl_certfile,
        ssl_keyfile=args.ssl_keyfile,
    )
    if args.workers > 1:  # uvicorn's supervisor: one listening socket, N processes, a dead one replaced
        os.environ["ECODRIVE_LOG_LEVEL"] = args.log_level
        config = uvicorn.Config("server.main:app_from_env", factory=True, workers=args.workers, http="server.main:EnvProtocol", **common)
    else:
        config = uvicorn.Config(create_app(settings), http=protocol_class(settings.read_timeout_s, settings.max_connections, settings.max_connections_per_client), **common)
    install_log_redaction()  # after uvicorn's Config has set up its loggers
    if args.workers > 1:
        from uvicorn.supervisors import Multiprocess

        Multiprocess(config, sockets=[config.bind_socket()]).run()
    else:
        uvicorn.Server(config).run()
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
