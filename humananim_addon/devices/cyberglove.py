"""Virtual Technologies CyberGlove over RS-232 (18- and 22-sensor models): polling and
streaming, record parsing, a simulator on a pseudo-terminal, and the sensor layout that maps
to the rig's finger roles.

Protocol (CyberGlove reference manual, binary commands): 'G' asks for one record, 'S' starts
streaming records, ^C (0x03) stops the stream; '?S' answers the number of sensors. A record
is the command letter echoed ('G' or 'S'), one byte per sensor, an optional status byte
(enabled with 'u' 1) and a NUL terminator; sensor bytes are 1..255 so the terminator can't
appear inside a record. An error comes back as 'e' and a code letter ('g': glove not plugged
in, 's': sampling error, '?': unknown command) followed by NUL."""

import time

import numpy as np

from .device import Device, DeviceError, open_serial
from .pty_sim import PtySimulator

POLL = b"G"
STREAM = b"S"
STOP = b"\x03"
QUERY_SENSORS = b"?S"
STATUS_BYTE = b"u"
ERROR_CODES = {ord("g"): "glove not plugged in", ord("s"): "sampling error", ord("?"): "unknown command"}

# Sensor order of the manual's sensor tables; each is (role joint, axis) for the rig:
# role joint is (finger, bone index along the finger chain) or ('hand', 0) or ('palm', 0).
SENSORS_18 = (
    ("thumb", 0, "roll"), ("thumb", 1, "flex"), ("thumb", 2, "flex"), ("thumb", 0, "abduct"),
    ("index", 0, "flex"), ("index", 1, "flex"),
    ("middle", 0, "flex"), ("middle", 1, "flex"), ("index", 0, "spread"),
    ("ring", 0, "flex"), ("ring", 1, "flex"), ("ring", 0, "spread"),
    ("pinky", 0, "flex"), ("pinky", 1, "flex"), ("pinky", 0, "spread"),
    ("palm", 0, "arch"), ("hand", 0, "flex"), ("hand", 0, "abduct"),
)
SENSORS_22 = (
    ("thumb", 0, "roll"), ("thumb", 1, "flex"), ("thumb", 2, "flex"), ("thumb", 0, "abduct"),
    ("index", 0, "flex"), ("index", 1, "flex"), ("index", 2, "flex"),
    ("middle", 0, "flex"), ("middle", 1, "flex"), ("middle", 2, "flex"), ("index", 0, "spread"),
    ("ring", 0, "flex"), ("ring", 1, "flex"), ("ring", 2, "flex"), ("ring", 0, "spread"),
    ("pinky", 0, "flex"), ("pinky", 1, "flex"), ("pinky", 2, "flex"), ("pinky", 0, "spread"),
    ("palm", 0, "arch"), ("hand", 0, "flex"), ("hand", 0, "abduct"),
)
LAYOUTS = {18: SENSORS_18, 22: SENSORS_22}


class GloveParser:
    """Records out of a byte stream: letter, n sensor bytes, [status], NUL. Anything else is
    skipped up to the next record letter (resync)."""

    def __init__(self, sensors, status_byte=False, letters=b"GS"):
        self.sensors = sensors
        self.size = 2 + sensors + (1 if status_byte else 0)
        self.letters = set(letters)
        self.buf = bytearray()
        self.garbage_bytes = 0
        self.corrupt_records = 0
        self.errors = []
        self.resyncing = False

    def feed(self, data):
        self.buf.extend(data)
        out, buf, i = [], self.buf, 0
        while True:
            start = i
            while i < len(buf) and buf[i] not in self.letters and buf[i] != ord("e"):
                i += 1
            if i > start:
                self.garbage_bytes += i - start
                self.resyncing = True
            if i >= len(buf):
                break
            if buf[i] == ord("e"):
                if len(buf) - i < 3:
                    break
                if buf[i + 2] == 0:
                    self.errors.append(ERROR_CODES.get(buf[i + 1], f"error '{chr(buf[i + 1])}'"))
                    i += 3
                else:
                    i += 1
                    self.garbage_bytes += 1
                continue
            if len(buf) - i < self.size:
                break
            rec = buf[i:i + self.size]
            if rec[-1] != 0 or 0 in rec[1:-1]:
                self.corrupt_records += 1
                self.resyncing = True
                i += 1
                continue
            out.append(np.frombuffer(bytes(rec[1:1 + self.sensors]), dtype=np.uint8).astype(float))
            self.resyncing = False
            i += self.size
        del buf[:i]
        return out


