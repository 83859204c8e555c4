"""``nurbskit studio``: the browser studio (the ``[studio]`` extra).

Examples::

    nurbskit studio                              # http://127.0.0.1:8080/, files from .
    nurbskit studio --workdir scans --open       # and open a browser
    nurbskit studio --host 0.0.0.0 --port 9000   # reachable from the network (warns)

It reads and writes only inside ``--workdir``; uploads larger than
``--max-upload-mb`` are refused. Ctrl-C stops the server.
"""

from __future__ import annotations

import math
import os
import socket
import sys
import time
from pathlib import Path

from ..errors import OptionError
from ..studio.guard import is_loopback

MAX_UPLOAD_MB = 10240.0
"""The largest ``--max-upload-mb`` (10 GiB): an upload is held whole in memory, in the browser and here."""

MEBIBYTE = 1024 * 1024


def _port(text: str) -> int:
    try:
        value = int(text)
    except ValueError:
        raise OptionError(f"--port: expected an integer 0..65535, got {text!r}") from None
    if not 0 <= value <= 65535:
        raise OptionError(f"--port: expected an integer 0..65535, got {value}")
    return value


def _megabytes(text: str) -> float:
    """``"200"`` -> ``200.0``: a finite number of MB above 0 and at most :data:`MAX_UPLOAD_MB`."""
    expected = f"--max-upload-mb: expected a number of MB above 0 and at most {MAX_UPLOAD_MB:g}"
    try:
        value = float(text)
    except ValueError:
        raise OptionError(f"{expected}, got {text!r}") from None
    # nan fails every comparison; inf and 1e400 (inf too) fail the upper bound
    if not (math.isfinite(value) and 0 < value <= MAX_UPLOAD_MB):
        raise OptionError(f"{expected}, got {text!r}")
    if int(value * MEBIBYTE) < 1:
        raise OptionError(f"--max-upload-mb: expected at least one byte ({1 / MEBIBYTE:.1g} MB), got {text!r}")
    return value


def _sockets(name: str):
    """Every ``(family, kind, proto, address)`` that ``name`` resolves to for a server, as
    asyncio's server resolves it (raises ``socket.gaierror``, ``UnicodeError`` or ``ValueError``)."""
    infos = socket.getaddrinfo(name, 0, socket.AF_UNSPEC, socket.SOCK_STREAM, 0, socket.AI_PASSIVE)
    return [(family, kind, proto, address) for family, kind, proto, _, address in dict.fromkeys(infos)]


def _bind_all(addresses, port: int) -> int:
    """Bind (and release) every address at ``port``, as asyncio's server would -> the number
    bound; raises the first bind's ``OSError``, its message naming the address. Families
    this machine lacks are skipped."""
    bound = 0
    for family, kind, proto, address in addresses:
        try:
            sock = socket.socket(family, kind, proto)
        except OSError:
            continue  # a family this machine lacks; asyncio skips it too
        with sock:
            if family == socket.AF_INET6 and hasattr(socket, "IPPROTO_IPV6"):
                sock.setsockopt(socket.IPPROTO_IPV6, socket.IPV6_V6ONLY, True)
            if port and os.name == "posix":  # asyncio's server sets it on POSIX
                sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
            try:
                sock.bind((address[0], port, *address[2:]))
            except OSError as exc:  # the same kind (OSError maps errno to its subclass), naming the address
                raise OSError(exc.errno, f"{address[0]}: {(exc.strerror or str(exc)).lower()}") from None
        bound += 1
    return bound


def check_host(host: str) -> str:
    """The address to hand to viser for ``--host``; an OptionError unless it can be bound here.

    viser reads every failure to bind as "port in use" and tries the next port; when the
    host itself is the problem (a name that does not resolve, an address of another
    machine) all 1000 tries fail and the caller then waits, silently, for ever. So resolve
    the host as asyncio's server does (every address the name has, each bound) and bind
    each to port 0 (any free port): that fails only for the address, never for the port
    (:func:`check_port` chooses that). ``[::1]`` is accepted for ``::1``.
    """
    name = host.strip()
    if name.startswith("[") and name.endswith("]"):
        name = name[1:-1]

    def refuse(why: str) -> OptionError:
        return OptionError(f"--host: expected an address of this machine (or a name that resolves to one), "
                           f"got {host!r} ({why})")

    if not name:
        raise refuse("empty; 0.0.0.0 binds every IPv4 address, :: every IPv6 one")
    try:
        addresses = _sockets(name)
    except socket.gaierror as exc:
        raise refuse(exc.strerror or str(exc)) from None
    except (UnicodeError, ValueError):  # "bad..name" (idna), an embedded NUL
        raise refuse("not a valid host name") from None
    try:
        bound = _bind_all(addresses, 0)
    except OSError as exc:
        raise refuse(exc.strerror or str(exc)) from None
    if not bound:
        raise refuse("no socket of its address family can be made here")
    return name


