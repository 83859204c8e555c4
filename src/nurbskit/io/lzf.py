"""LZF (Marc Lehmann's liblzf), as used by PCD ``binary_compressed``.

The compressed stream is a sequence of tokens; with ``c`` the control byte:

* ``c < 32``: a literal run of ``c + 1`` bytes follows;
* otherwise a back reference: ``length = c >> 5`` (7 means "add the next byte"), then
  ``offset = ((c & 31) << 8) + next byte + 1``; copy ``length + 2`` bytes starting
  ``offset`` bytes back in the output (the copy may overlap what it produces).

The decoder works token by token with bytearray slice copies. ``compress_literal``
writes a valid LZF stream of literal runs only (no size reduction), which any LZF
decoder reads; it is what the PCD writer uses to stay pure numpy.
"""

from __future__ import annotations

import numpy as np


class LZFError(ValueError):
    """A corrupt or truncated LZF stream."""


def decompress(data: bytes | bytearray | memoryview, expected_size: int, *, use_c: bool = True) -> bytes:
    """Decode an LZF stream into exactly ``expected_size`` bytes.

    Example:
        >>> decompress(bytes([2]) + b"abc" + bytes([0x20, 2]), 6)  # "abc" then copy 3 from 3 back
        b'abcabc'
    """
    if use_c:
        try:  # the C implementation, when installed (optional: pip install python-lzf)
            import lzf  # type: ignore

            out = lzf.decompress(bytes(data), expected_size + 1)
            if out is not None and len(out) == expected_size:
                return out
        except ImportError:
            pass
        except ValueError:  # corrupt: let the Python decoder say where
            pass
    src = bytes(data)
    n = len(src)
    out = bytearray()
    i = pos = 0  # input offset, output length (kept as ints: cheaper than len() per token)
    while i < n:
        c = src[i]
        i += 1
        if c < 32:
            end = i + c + 1
            if end > n:
                raise LZFError(f"literal run of {c + 1} bytes at input offset {i - 1} passes the end of the data")
            out += src[i:end]
            pos += c + 1
            i = end
        else:
            length = c >> 5
            if length == 7:
                if i >= n:
                    raise LZFError("stream ends inside a back reference")
                length += src[i]
                i += 1
            if i >= n:
                raise LZFError("stream ends inside a back reference")
            offset = ((c & 31) << 8) + src[i] + 1
            i += 1
            length += 2
            start = pos - offset
            if start < 0:
                raise LZFError(f"back reference {offset} bytes back, but only {pos} bytes were produced")
            if offset >= length:
                out += out[start: start + length]
            else:  # overlapping copy repeats the last `offset` bytes
                out += (bytes(out[start:]) * (-(-length // offset)))[:length]
            pos += length
            if pos > expected_size:  # also bounds what a corrupt stream can make us allocate
                raise LZFError(f"stream decodes to more than the {expected_size} bytes announced")
    if pos != expected_size:
        raise LZFError(f"stream decodes to {pos} bytes, {expected_size} were announced")
    return bytes(out)


def compress_literal(data: bytes) -> bytes:
    """A valid LZF stream holding ``data`` as literal runs of up to 32 bytes (vectorised).

    Example:
        >>> decompress(compress_literal(b"hello"), 5)
        b'hello'
    """
    raw = np.frombuffer(bytes(data), np.uint8)
    n = raw.size
    if n == 0:
        return b""
    full, rest = divmod(n, 32)
    parts = []
    if full:
        block = np.empty((full, 33), np.uint8)
        block[:, 0] = 31
        block[:, 1:] = raw[: full * 32].reshape(full, 32)
        parts.append(block.tobytes())
    if rest:
        parts.append(bytes([rest - 1]) + raw[full * 32:].tobytes())
    return b"".join(parts)
