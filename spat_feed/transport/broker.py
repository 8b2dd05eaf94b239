"""The MQTT broker configuration we ship: who may publish SPaT (docs/SPAT.md section 5, "Who may publish SPaT").

``python -m spat_feed.transport.broker DIR --controller k648=648 --reader service`` writes, into ``DIR``:

* ``mosquitto.conf``: one listener, ``allow_anonymous false``, the files below, ``max_packet_size`` a little over
  :data:`~spat_feed.transport.store.MAX_SPAT_BYTES` (the broker drops a larger publish before any subscriber sees it);
* ``passwd``: mosquitto's password file (PBKDF2-SHA512, ``$7$``, as ``mosquitto_passwd`` writes it), a random
  password per user;
* ``acl``: each controller may *write* its own intersections' topics (``<prefix>/<id>``) and nothing else, no other
  user may write them; each reader may *read* ``<prefix>/#`` and write nothing;
* ``<user>.url``: ``mqtt://user:password@host:port/prefix`` for that user (mode 600), what the feed
  (``--mqtt``) and the service (``ECO_SPAT_MQTT_URL``) are given;
* with ``--tls`` (a broker reached across networks): the listener speaks TLS only (``ca.crt``, ``server.crt``,
  ``server.key``: a CA of its own made with the ``openssl`` command, the server's certificate for ``--host``), and the
  URLs are ``mqtts://...?ca=DIR/ca.crt``. A city's own CA replaces it by editing ``mosquitto.conf``.

Users and passwords that already exist in ``DIR`` are kept (a restarted broker, a container recreated on the same
volume); ``--fresh`` makes new ones. A message on a topic its publisher may not write never reaches a subscriber
(mosquitto drops it); the store's plausibility rule (``implausible``) stands behind that for a controller's own
credentials misused.
"""

from __future__ import annotations

import argparse
import base64
import hashlib
import os
import pwd
import re
import secrets
import subprocess
from pathlib import Path
from urllib.parse import quote

from spat_feed.transport.mqtt import DEFAULT_PREFIX
from spat_feed.transport.store import MAX_SPAT_BYTES

PBKDF2_ITERATIONS = 101  # mosquitto_passwd's own
MAX_PACKET_BYTES = MAX_SPAT_BYTES + 4096  # the payload limit plus the topic and header
_NAME = re.compile(r"^[A-Za-z0-9_.-]+$")


def password_hash(password: str, salt: bytes | None = None, iterations: int = PBKDF2_ITERATIONS) -> str:
    """mosquitto's ``$7$`` password hash (PBKDF2-HMAC-SHA512, 12-byte salt, 64-byte key).

    Examples
    --------
    >>> password_hash("pw", bytes(12)).split("$")[:3]
    ['', '7', '101']
    """
    salt = secrets.token_bytes(12) if salt is None else salt
    key = hashlib.pbkdf2_hmac("sha512", password.encode(), salt, iterations, 64)
    return f"$7${iterations}${base64.b64encode(salt).decode()}${base64.b64encode(key).decode()}"


def _existing(folder: Path) -> dict[str, str]:
    """user -> password of the ``<user>.url`` files already in ``folder``."""
    out = {}
    for path in folder.glob("*.url"):
        m = re.match(r"^mqtt://([^:@/]+):([^@/]+)@", path.read_text().strip())
        if m:
            out[m.group(1)] = m.group(2)
    return out