#: How many ports past --port are tried when it is taken (viser's own loop tries 1000).
PORT_TRIES = 1000


def check_port(host: str, port: int) -> int:
    """The port to hand to viser: ``port`` if every address of ``host`` (checked by
    :func:`check_host`) can bind it, else the next one that can; 0 stays 0 (the system
    picks). An OptionError when ``port`` needs privileges (viser would take "permission
    denied" for "in use" and try the next 1000 ports, all privileged below 1024, then
    wait for ever) or when no port from it to 65535 is free (viser's loop would run past
    65535 and stop with the page never served)."""
    if port == 0:
        return 0
    addresses = _sockets(host)
    for candidate in range(port, min(port + PORT_TRIES, 65536)):
        try:
            _bind_all(addresses, candidate)
        except PermissionError:
            raise OptionError(f"--port: {candidate} is not open to this user (permission denied; ports below "
                              f"1024 usually need root); use a port from 1024 to 65535, or 0 for any free one"
                              ) from None
        except OSError:
            continue  # in use: the next one, as viser would
        return candidate
    last = min(port + PORT_TRIES, 65536) - 1
    raise OptionError(f"--port: {port} and the ports after it up to {last} are in use on {host}; "
                      f"choose another, or 0 for any free one")


def register(subparsers) -> None:
    p = subparsers.add_parser(
        "studio", help="the browser studio: load, fit, generate and edit NURBS",
        description="Serve the nurbskit studio (viser) at http://HOST:PORT/. It reads and writes only "
                    "inside --workdir. Needs the [studio] extra.",
    )
    p.add_argument("--host", default="127.0.0.1", help="address to bind (default 127.0.0.1: this machine only)")
    p.add_argument("--port", default="8080", help="port (default 8080; the next free one when taken; 0: any)")
    p.add_argument("--workdir", default=".", help="the only folder the studio reads and writes (default: .)")
    p.add_argument("--max-upload-mb", default="200", help="largest accepted upload in MB (default 200)")
    p.add_argument("--open", action="store_true", help="open the page in a web browser")
    p.set_defaults(run=run)


def run(args) -> int:
    from .._optional import require

    port = _port(args.port)
    limit = _megabytes(args.max_upload_mb)
    if not args.workdir.strip():
        raise OptionError("--workdir: expected a folder, got an empty name")
    workdir = Path(args.workdir)
    if not workdir.is_dir():
        raise OptionError(f"--workdir: {workdir} is not a directory")
    if not os.access(workdir, os.W_OK | os.X_OK):
        sys.stderr.write(f"nurbskit studio: note: {workdir} is read-only here: uploads and saving will fail\n")
    host = check_host(args.host)  # before viser, whose bind loop never ends for a bad host
    port = check_port(host, port)  # or for a privileged port, or past 65535
    require("viser", "studio", "nurbskit studio")
    from ..studio.app import Studio, StudioOptions

    if not is_loopback(host):
        sys.stderr.write(
            f"nurbskit studio: warning: binding {host}: anyone who can reach this machine can use the "
            f"studio and the files in {workdir.resolve()}\n"
        )
    studio = Studio(StudioOptions(host=host, port=port, workdir=workdir,
                                  max_upload_bytes=int(limit * MEBIBYTE))).start()
    sys.stderr.write(f"nurbskit studio: serving {studio.url} (files in {studio.workdir.root}); Ctrl-C stops\n")
    sys.stderr.flush()
    if args.open:
        import webbrowser

        webbrowser.open(studio.url)
    try:
        while True:
            time.sleep(3600)
    finally:
        studio.stop()
