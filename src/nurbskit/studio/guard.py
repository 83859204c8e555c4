"""Requests from other web sites refused.

A browser lets any page open a websocket to ``ws://127.0.0.1:PORT``: binding to loopback
keeps other machines out, not the other sites a user has open. viser checks neither the
``Origin`` nor the ``Host`` of a request, so the studio wraps the server's request hook
(websockets' ``process_request``) once, before viser starts its server:

* ``Origin`` (which browsers send with every websocket handshake and cross-site request)
  must name the server the page came from: the request's own ``Host``. Clients that are
  not browsers send none and are let through (they run as a user of this machine).
* On a loopback address the ``Host`` must be a loopback name (``localhost``,
  ``127.0.0.1``, ``[::1]``): a site whose name an attacker points at 127.0.0.1 (DNS
  rebinding) arrives with its own name.

A refused request gets ``403 Forbidden`` before viser sees it.
"""

from __future__ import annotations

import http
import ipaddress
from urllib.parse import urlsplit

LOOPBACK_NAMES = ("localhost", "127.0.0.1", "::1")


def is_loopback(host: str) -> bool:
    """True for addresses only this machine reaches (127.0.0.0/8, ::1, localhost)."""
    name = host.strip().strip("[]").lower()
    if name == "localhost" or name.endswith(".localhost"):
        return True
    try:
        return ipaddress.ip_address(name).is_loopback
    except ValueError:
        return False


def refusal(headers, loopback: bool) -> str | None:
    """Why a request with these headers is refused, or None (see the module docstring)."""
    host = (headers.get("Host") or "").strip()
    if loopback:
        name = urlsplit("//" + host).hostname or ""
        if not is_loopback(name):
            return f"the studio listens on this machine only; Host {host!r} is not a loopback name"
    origin = headers.get("Origin")
    if origin is not None and urlsplit(origin).netloc.lower() != host.lower():
        return f"requests from {origin!r} (another site) are refused"
    return None


def _checked(process_request, loopback: bool):
    def check(connection, request):
        why = refusal(request.headers, loopback)
        if why is not None:
            return connection.respond(http.HTTPStatus.FORBIDDEN, f"nurbskit studio: {why}\n")
        return None if process_request is None else process_request(connection, request)

    return check


def install() -> None:
    """Wrap ``websockets.asyncio.server.serve`` (which viser calls as ``serve(handler,
    host, port, ..., process_request=...)``) so that every server it starts checks
    :func:`refusal` first, for loopback hosts by the stricter rule. Idempotent."""
    import websockets.asyncio.server as server

    serve = server.serve
    if getattr(serve, "nurbskit_guard", False):
        return

    def guarded(handler, host=None, port=None, *args, **kwargs):
        kwargs["process_request"] = _checked(kwargs.get("process_request"), is_loopback(str(host or "")))
        return serve(handler, host, port, *args, **kwargs)

    guarded.nurbskit_guard = True
    server.serve = guarded
