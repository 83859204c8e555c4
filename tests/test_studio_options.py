"""``nurbskit studio``'s options checked before any server starts: ``--host`` (a bad one
made viser try port after port, silently, for ever) and ``--max-upload-mb`` (``inf``
ended in an "unexpected OverflowError"). No test here starts a server."""

from __future__ import annotations

import socket

import pytest

from nurbskit.cli import main
from nurbskit.cli.studio_command import MAX_UPLOAD_MB, _megabytes, check_host, check_port
from nurbskit.errors import OptionError

HOST_EXPECTED = "--host: expected an address of this machine (or a name that resolves to one), got "


def _has_ipv6_loopback() -> bool:
    try:
        with socket.socket(socket.AF_INET6, socket.SOCK_STREAM) as sock:
            sock.bind(("::1", 0))
        return True
    except OSError:
        return False


@pytest.mark.parametrize("host, why", [
    ("192.0.2.1", "cannot assign requested address"),  # TEST-NET-1 (RFC 5737): never this machine's
    ("bad..name", "not a valid host name"),  # refused by the idna codec, before any lookup
    ("", "empty"),
    ("  ", "empty"),
])
def test_a_host_that_cannot_be_bound_is_refused(host, why):
    with pytest.raises(OptionError) as info:
        check_host(host)
    message = str(info.value)
    assert message.startswith(HOST_EXPECTED + repr(host)) and why in message and "\n" not in message


def test_a_name_that_does_not_resolve_is_refused(monkeypatch):
    """Without a lookup (which may be slow where no resolver answers): getaddrinfo's own failure."""
    def no_such_name(*args, **kwargs):
        raise socket.gaierror(socket.EAI_NONAME, "Name or service not known")

    monkeypatch.setattr(socket, "getaddrinfo", no_such_name)
    with pytest.raises(OptionError, match=r"got 'not-an-address' \(Name or service not known\)$"):
        check_host("not-an-address")


@pytest.mark.parametrize("host", ["127.0.0.1", "localhost", "0.0.0.0"])
def test_addresses_of_this_machine_pass(host):
    assert check_host(host) == host


@pytest.mark.skipif(not _has_ipv6_loopback(), reason="no IPv6 loopback here")
def test_an_ipv6_literal_passes_with_or_without_brackets():
    assert check_host("::1") == "::1"
    assert check_host("[::1]") == "::1"


def test_a_port_in_use_is_not_the_hosts_fault():
    """The host check binds to port 0, so a taken --port still goes to viser (the next free one)."""
    with socket.socket() as busy:
        busy.bind(("127.0.0.1", 0))
        busy.listen()
        assert check_host("127.0.0.1") == "127.0.0.1"


def _listening(port: int = 0) -> socket.socket:
    sock = socket.socket()
    sock.bind(("127.0.0.1", port))
    sock.listen()
    return sock


def test_a_free_port_is_kept_and_a_taken_one_moves_to_the_next_free():
    with _listening() as busy:
        taken = busy.getsockname()[1]
        chosen = check_port("127.0.0.1", taken)
        assert chosen > taken  # the next port that binds, as viser would move on
        with socket.socket() as probe:  # and it really is free
            probe.bind(("127.0.0.1", chosen))
    assert check_port("127.0.0.1", 0) == 0


def test_the_last_port_taken_is_one_line_not_a_hang():
    """viser's loop would try 65536 (OverflowError in its thread) and the studio never start."""
    try:
        busy = _listening(65535)
    except OSError:
        pytest.skip("port 65535 is taken on this machine by something else")
    with busy, pytest.raises(OptionError, match=r"--port: 65535 and the ports after it up to 65535 are in use"):
        check_port("127.0.0.1", 65535)


def test_a_privileged_port_is_one_line_not_a_thousand_tries(monkeypatch):
    """Without root, viser takes 'permission denied' for 'in use' and tries the next 1000
    ports, all privileged from port 1 on, then waits for ever."""
    import nurbskit.cli.studio_command as sc

    def denied(addresses, port):
        raise OSError(13, "127.0.0.1: permission denied")

    monkeypatch.setattr(sc, "_bind_all", denied)
    with pytest.raises(OptionError, match=r"--port: 1 is not open to this user \(permission denied"):
        check_port("127.0.0.1", 1)


@pytest.mark.parametrize("host", ["192.0.2.1", "bad..name", ""])
def test_the_command_refuses_a_bad_host_in_one_line_without_a_warning(host, tmp_path, capsys, monkeypatch):
    import nurbskit.studio.app as app

    def never(self):  # the check must come before the server
        raise AssertionError("the server was started")

    monkeypatch.setattr(app.Studio, "start", never)
    assert main(["studio", "--workdir", str(tmp_path), "--port", "0", "--host", host]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and HOST_EXPECTED + repr(host) in err
    assert "warning" not in err and "Traceback" not in err and "unexpected" not in err


@pytest.mark.parametrize("text", ["inf", "-inf", "Infinity", "nan", "1e400", "1e300", "-1", "0", "-0.0",
                                  str(MAX_UPLOAD_MB * 2), "abc", ""])
def test_max_upload_mb_refuses_what_is_not_a_finite_positive_size(text):
    with pytest.raises(OptionError) as info:
        _megabytes(text)
    assert str(info.value) == (f"--max-upload-mb: expected a number of MB above 0 and at most {MAX_UPLOAD_MB:g}, "
                               f"got {text!r}")


def test_max_upload_mb_refuses_less_than_a_byte():
    with pytest.raises(OptionError, match=r"--max-upload-mb: expected at least one byte .* got '1e-9'"):
        _megabytes("1e-9")


@pytest.mark.parametrize("text, value", [("200", 200.0), ("0.5", 0.5), ("1e-6", 1e-6),
                                         (str(MAX_UPLOAD_MB), MAX_UPLOAD_MB)])
def test_max_upload_mb_accepts_sizes_in_range(text, value):
    assert _megabytes(text) == value


@pytest.mark.parametrize("text", ["inf", "nan", "1e400"])
def test_the_command_refuses_a_bad_upload_limit_in_one_line(text, tmp_path, capsys):
    assert main(["studio", "--workdir", str(tmp_path), "--max-upload-mb", text]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "--max-upload-mb" in err and repr(text) in err
    assert "unexpected" not in err and "Traceback" not in err
