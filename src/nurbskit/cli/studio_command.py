"""``nurbskit studio``: the browser studio (the ``[studio]`` extra).

Examples::

    nurbskit studio                              # http://127.0.0.1:8080/, files from .
    nurbskit studio --workdir scans --open       # and open a browser
    nurbskit studio --host 0.0.0.0 --port 9000   # reachable from the network (warns)

It reads and writes only inside ``--workdir``; uploads larger than
``--max-upload-mb`` are refused. Ctrl-C stops the server.
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

from ..errors import OptionError



def is_loopback(host: str) -> bool:
    """True for addresses only this machine reaches (127.0.0.0/8, ::1, localhost)."""
    import ipaddress

    if host.strip().lower() == "localhost":
        return True
    try:
        return ipaddress.ip_address(host.strip("[]")).is_loopback
    except ValueError:
        return False


def _port(text: str) -> int:
    try:
        value = int(text)
    except ValueError:
        raise OptionError(f"--port: expected an integer 0..65535, got {text!r}") from None
    if not 0 <= value <= 65535:
        raise OptionError(f"--port: expected an integer 0..65535, got {value}")
    return value


def _megabytes(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise OptionError(f"--max-upload-mb: expected a positive number, got {text!r}") from None
    if not value > 0:
        raise OptionError(f"--max-upload-mb: expected a positive number, got {text!r}")
    return value


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
    workdir = Path(args.workdir)
    if not workdir.is_dir():
        raise OptionError(f"--workdir: {workdir} is not a directory")
    require("viser", "studio", "nurbskit studio")
    from ..studio.app import Studio, StudioOptions

    if not is_loopback(args.host):
        sys.stderr.write(
            f"nurbskit studio: warning: binding {args.host}: anyone who can reach this machine can use the "
            f"studio and the files in {workdir.resolve()}\n"
        )
    studio = Studio(StudioOptions(host=args.host, port=port, workdir=workdir,
                                  max_upload_bytes=int(limit * 1024 * 1024))).start()
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
