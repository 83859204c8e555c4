"""``python -m nurbskit``: the command line, with Ctrl-C during start-up said in one line."""

try:
    from .cli import entry
except KeyboardInterrupt:  # pressed while the command was still importing
    import sys

    sys.stderr.write("nurbskit: interrupted\n")
    raise SystemExit(130) from None

entry()
