"""Who may drive the app: the checks made on every HTTP request and websocket handshake.

A browser lets any page open a websocket to any address, so without these checks a page from
another site (or another local port) could read the app's state and change labels. Three rules:

* **Host**: the request's ``Host`` header names this server (for a loopback bind: 127.0.0.1,
  localhost or ::1; plus ``allowed_hosts``), which defeats DNS rebinding;
* **Origin**: a browser's websocket handshake carries the page's origin, which must be this
  server itself (``http://<Host>``): pages served from anywhere else are refused;
* **Token** (required when the app listens beyond loopback): ``?token=...`` in the URL the server
  prints; the page load then sets an HttpOnly cookie that the websocket handshake carries.

viser (1.1) has no hook for this, so :func:`guarded_viser_server` hands viser's websocket server
a ``process_request`` that runs these checks before viser's own (static files and the upgrade),
through the public ``websockets`` function viser binds it with. It checks that it did: a viser that
binds its server another way is refused with a clear error, never served unguarded. The upstream
feature that would remove this shim (a request hook on ``ViserServer``) is written out in
docs/development.md.
"""

from __future__ import annotations

import contextlib
import hmac
import http
import io
import ipaddress
import secrets
import socket
import threading
from dataclasses import dataclass, field
from urllib.parse import parse_qs, urlsplit

import viser
import websockets.asyncio.server

COOKIE = "pnlviz_token"
LOOPBACK_NAMES = ("127.0.0.1", "localhost", "::1")
_SERVE_PATCH = threading.Lock()


def is_loopback(host: str) -> bool:
    if host == "localhost":
        return True
    try:
        return ipaddress.ip_address(host.strip("[]")).is_loopback
    except ValueError:
        return False


def new_token() -> str:
    return secrets.token_urlsafe(18)


def _host_name(value: str) -> str:
    """``"127.0.0.1:8080"`` -> ``"127.0.0.1"``, ``"[::1]:8080"`` -> ``"::1"`` (lower case)."""
    value = value.strip().lower()
    if value.startswith("["):
        return value[1:value.find("]")] if "]" in value else value
    return value.rsplit(":", 1)[0] if value.count(":") == 1 else value


def _lan_address() -> str | None:
    """This machine's address on its default route (no packet is sent), else None."""
    with contextlib.suppress(OSError), socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.connect(("10.255.255.255", 1))
        return s.getsockname()[0]
    return None


@dataclass
class AccessPolicy:
    """The checks for a server bound to ``host`` (``port`` is set once bound). ``token`` None on
    a loopback bind means no token; on any other bind a token is generated."""

    host: str
    token: str | None = None
    allowed_hosts: tuple[str, ...] = ()
    port: int = 0
    names: set[str] = field(default_factory=set)

    def __post_init__(self):
        if self.token is None and not is_loopback(self.host):
            self.token = new_token()
        names = {self.host.lower().strip("[]"), *(h.lower().strip("[]") for h in self.allowed_hosts)}
        if is_loopback(self.host) or self.host in ("0.0.0.0", "::"):
            names.update(LOOPBACK_NAMES)
        if not is_loopback(self.host):
            names.update({socket.gethostname().lower(), socket.getfqdn().lower(), _lan_address() or ""})
        self.names = {n for n in names if n}
        self.any_host = self.host in ("0.0.0.0", "::")

    # ------------------------------------------------------------------ URLs
    def urls(self) -> list[str]:
        """URLs a browser can open, the first one on this machine when that works."""
        query = f"?token={self.token}" if self.token else ""
        if self.any_host:
            hosts = ["127.0.0.1", _lan_address() or socket.gethostname()]
        else:
            hosts = [self.host]
        return [f"http://{'[' + h + ']' if ':' in h else h}:{self.port}/{query}" for h in dict.fromkeys(hosts)]

    # ------------------------------------------------------------------ checks
    def refusal(self, headers, path: str) -> str | None:
        """Why a request is refused, or None when it may go on."""
        hosts, origins = headers.get_all("Host"), headers.get_all("Origin")
        if len(hosts) != 1 or len(origins) > 1:
            return "one Host header (and at most one Origin) expected"
        host_header = hosts[0].strip().lower()
        if not self.any_host and _host_name(host_header) not in self.names:
            return f"this server does not answer to the host name {_host_name(host_header)!r}"
        if origins:
            parts = urlsplit(origins[0])
            if parts.scheme not in ("http", "https") or parts.netloc.lower() != host_header:
                return f"pages from {origins[0][:80]} may not use this server"
        if self.token and not self._has_token(headers, path):
            return "this server needs its token: open the URL it printed (.../?token=...)"
        return None

    def token_in_query(self, path: str) -> bool:
        given = parse_qs(urlsplit(path).query).get("token", [""])[0]
        return bool(self.token) and hmac.compare_digest(given.encode(), (self.token or "").encode())

    def _has_token(self, headers, path: str) -> bool:
        if self.token_in_query(path):
            return True
        for cookie in headers.get_all("Cookie"):
            for part in cookie.split(";"):
                name, _, value = part.strip().partition("=")
                if name == COOKIE and hmac.compare_digest(value.encode(), (self.token or "").encode()):
                    return True
        return False

    def process_request(self, inner):
        """A websockets ``process_request`` running these checks before ``inner`` (viser's)."""

        def guarded(connection, request):
            why = self.refusal(request.headers, request.path)
            if why is not None:
                return connection.respond(http.HTTPStatus.FORBIDDEN, f"pnlviz: refused: {why}\n")
            response = inner(connection, request) if inner is not None else None
            if response is not None and self.token_in_query(request.path):
                response.headers["Set-Cookie"] = f"{COOKIE}={self.token}; HttpOnly; SameSite=Strict; Path=/"
            return response

        return guarded


def guarded_viser_server(policy: AccessPolicy, **kw) -> viser.ViserServer:
    """``viser.ViserServer(**kw)`` whose websocket server runs ``policy`` on every request.

    viser binds its websocket server inside ``ViserServer.__init__`` (in its own thread, while the
    constructor waits); the ``serve`` it calls is wrapped for exactly that time, under a lock. The
    banner viser prints meanwhile is dropped: the caller prints the URLs to open (with the token).
    """
    real = websockets.asyncio.server.serve
    guarded = threading.Event()

    def serve(handler, host=None, port=None, *, process_request=None, **options):
        guarded.set()
        return real(handler, host, port, process_request=policy.process_request(process_request), **options)

    with _SERVE_PATCH, contextlib.redirect_stdout(io.StringIO()):  # viser's banner shows URLs without the token
        setattr(websockets.asyncio.server, "serve", serve)  # a function where websockets has a class
        try:
            server = viser.ViserServer(**kw)
        finally:
            setattr(websockets.asyncio.server, "serve", real)
    if not guarded.is_set():
        server.stop()
        raise UnguardedServerError(
            f"viser {getattr(viser, '__version__', '?')} started its web server without the access checks: "
            f"pnlviz needs viser>=1.1.1,<1.2 (pip install 'viser>=1.1.1,<1.2')")
    return server


class UnguardedServerError(RuntimeError):
    """The installed viser binds its web server in a way the access checks cannot reach."""