class CyberGlove(Device):
    kind = "cyberglove"

    def __init__(self, name, port, baud=115200, sensors=18, mode="STREAM", hand="R", timeout=0.05,
                 watchdog=1.0, settle=0.1, **kw):
        super().__init__(name, **kw)
        if sensors not in LAYOUTS:
            raise DeviceError(f"a CyberGlove has 18 or 22 sensors, not {sensors}")
        self.port, self.baud, self.sensors, self.mode, self.hand = port, baud, sensors, mode.upper(), hand
        self.timeout, self.watchdog, self.settle = timeout, watchdog, settle
        self._ser = self._parser = None
        self._last_data = 0.0

    def _write(self, data):
        self._ser.write(data)
        self._ser.flush()

    def _open(self):
        self._ser = open_serial(self.port, self.baud, self.timeout)
        self._write(STOP)
        time.sleep(self.settle)
        self._ser.reset_input_buffer()
        self._write(QUERY_SENSORS)
        answer = b""
        deadline = time.perf_counter() + 1.0
        while len(answer) < 4 and time.perf_counter() < deadline:
            answer += self._ser.read(4 - len(answer))
        if answer[:1] == b"e" and len(answer) >= 3:
            raise DeviceError(f"{self.name}: CyberGlove {ERROR_CODES.get(answer[1], 'error')}")
        if len(answer) < 4 or answer[:2] != QUERY_SENSORS or answer[3] != 0:
            raise DeviceError(f"{self.name}: no CyberGlove answers on {self.port}")
        if answer[2] != self.sensors:
            raise DeviceError(f"{self.name}: the glove has {answer[2]} sensors, the device is set to "
                              f"{self.sensors}")
        self._write(STATUS_BYTE + b"\x00")  # no status byte in records
        time.sleep(self.settle)
        self._ser.reset_input_buffer()
        self._parser = GloveParser(self.sensors)
        if self.mode == "STREAM":
            self._write(STREAM)
        self._last_data = time.perf_counter()

    def _read(self):
        if self.mode == "POLL":
            self._write(POLL)
            data = self._ser.read(self._parser.size)
        else:
            data = self._read_stream()
        now = time.perf_counter()
        records = self._records(data, now)
        if records is None:
            return []
        if self._parser.errors:
            self.last_error = self._parser.errors[-1]
            if self.last_error == ERROR_CODES[ord("g")]:
                raise DeviceError(f"{self.name}: CyberGlove {self.last_error}")
        return [self.make_sample("glove", "glove", {"raw": r, "model": self.sensors, "hand": self.hand}, now)
                for r in records]

    def _close(self):
        ser, self._ser = self._ser, None
        if ser is not None:
            try:
                ser.write(STOP)
            except Exception:
                pass
            ser.close()


def default_glove_motion(t, sensors):
    """Raw sensor bytes 1..255 of a hand slowly closing and opening."""
    phase = 0.5 - 0.5 * np.cos(2 * np.pi * 0.25 * t + np.arange(sensors) * 0.1)
    return np.clip(np.rint(40 + 180 * phase), 1, 255).astype(np.uint8)


class CyberGloveSimulator(PtySimulator):
    """A CyberGlove answering 'G', 'S', ^C, '?S' and 'u' on a pseudo-terminal. Sensor values come
    from `posture(t)` (device time t) unless `hold` is set (a fixed array of raw values)."""

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
        self.status_byte = False
        self._pending = bytearray()

    def values(self, tick):
        return np.asarray(self.hold if self.hold is not None else self.posture(tick / self.rate), np.uint8)

    def _record(self, letter, tick):
        if not self.glove_plugged:
            return b"eg\x00"
        out = letter + bytes(self.values(tick))
        if self.status_byte:
            out += b"\x01"
        return out + b"\x00"

    def tick(self, now):
        self.sent.append((self.tick_count, now))
        self.send(self._record(STREAM, self.tick_count))
        self.tick_count += 1

    def on_bytes(self, data):
        self._pending.extend(data)
        p = self._pending
        while p:
            c = p[0]
            if c == STOP[0]:
                self.streaming = False
                del p[0]
            elif c == POLL[0]:
                del p[0]
                self.send(self._record(POLL, self.tick_count))
                self.tick_count += 1
            elif c == STREAM[0]:
                del p[0]
                self.streaming = True
            elif c == ord("?"):
                if len(p) < 2:
                    return
                what = p[1]
                del p[:2]
                self.send(b"?S" + bytes([self.sensors]) + b"\x00" if what == ord("S") else b"e?\x00")
            elif c == STATUS_BYTE[0]:
                if len(p) < 2:
                    return
                self.status_byte = bool(p[1])
                del p[:2]
                self.send(b"u\x00")
            else:
                del p[0]
                self.send(b"e?\x00")