def write_broker_config(
    folder: str | Path,
    controllers: dict[str, tuple[int, ...]],
    readers: tuple[str, ...] = ("service",),
    *,
    port: int = 1883,
    listen: str = "127.0.0.1",
    host: str = "127.0.0.1",
    prefix: str = DEFAULT_PREFIX,
    fresh: bool = False,
    tls: bool = False,
) -> Path:
    """Write the broker's configuration into ``folder`` (see the module docstring); returns ``mosquitto.conf``."""
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    owners: dict[int, str] = {}
    for user, ids in controllers.items():
        for ident in ids:
            if ident in owners:
                raise ValueError(f"intersection {ident} given to {owners[ident]} and {user}: one controller per topic")
            owners[ident] = user
    users = [*controllers, *readers]
    for user in users:
        if not _NAME.match(user):
            raise ValueError(f"user names are letters, digits, '_', '.', '-': {user!r}")
    if len(set(users)) != len(users):
        raise ValueError(f"a user is both a controller and a reader, or named twice: {users}")
    known = {} if fresh else _existing(folder)
    passwords = {u: known.get(u) or secrets.token_urlsafe(18) for u in users}
    acl = [f"# who may publish SPaT: each intersection's topic is written by its controller only (written by python -m spat_feed.transport.broker)"]
    for user, ids in controllers.items():
        acl += ["", f"user {user}", *(f"topic write {prefix}/{i}" for i in sorted(ids))]
    for user in readers:
        acl += ["", f"user {user}", f"topic read {prefix}/#"]
    (folder / "acl").write_text("\n".join(acl) + "\n")
    passwd = folder / "passwd"
    passwd.write_text("".join(f"{u}:{password_hash(p)}\n" for u, p in passwords.items()))
    passwd.chmod(0o600)
    scheme, query, tls_conf = "mqtt", "", ""
    if tls:
        ca, cert, key = _certificates(folder, host, fresh)
        scheme, query = "mqtts", f"?ca={quote(str(ca.resolve()))}"
        tls_conf = f"cafile {ca.resolve()}\ncertfile {cert.resolve()}\nkeyfile {key.resolve()}\ntls_version tlsv1.2\n"
    for user, password in passwords.items():
        path = folder / f"{user}.url"
        path.write_text(f"{scheme}://{user}:{quote(password, safe='')}@{host}:{port}/{prefix}{query}\n")
        path.chmod(0o600)
    conf = folder / "mosquitto.conf"
    conf.write_text(
        f"listener {port} {listen}\n"
        + tls_conf
        + "allow_anonymous false\n"
        f"password_file {passwd.resolve()}\n"
        f"acl_file {(folder / 'acl').resolve()}\n"
        f"max_packet_size {MAX_PACKET_BYTES}\n"
        "persistence false\n"
        f"user {pwd.getpwuid(os.getuid()).pw_name}\n"  # started as root, mosquitto would turn into a user that cannot read them
    )
    return conf


def _certificates(folder: Path, host: str, fresh: bool) -> tuple[Path, Path, Path]:
    """A CA and the broker's certificate for ``host`` (and localhost), made with ``openssl``; kept if present."""
    ca, ca_key, cert, key = (folder / n for n in ("ca.crt", "ca.key", "server.crt", "server.key"))
    if not fresh and all(p.exists() for p in (ca, cert, key)):
        return ca, cert, key
    alt = f"subjectAltName=DNS:{host},DNS:localhost,IP:127.0.0.1" if not re.match(r"^[0-9.]+$", host) else f"subjectAltName=IP:{host},DNS:localhost"

    def run(*args: str) -> None:
        subprocess.run(["openssl", *args], check=True, capture_output=True)

    run("req", "-x509", "-newkey", "rsa:2048", "-nodes", "-days", "825", "-subj", "/CN=ecodrive SPaT broker CA",
        "-keyout", str(ca_key), "-out", str(ca))  # fmt: skip
    csr = folder / "server.csr"
    run("req", "-newkey", "rsa:2048", "-nodes", "-subj", f"/CN={host}", "-keyout", str(key), "-out", str(csr))
    ext = folder / "server.ext"
    ext.write_text(alt + "\n")
    run("x509", "-req", "-in", str(csr), "-CA", str(ca), "-CAkey", str(ca_key), "-CAcreateserial", "-days", "825",
        "-extfile", str(ext), "-out", str(cert))  # fmt: skip
    for p in (ca_key, key):
        p.chmod(0o600)
    csr.unlink()
    ext.unlink()
    return ca, cert, key


def _controller(text: str) -> tuple[str, tuple[int, ...]]:
    name, _, ids = text.partition("=")
    try:
        return name, tuple(int(i) for i in ids.split(",") if i)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected NAME=ID[,ID...], got {text!r}") from None


def main(argv: list[str] | None = None) -> None:
    p = argparse.ArgumentParser(prog="python -m spat_feed.transport.broker", description=__doc__.split("\n\n")[0])
    p.add_argument("folder", type=Path)
    p.add_argument("--controller", type=_controller, action="append", default=[], metavar="NAME=ID[,ID...]",
                   help="a user that may publish the topics of these intersections (and no other)")
    p.add_argument("--reader", action="append", default=[], metavar="NAME", help="a user that may read every SPaT topic (default: service)")
    p.add_argument("--port", type=int, default=1883)
    p.add_argument("--listen", default="127.0.0.1", help="the broker's listening address")
    p.add_argument("--host", default="127.0.0.1", help="the broker's address in the users' URLs")
    p.add_argument("--prefix", default=DEFAULT_PREFIX)
    p.add_argument("--fresh", action="store_true", help="new passwords for every user (and certificates)")
    p.add_argument("--tls", action="store_true", help="TLS only on the listener (a CA and a certificate for --host, openssl)")
    args = p.parse_args(argv)
    conf = write_broker_config(args.folder, dict(args.controller), tuple(args.reader) or ("service",), port=args.port,
                               listen=args.listen, host=args.host, prefix=args.prefix, fresh=args.fresh, tls=args.tls)  # fmt: skip
    print(conf)


if __name__ == "__main__":
    main()
