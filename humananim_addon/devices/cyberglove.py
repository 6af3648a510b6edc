"""Virtual Technologies CyberGlove over RS-232 (18- and 22-sensor models): polling and
streaming, record parsing and the sensor layout that maps to the rig's finger roles. The
simulator is in sim_glove.py, written separately.

Protocol: the CyberGlove Reference Manual's binary commands. The manual itself is not in our
reference library; the commands, replies and the optional record fields below follow it as a
public driver that implements it quotes it (CyberGlove.cpp: Control, Parameter and Query
tables, GetSample):
- 'G' asks for one record, 'S' streams records, ^C (0x03) stops the stream;
- a parameter is set with its letter and a byte 0/1 and answered with the letter and NUL:
  'D' includes the time stamp in every record, 'U' includes the glove status byte;
- a query '?x' is echoed and answered with its value and NUL: '?S' the number of sensors;
- a record is the command letter ('G' or 'S'), one byte per sensor (1..255: never NUL), then,
  when enabled, the time stamp (a NUL-encoding byte whose bit k says byte k was 0 and is sent
  as 1 << k, then the 4 bytes of the time stamp, least significant first), then the status
  byte, then NUL;
- an error is 'e', a code letter and NUL: '?' unknown command, 'n' too many numbers, 'y' sync
  input rate too fast, 'g' glove not plugged in, 's' sampling rate too fast.

Every connect and reconnect brings the glove from any state to the configured one: ^C (ends a
stream), the reply to '?S' checked against the model, 'D' and 'U' sent with what the device is
set to (a glove left with its time stamp or status byte on by another program is turned to
ours), each answer checked; the parser then expects exactly the configured record. An error
reply is an error (the device's last error; 'glove not plugged in' ends the connection and the
reader retries), never a record."""

import time

import numpy as np

from .device import Device, DeviceError, open_serial

POLL = b"G"
STREAM = b"S"
STOP = b"\x03"
QUERY_SENSORS = b"?S"
TIME_STAMP = b"D"
STATUS_BYTE = b"U"
ERROR_CODES = {ord("?"): "unknown command", ord("n"): "too many numbers", ord("y"): "sync input rate too fast",
               ord("g"): "glove not plugged in", ord("s"): "sampling rate too fast"}
UNPLUGGED = ERROR_CODES[ord("g")]

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
    """Records out of a byte stream: letter, n sensor bytes, [time stamp], [status], NUL; error
    replies 'e' code NUL. Anything else is skipped up to the next record letter (resync).
    Counters as RecordParser's: discarded_bytes, resyncs, rejected."""

    def __init__(self, sensors, time_stamp=False, status_byte=False, letters=b"GS"):
        self.sensors = sensors
        self.time_stamp, self.status_byte = time_stamp, status_byte
        self.size = 2 + sensors + (5 if time_stamp else 0) + (1 if status_byte else 0)
        self.letters = set(letters)
        self.buf = bytearray()
        self.discarded_bytes = 0
        self.resyncs = 0
        self.rejected = 0
        self.errors = []
        self.resyncing = False

    def _lose_sync(self):
        if not self.resyncing:
            self.resyncing = True
            self.resyncs += 1

    def _error_at(self, i):
        b = self.buf
        return b[i] == ord("e") and i + 2 < len(b) and b[i + 1] in ERROR_CODES and b[i + 2] == 0

    def feed(self, data):
        """Bytes in, [dict(raw=, [time_stamp=], [status=])] out; error replies go to `errors`."""
        self.buf.extend(data)
        out, buf, i = [], self.buf, 0
        while True:
            start = i
            while i < len(buf) and buf[i] not in self.letters and not (buf[i] == ord("e") and (
                    len(buf) - i < 3 or self._error_at(i))):
                i += 1
            if i > start:
                self.discarded_bytes += i - start
                self._lose_sync()
            if i >= len(buf):
                break
            if buf[i] == ord("e"):
                if len(buf) - i < 3:
                    break
                self.errors.append(ERROR_CODES[buf[i + 1]])
                i += 3
                continue
            if len(buf) - i < self.size:
                break
            rec = self._check(bytes(buf[i:i + self.size]))
            if rec is None:
                self.rejected += 1
                self.discarded_bytes += 1
                self._lose_sync()
                i += 1
                continue
            out.append(rec)
            self.resyncing = False
            i += self.size
        del buf[:i]
        return out

    def _check(self, rec):
        n = self.sensors
        sensors = rec[1:1 + n]
        if rec[-1] != 0 or 0 in sensors:
            return None
        out = {"raw": np.frombuffer(sensors, dtype=np.uint8).astype(float)}
        k = 1 + n
        if self.time_stamp:
            enc, stamp = rec[k], rec[k + 1:k + 5]
            if 0 in stamp or enc & 0xF0:
                return None
            value = 0
            for j, b in enumerate(stamp):
                if enc >> j & 1:
                    if b != 1 << j:
                        return None
                    b = 0
                value |= b << (8 * j)
            out["time_stamp"] = value
            k += 5
        if self.status_byte:
            if rec[k] == 0:
                return None
            out["status"] = rec[k]
        return out


