"""A minimal OSC 1.0 encoder and parser: messages with int32, float32, string, blob, true,
false and nil arguments, and bundles (nested). Enough for the VMC protocol."""

import struct


def _pad(b):
    return b + b"\x00" * (4 - len(b) % 4)


def _string(s):
    return _pad(s.encode("utf-8"))


def encode_message(address, *args):
    tags, data = ",", b""
    for a in args:
        if a is True:
            tags += "T"
        elif a is False:
            tags += "F"
        elif a is None:
            tags += "N"
        elif isinstance(a, int):
            tags += "i"
            data += struct.pack(">i", a)
        elif isinstance(a, float):
            tags += "f"
            data += struct.pack(">f", a)
        elif isinstance(a, str):
            tags += "s"
            data += _string(a)
        elif isinstance(a, (bytes, bytearray)):
            tags += "b"
            data += struct.pack(">i", len(a)) + bytes(a) + b"\x00" * (-len(a) % 4)
        else:
            tags += "f"
            data += struct.pack(">f", float(a))
    return _string(address) + _string(tags) + data


def encode_bundle(elements, timetag=1):
    """`elements`: encoded messages or bundles; timetag 1 means 'immediately'."""
    out = _string("#bundle") + struct.pack(">Q", timetag)
    for e in elements:
        out += struct.pack(">i", len(e)) + e
    return out


class OSCError(ValueError):
    pass


def _read_string(data, i):
    end = data.find(b"\x00", i)
    if end < 0:
        raise OSCError("unterminated OSC string")
    s = data[i:end].decode("utf-8", "replace")
    return s, (end + 4) & ~3


def parse(data):
    """A datagram to a flat list of (address, args) messages (bundles unpacked in order)."""
    data = bytes(data)
    if data.startswith(b"#bundle\x00"):
        if len(data) < 16:
            raise OSCError("short OSC bundle")
        out, i = [], 16
        while i < len(data):
            if i + 4 > len(data):
                raise OSCError("truncated OSC bundle element size")
            (size,) = struct.unpack_from(">i", data, i)
            i += 4
            if size < 0 or i + size > len(data):
                raise OSCError("OSC bundle element runs past the datagram")
            out.extend(parse(data[i:i + size]))
            i += size
        return out
    if not data.startswith(b"/"):
        raise OSCError("an OSC message starts with '/'")
    address, i = _read_string(data, 0)
    if i >= len(data):
        return [(address, [])]
    tags, i = _read_string(data, i)
    if not tags.startswith(","):
        raise OSCError("missing OSC type tags")
    args = []
    for t in tags[1:]:
        if t == "i":
            args.append(struct.unpack_from(">i", data, i)[0])
            i += 4
        elif t == "f":
            args.append(struct.unpack_from(">f", data, i)[0])
            i += 4
        elif t == "d":
            args.append(struct.unpack_from(">d", data, i)[0])
            i += 8
        elif t == "h":
            args.append(struct.unpack_from(">q", data, i)[0])
            i += 8
        elif t == "s":
            s, i = _read_string(data, i)
            args.append(s)
        elif t == "b":
            (n,) = struct.unpack_from(">i", data, i)
            args.append(data[i + 4:i + 4 + n])
            i += 4 + n + (-n % 4)
        elif t in "TFN":
            args.append({"T": True, "F": False, "N": None}[t])
        else:
            raise OSCError(f"unsupported OSC type tag '{t}'")
        if i > len(data):
            raise OSCError("OSC arguments run past the datagram")
    return [(address, args)]
