"""A CyberGlove on a pseudo-terminal, written from the CyberGlove Reference Manual's binary
command set (as quoted by a public driver: the manual is not in our reference library) and
independently of the driver in cyberglove.py (it imports nothing from it).

Modelled: 'G' (one record), 'S' (stream), ^C (stop), ^R (reset to the power-up state), the
queries '?S' (sensors), '?D' (time stamp on), '?U' (status byte on) and '?G' (glove plugged in),
the parameters 'D' (time stamp) and 'U' (status byte) set with a byte 0/1 and answered with the
letter and NUL; records 'G'/'S' + one byte per sensor (1..255) + [NUL-encoding byte and 4 time
stamp bytes, least significant first, a zero byte k sent as 1 << k with bit k of the encoding
byte set] + [status byte] + NUL; error replies 'e' + code + NUL ('?' unknown command, 'g' glove
not plugged in). Parameters persist until power-up or ^R: a glove another program left with
its time stamp or status byte on sends them until told otherwise."""

import numpy as np

from .pty_sim import PtySimulator

_STOP, _RESET = 0x03, 0x12


def default_glove_motion(t, sensors):
    """Raw sensor bytes 1..255 of a hand slowly closing and opening."""
    phase = 0.5 - 0.5 * np.cos(2 * np.pi * 0.25 * t + np.arange(sensors) * 0.1)
    return np.clip(np.rint(40 + 180 * phase), 1, 255).astype(np.uint8)


def time_stamp_bytes(value):
    """The NUL-encoding byte and the 4 bytes of a time stamp as the glove sends them."""
    enc, out = 0, bytearray()
    for k in range(4):
        b = (value >> (8 * k)) & 0xFF
        if b == 0:
            enc |= 1 << k
            b = 1 << k
        out.append(b)
    return bytes([enc]) + bytes(out)


class CyberGloveSimulator(PtySimulator):
    """Sensor values come from `posture(t)` (device time t) unless `hold` is set (a fixed array of
    raw values). `glove_plugged` False makes every record an 'eg' error reply. The time stamp
    counts device milliseconds."""

    def __init__(self, sensors=18, rate=100.0, speed=1.0, posture=None):
        self.sensors = sensors
        self.posture = posture or (lambda t: default_glove_motion(t, sensors))
        self.hold = None
        self.sent = []
        self.tick_count = 0
        self.glove_plugged = True
        super().__init__("cyberglove", rate, speed)
        self.on_power_up()

    def on_power_up(self):
        self.streaming = False
        self.time_stamp = False
        self.status_byte = False
        self._pending = bytearray()

    def values(self, tick):
        return np.asarray(self.hold if self.hold is not None else self.posture(tick / self.rate), np.uint8)

    def record(self, letter, tick):
        if not self.glove_plugged:
            return b"eg\x00"
        out = letter + bytes(self.values(tick))
        if self.time_stamp:
            out += time_stamp_bytes(int(round(1000 * tick / self.rate)))
        if self.status_byte:
            out += b"\x01"  # glove in
        return out + b"\x00"

    # -- the glove --------------------------------------------------------------------------
    def tick(self, now):
        self.sent.append((self.tick_count, now))
        self.send(self.record(b"S", self.tick_count))
        self.tick_count += 1

    def on_bytes(self, data):
        self._pending.extend(data)
        p = self._pending
        while p:
            c = p[0]
            if c == _STOP:
                self.streaming = False
                del p[0]
            elif c == _RESET:
                del p[0]
                self.on_power_up()
            elif c == ord("G"):
                del p[0]
                self.streaming = False
                self.send(self.record(b"G", self.tick_count))
                self.tick_count += 1
            elif c == ord("S"):
                del p[0]
                self.streaming = True
            elif c == ord("?"):
                if len(p) < 2:
                    return
                what = p[1]
                del p[:2]
                values = {ord("S"): self.sensors, ord("D"): int(self.time_stamp), ord("U"): int(self.status_byte),
                          ord("G"): int(self.glove_plugged)}
                self.send(b"?" + bytes([what, values[what]]) + b"\x00" if what in values else b"e?\x00")
            elif c in (ord("D"), ord("U")):
                if len(p) < 2:
                    return
                on = bool(p[1])
                del p[:2]
                if c == ord("D"):
                    self.time_stamp = on
                else:
                    self.status_byte = on
                self.send(bytes([c]) + b"\x00")
            else:
                del p[0]
                self.send(b"e?\x00")