class CyberGlove(Device):
    """`time_stamp`, `status_byte`: whether records carry them (set on the glove at connect)."""

    kind = "cyberglove"

    def __init__(self, name, port, baud=115200, sensors=18, mode="STREAM", hand="R", timeout=0.05,
                 watchdog=1.0, settle=0.1, time_stamp=False, status_byte=False, **kw):
        super().__init__(name, **kw)
        if sensors not in LAYOUTS:
            raise DeviceError(f"a CyberGlove has 18 or 22 sensors, not {sensors}")
        self.port, self.baud, self.sensors, self.mode, self.hand = port, baud, sensors, mode.upper(), hand
        self.timeout, self.watchdog, self.settle = timeout, watchdog, settle
        self.time_stamp, self.status_byte = time_stamp, status_byte
        self._ser = self._parser = None
        self._last_data = 0.0

    def _write(self, data):
        self._ser.write(data)
        self._ser.flush()

    def _answer(self, n, what):
        """n bytes of an answer; an error reply raises with its meaning."""
        answer = b""
        deadline = time.perf_counter() + 1.0
        while len(answer) < n and time.perf_counter() < deadline:
            answer += self._ser.read(n - len(answer))
            if answer[:1] == b"e" and len(answer) >= 3:
                break
        if answer[:1] == b"e" and len(answer) >= 3 and answer[1] in ERROR_CODES:
            raise DeviceError(f"{self.name}: CyberGlove {ERROR_CODES[answer[1]]} (to {what})")
        return answer

    def _set(self, letter, on):
        self._write(letter + bytes([int(on)]))
        if self._answer(2, letter.decode()) != letter + b"\x00":
            raise DeviceError(f"{self.name}: the CyberGlove did not acknowledge '{letter.decode()}'")

    def _open(self):
        self._ser = open_serial(self.port, self.baud, self.timeout)
        self._write(STOP)
        time.sleep(self.settle)
        self._ser.reset_input_buffer()
        self._write(QUERY_SENSORS)
        answer = self._answer(4, "?S")
        if len(answer) < 4 or answer[:2] != QUERY_SENSORS or answer[3] != 0:
            raise DeviceError(f"{self.name}: no CyberGlove answers on {self.port}")
        if answer[2] != self.sensors:
            raise DeviceError(f"{self.name}: the glove has {answer[2]} sensors, the device is set to "
                              f"{self.sensors}")
        self._set(TIME_STAMP, self.time_stamp)
        self._set(STATUS_BYTE, self.status_byte)
        self._parser = self._new_parser(GloveParser(self.sensors, self.time_stamp, self.status_byte))
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
            self.last_error = f"CyberGlove {self._parser.errors[-1]}"
            unplugged = UNPLUGGED in self._parser.errors
            self._parser.errors.clear()
            if unplugged:
                raise DeviceError(f"{self.name}: CyberGlove {UNPLUGGED}")
        out = []
        for r in records:
            data = dict(r, model=self.sensors, hand=self.hand)
            out.append(self.make_sample("glove", "glove", data, now))
        return out

    def _close(self):
        ser, self._ser = self._ser, None
        if ser is not None:
            try:
                ser.write(STOP)
            except Exception:
                pass
            ser.close()
