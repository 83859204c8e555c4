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


# ---- what a client sends --------------------------------------------------------------
# viser applies a client's widget update as sent: any property (a client may raise a
# slider's max), any number (a 2,000 x 2,000 grid from a widget whose slider stops at
# 64), any choice (a dropdown value that is not an option). The studio checks each
# update against what the widget offers on the server before viser applies it.


def checked_value(props, value):
    """``value`` as a widget with server-side properties ``props`` (its ``min``, ``max``,
    ``options``) may hold it: numbers clamped into ``[min, max]``, elementwise for
    vectors; None when it cannot be (NaN, a choice that is not an option, a wrong length).

    Example:
        >>> from types import SimpleNamespace as P
        >>> checked_value(P(min=2, max=64), 2000), checked_value(P(min=(2, 2), max=(64, 64)), (1, 9))
        (64, (2, 9))
        >>> checked_value(P(options=("cpu",)), "cuda:7") is None
        True
    """
    import math

    options = getattr(props, "options", None)
    if options is not None:
        return value if value in tuple(options) else None
    low, high = getattr(props, "min", None), getattr(props, "max", None)

    def clamp(x, lo, hi):
        if isinstance(x, bool) or not isinstance(x, (int, float)):
            return x
        if isinstance(x, float) and math.isnan(x):
            return None
        x = x if lo is None else max(x, lo)
        return x if hi is None else min(x, hi)

    if isinstance(value, (tuple, list)):
        n = len(value)
        lows = low if isinstance(low, (tuple, list)) else (low,) * n
        highs = high if isinstance(high, (tuple, list)) else (high,) * n
        if len(lows) != n or len(highs) != n:
            return None
        out = tuple(clamp(x, lo, hi) for x, lo, hi in zip(value, lows, highs))
        return None if any(x is None for x in out) else out
    if isinstance(value, (int, float)) and not isinstance(value, bool):
        return clamp(value, low, high)
    return value


def check_client_updates(gui) -> bool:
    """Check every widget update a client of ``gui`` (a viser client's GUI API) sends before
    viser applies it: only ``value`` is a client's to set, and it must be one the widget
    offers (:func:`checked_value`). Returns False when viser's internals are not those
    this was written against (then nothing is checked here; the tabs' own checks remain)."""
    from viser import _messages

    handles = getattr(gui, "_gui_input_handle_from_uuid", None)
    interface = getattr(gui, "_websock_interface", None)
    handlers = getattr(interface, "_incoming_handlers", None)
    if not isinstance(handles, dict) or not isinstance(handlers, dict):
        return False

    def check(client_id, message) -> None:
        handle = handles.get(message.uuid)
        if handle is None or not isinstance(message.updates, dict):
            return
        impl = handle._impl
        updates = {"value": message.updates["value"]} if "value" in message.updates else {}
        if "value" in updates and not impl.is_button:
            props = getattr(impl, "props", impl)
            value = checked_value(props, updates["value"])
            if value is None:
                del updates["value"]
            else:
                updates["value"] = value
        message.updates.clear()
        message.updates.update(updates)

    handlers.setdefault(_messages.GuiUpdateMessage, []).insert(0, check)  # before viser's own handler
    return True
