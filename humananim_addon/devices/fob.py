"""Ascension Flock of Birds over RS-232: commands, the binary record format, a driver and a
simulator that speaks the same protocol on a pseudo-terminal.

Protocol source: Ascension Technology, "The Flock of Birds Installation and Operation Guide"
(RS-232 commands chapter: command bytes, the "RS232 TO FBB" prefix 0xF0 + address, CHANGE
VALUE / EXAMINE VALUE parameter numbers, HEMISPHERE arguments, the data record format),
cross-checked with the decoding in VRPN's vrpn_Tracker_Flock (auto-configuration with
CHANGE VALUE 50, group mode with CHANGE VALUE 35 and the trailing address byte, the flock
system status bits of EXAMINE VALUE 36).

Record format: every value is a 14-bit two's-complement word sent as two bytes, the least
significant first. Each byte carries 7 data bits; bit 7 is the phasing bit, set only on the
first byte of a record, so a reader can find the start of a record in a byte stream. The word
is ((MSbyte << 7) | (LSbyte & 0x7F)) << 2 read as a signed 16-bit integer, and scales to
+-full scale at +-32768: positions to the range in inches (36 in for the standard transmitter,
72 in with the 72-in scaling, 144 in for the Extended Range Controller), angles to +-180 deg,
matrix and quaternion elements to +-1. In group mode each bird's record is followed by one
byte holding its FBB address.

Orientation conventions (as the guide defines them): angles are azimuth (about Z), elevation
(about Y) and roll (about X) of the sensor in the transmitter's frame (X forward, Y right,
Z down); the rotation taking sensor axes to transmitter axes is Rz(A) Ry(E) Rx(R). The MATRIX
record is the guide's M, the transpose of that rotation, sent column by column
(M11, M21, M31, M12, ...). The QUATERNION record is q0 (scalar), q1, q2, q3 of the same
sensor-to-transmitter rotation."""

import time

import numpy as np

from ...solver import rotations
from .device import Device, DeviceError, open_serial
from .pty_sim import PtySimulator

INCH = 0.0254

# Command bytes (the guide's RS-232 command table)
POINT = b"B"
STREAM = b"@"
RUN = b"F"
SLEEP = b"G"
CHANGE_VALUE = b"P"
EXAMINE_VALUE = b"O"
HEMISPHERE = b"L"
RS232_TO_FBB = 0xF0  # + FBB address 1..14 (normal addressing): the next command is for that bird

RECORDS = {  # name: (command byte, words)
    "POSITION": (b"V", 3),
    "ANGLES": (b"W", 3),
    "MATRIX": (b"X", 9),
    "POSITION/ANGLES": (b"Y", 6),
    "POSITION/MATRIX": (b"Z", 12),
    "QUATERNION": (b"\\", 4),
    "POSITION/QUATERNION": (b"]", 7),
}
COMMAND_RECORD = {cmd[0]: name for name, (cmd, _) in RECORDS.items()}

# CHANGE VALUE / EXAMINE VALUE parameter numbers and their value sizes in bytes
PARAM_STATUS = 0
PARAM_SOFTWARE_REVISION = 1
PARAM_POSITION_SCALING = 3
PARAM_ERROR_CODE = 10
PARAM_MODEL = 15
PARAM_FBB_ADDRESSING = 19
PARAM_FBB_ADDRESS = 21
PARAM_HEMISPHERE = 22
PARAM_GROUP_MODE = 35
PARAM_SYSTEM_STATUS = 36
PARAM_AUTOCONFIG = 50
PARAM_SIZES = {PARAM_STATUS: 2, PARAM_SOFTWARE_REVISION: 2, PARAM_POSITION_SCALING: 2, PARAM_ERROR_CODE: 1,
               PARAM_MODEL: 10, PARAM_FBB_ADDRESSING: 1, PARAM_FBB_ADDRESS: 1, PARAM_HEMISPHERE: 2,
               PARAM_GROUP_MODE: 1, PARAM_SYSTEM_STATUS: 14, PARAM_AUTOCONFIG: 1}

HEMISPHERES = {  # name: (HEMI_AXIS, HEMI_SIGN)
    "FORWARD": (0x00, 0x00), "AFT": (0x00, 0x01), "UPPER": (0x0C, 0x01),
    "LOWER": (0x0C, 0x00), "LEFT": (0x06, 0x01), "RIGHT": (0x06, 0x00),
}

# flock system status byte per FBB address (EXAMINE VALUE 36)
STATUS_ACCESSIBLE, STATUS_RUNNING, STATUS_RECEIVER, STATUS_ERT = 0x80, 0x40, 0x20, 0x10

ERRORS = {1: "System RAM test error", 2: "Non-volatile storage write failure",
          3: "System EEPROM configuration corrupt", 4: "Transmitter EEPROM configuration corrupt",
          5: "Receiver EEPROM configuration corrupt", 6: "Invalid RS232 command", 7: "Not an FBB master",
          8: "No birds are active", 9: "Bird has not been initialized", 10: "FBB receive error (intra bird bus)",
          11: "RS232 overrun and/or framing error", 12: "FBB receive error (FBB host bus)",
          13: "No FBB command response", 14: "Invalid FBB host command", 15: "FBB run time error",
          16: "Invalid CPU speed", 17: "Slave no data", 18: "Illegal baud rate", 19: "Slave acknowledge error",
          28: "CRT synchronization error", 29: "Transmitter not active", 30: "ERC extended range transmitter "
          "not attached", 31: "CPU time overflow", 32: "Receiver saturated", 33: "Slave configuration error",
          34: "ERC watchdog error", 35: "ERC overtemperature"}

RANGES_INCHES = {"STANDARD": 36.0, "STANDARD_72": 72.0, "EXTENDED": 144.0}


def record_size(fmt, group=False):
    return 2 * RECORDS[fmt][1] + (1 if group else 0)


def resolution(range_inches):
    """Metres per least significant step of a position word (14 bits of 16)."""
    return range_inches * INCH * 4.0 / 32768.0


# -- words ----------------------------------------------------------------------------------------
def encode_words(values, full_scale):
    """Values (scaled so that full_scale maps to 32768) to the 2-bytes-per-word wire form,
    the phasing bit set on the first byte."""
    n = np.clip(np.rint(np.asarray(values, float) / full_scale * 32768.0), -32768, 32767).astype(np.int64)
    w = (n >> 2) & 0x3FFF  # the 14 bits sent
    out = bytearray()
    for v in w:
        out.append(int(v) & 0x7F)
        out.append((int(v) >> 7) & 0x7F)
    if out:
        out[0] |= 0x80
    return bytes(out)


def decode_words(data):
    """The wire bytes of a record (phasing bit included) to signed 16-bit integers."""
    b = np.frombuffer(bytes(data), dtype=np.uint8).astype(np.int64)
    lsb, msb = b[0::2] & 0x7F, b[1::2] & 0x7F
    n = ((msb << 7) | lsb) << 2
    return np.where(n >= 32768, n - 65536, n)


def quantize(values, full_scale):
    """What the device can represent: the value after encoding and decoding."""
    return decode_words(encode_words(values, full_scale)) * full_scale / 32768.0


# -- orientation --------------------------------------------------------------------------------
def angles_to_rotation(angles_deg):
    """(azimuth, elevation, roll) degrees to the sensor-to-transmitter rotation matrix."""
    a, e, r = np.radians(angles_deg)
    ca, sa, ce, se, cr, sr = np.cos(a), np.sin(a), np.cos(e), np.sin(e), np.cos(r), np.sin(r)
    rz = np.array([[ca, -sa, 0], [sa, ca, 0], [0, 0, 1]])
    ry = np.array([[ce, 0, se], [0, 1, 0], [-se, 0, ce]])
    rx = np.array([[1, 0, 0], [0, cr, -sr], [0, sr, cr]])
    return rz @ ry @ rx


def rotation_to_angles(m):
    m = np.asarray(m, float)
    elevation = np.arcsin(np.clip(-m[2, 0], -1.0, 1.0))
    azimuth = np.arctan2(m[1, 0], m[0, 0])
    roll = np.arctan2(m[2, 1], m[2, 2])
    return np.degrees([azimuth, elevation, roll])


def encode_record(fmt, position_m, angles_deg, range_inches, address=None):
    """One record as the bird sends it, from a position (metres) and angles (degrees)."""
    rot = angles_to_rotation(angles_deg)
    pos_in = np.asarray(position_m, float) / INCH
    parts = []
    if fmt.startswith("POSITION"):
        parts.append((pos_in, range_inches))
    if fmt.endswith("ANGLES"):
        parts.append((angles_deg, 180.0))
    elif fmt.endswith("MATRIX"):
        parts.append((rot.T.flatten(order="F"), 1.0))  # the guide's M = rot^T, column by column
    elif fmt.endswith("QUATERNION"):
        q = rotations.from_matrix(rot)
        parts.append((q if q[0] >= 0 else -q, 1.0))
    words = np.concatenate([np.asarray(v, float) / s for v, s in parts])
    data = bytearray(encode_words(words, 1.0))
    if address is not None:
        data.append(address & 0x7F)
    return bytes(data)


def decode_record(fmt, words, range_inches):
    """Signed words of one record to a sample dict: position (m), quaternion (w,x,y,z), and
    the angles or matrix when that is what the bird sent."""
    w = np.asarray(words, float) / 32768.0
    out = {}
    if fmt.startswith("POSITION"):
        out["position"] = w[:3] * range_inches * INCH
        w = w[3:]
    if fmt.endswith("ANGLES"):
        angles = w[:3] * 180.0
        out["angles"] = angles
        out["quaternion"] = rotations.from_matrix(angles_to_rotation(angles))
    elif fmt.endswith("MATRIX"):
        m = w[:9].reshape(3, 3, order="F")
        out["matrix"] = m
        out["quaternion"] = rotations.from_matrix(_orthonormal(m.T))
    elif fmt.endswith("QUATERNION"):
        out["quaternion"] = rotations.normalize(w[:4])
        out["raw_quaternion"] = w[:4]
    return out


def _orthonormal(m):
    u, _, vt = np.linalg.svd(m)
    r = u @ vt
    if np.linalg.det(r) < 0:
        u[:, -1] *= -1
        r = u @ vt
    return r


class RecordParser:
    """Finds records in a byte stream by their phasing bit, rejects corrupted ones and resyncs.

    A candidate record starts at a byte with bit 7 set; it is accepted when none of its other
    bytes has bit 7 set, its address byte (group mode) is one of the birds, and a quaternion
    or matrix is a rotation. A rejected candidate is dropped one byte at a time, so a real
    record hidden behind a partial one is still found."""

    def __init__(self, fmt, range_inches, addresses=None):
        self.fmt = fmt
        self.range_inches = range_inches
        self.addresses = None if addresses is None else set(addresses)
        self.size = record_size(fmt, addresses is not None)
        self.buf = bytearray()
        self.garbage_bytes = 0
        self.corrupt_records = 0
        self.resyncing = False

    def feed(self, data):
        """Bytes in, [(address or None, decoded dict)] out."""
        self.buf.extend(data)
        out = []
        buf, size = self.buf, self.size
        i = 0
        n = len(buf)
        while True:
            start = i
            while i < n and not buf[i] & 0x80:
                i += 1
            if i > start:
                self.garbage_bytes += i - start
                self.resyncing = True
            if n - i < size:
                break
            rec = bytes(buf[i:i + size])
            decoded = self._check(rec)
            if decoded is None:
                self.corrupt_records += 1
                self.resyncing = True
                i += 1
                continue
            out.append(decoded)
            self.resyncing = False
            i += size
        del buf[:i]
        return out

    def _check(self, rec):
        body = rec[:-1] if self.addresses is not None else rec
        if any(b & 0x80 for b in rec[1:]):
            return None
        address = None
        if self.addresses is not None:
            address = rec[-1]
            if address not in self.addresses:
                return None
        d = decode_record(self.fmt, decode_words(body), self.range_inches)
        if "raw_quaternion" in d and abs(np.linalg.norm(d.pop("raw_quaternion")) - 1.0) > 0.02:
            return None
        if "matrix" in d and np.abs(d["matrix"] @ d["matrix"].T - np.eye(3)).max() > 0.02:
            return None
        return address, d


class FlockOfBirds(Device):
    """A flock on one RS-232 port: a standalone bird, or several birds on the Fast Bird Bus
    addressed through the master (RS232 TO FBB), in group mode when more than one is read.

    `birds`: FBB addresses of the birds with a sensor; `units`: how many units the flock
    auto-configures (default: the highest address); `mode`: 'STREAM' or 'POINT'."""

    kind = "flock_of_birds"

    def __init__(self, name, port, baud=115200, birds=(1,), record="POSITION/QUATERNION", mode="STREAM",
                 hemisphere="FORWARD", standalone=False, units=None, settle=0.3, timeout=0.05, watchdog=1.0,
                 **kw):
        super().__init__(name, **kw)
        if record not in RECORDS:
            raise DeviceError(f"unknown Flock of Birds record '{record}' (one of {', '.join(RECORDS)})")
        if hemisphere not in HEMISPHERES:
            raise DeviceError(f"unknown hemisphere '{hemisphere}' (one of {', '.join(HEMISPHERES)})")
        if standalone and len(birds) != 1:
            raise DeviceError("a standalone bird is a single bird")
        self.port, self.baud, self.birds = port, baud, tuple(int(b) for b in birds)
        self.record, self.mode, self.hemisphere = record, mode.upper(), hemisphere
        self.standalone, self.units = standalone, units or max(self.birds)
        self.settle, self.timeout, self.watchdog = settle, timeout, watchdog
        self.group = len(self.birds) > 1
        self.range_inches = None
        self.model = ""
        self._ser = None
        self._parser = None
        self._last_data = 0.0

    # -- commands ---------------------------------------------------------------------------
    def _to(self, address):
        """The RS232 TO FBB prefix that sends the next command to one bird."""
        return b"" if self.standalone else bytes([RS232_TO_FBB + address])

    def _write(self, data):
        self._ser.write(data)
        self._ser.flush()

    def _read_exact(self, n, what):
        data = self._ser.read(n)
        deadline = time.perf_counter() + 1.0
        while len(data) < n and time.perf_counter() < deadline:
            data += self._ser.read(n - len(data))
        if len(data) < n:
            raise DeviceError(f"{self.name}: the flock did not answer {what} ({len(data)} of {n} bytes)")
        return data

    def examine(self, param):
        """EXAMINE VALUE: the parameter's bytes."""
        self._write(EXAMINE_VALUE + bytes([param]))
        return self._read_exact(PARAM_SIZES[param], f"EXAMINE VALUE {param}")

    def change(self, param, value):
        """CHANGE VALUE with the parameter's value bytes."""
        self._write(CHANGE_VALUE + bytes([param]) + bytes(value))

    def error_code(self):
        return self.examine(PARAM_ERROR_CODE)[0]

    # -- the device ---------------------------------------------------------------------------
    def _open(self):
        self._ser = open_serial(self.port, self.baud, self.timeout)
        self._write(POINT)  # a flock left streaming answers nothing else
        time.sleep(self.settle)
        self._ser.reset_input_buffer()
        if not self.standalone:
            # the guide asks for a pause of at least 300 ms around the auto-configuration
            self.change(PARAM_AUTOCONFIG, [self.units])
            time.sleep(self.settle)
            self._ser.reset_input_buffer()
            status = self.examine(PARAM_SYSTEM_STATUS)
            for b in self.birds:
                s = status[b - 1]
                if not (s & STATUS_ACCESSIBLE and s & STATUS_RUNNING and s & STATUS_RECEIVER):
                    raise DeviceError(f"{self.name}: bird {b} is not accessible, running and with a sensor "
                                      f"(status 0x{s:02x})")
        self.model = self.examine(PARAM_MODEL).decode("ascii", "replace").strip()
        if "ERC" in self.model:
            self.range_inches = RANGES_INCHES["EXTENDED"]
        else:
            scaling = self.examine(PARAM_POSITION_SCALING)
            self.range_inches = RANGES_INCHES["STANDARD_72" if scaling[0] | scaling[1] << 8 else "STANDARD"]
        cmd = RECORDS[self.record][0]
        for b in self.birds:
            self._write(self._to(b) + cmd)
            self._write(self._to(b) + HEMISPHERE + bytes(HEMISPHERES[self.hemisphere]))
        if self.group:
            self.change(PARAM_GROUP_MODE, [1])
        code = self.error_code()
        if code:
            raise DeviceError(f"{self.name}: flock error {code}: {ERRORS.get(code, 'unknown error')}")
        self._parser = RecordParser(self.record, self.range_inches, self.birds if self.group else None)
        self._held = []
        if self.mode == "STREAM":
            self._write(STREAM)
        self._last_data = time.perf_counter()

    def _read(self):
        if self.mode == "POINT":
            self._write(POINT if self.group or self.standalone else self._to(self.birds[0]) + POINT)
            want = self._parser.size * (len(self.birds) if self.group else 1)
            data = self._ser.read(want)
        else:
            data = self._read_stream()
        now = time.perf_counter()
        records = self._records(data, now)
        if records is None:
            return []
        if self.group:
            records = self._whole_records(records)
        samples = []
        for address, d in records:
            bird = self.birds[0] if address is None else address
            samples.append(self.make_sample(f"bird{bird}", "pose", d, now))
        return samples

    def _whole_records(self, records):
        """Group-mode birds held until their record is whole: a read can end mid-record, and the
        birds of one record must reach the take together (not some before recording began)."""
        out = []
        for address, d in records:
            if self._held and address <= self._held[-1][0]:  # a bird was lost: a new record began
                out += self._held
                self._held = []
            self._held.append((address, d))
            if address == max(self.birds):
                out += self._held
                self._held = []
        return out

    def _close(self):
        ser, self._ser = self._ser, None
        if ser is not None:
            try:
                ser.write(POINT + SLEEP)
            except Exception:
                pass
            ser.close()


def default_motion(address, t):
    """A performer's sensor moving smoothly: position (m) and angles (deg) at device time t."""
    k = float(address)
    pos = np.array([0.3 * np.sin(0.7 * t + k), 0.2 * np.cos(0.5 * t + 0.3 * k), 0.1 * k + 0.05 * np.sin(1.3 * t)])
    angles = np.array([150.0 * np.sin(0.4 * t + k), 60.0 * np.sin(0.3 * t + 0.5 * k), 170.0 * np.cos(0.6 * t + k)])
    return pos, angles


class FlockSimulator(PtySimulator):
    """A flock answering the guide's commands on a pseudo-terminal: auto-configuration,
    RS232 TO FBB, record formats per bird, hemisphere, group mode, point and stream, EXAMINE
    VALUE of status, model, scaling, error code and flock status. Motion comes from
    `motion(address, t)`; every streamed tick is logged in `sent` as (tick, perf_counter)."""

    def __init__(self, birds=(1,), extended_range=False, rate=100.0, speed=1.0, motion=default_motion,
                 standalone=False):
        self.birds = tuple(birds)
        self.extended_range = extended_range
        self.motion = motion
        self.standalone = standalone
        self.sent = []
        self.tick_count = 0
        super().__init__("fob", rate, speed)
        self.on_power_up()

    @property
    def range_inches(self):
        if self.extended_range:
            return RANGES_INCHES["EXTENDED"]
        return RANGES_INCHES["STANDARD_72" if self.scaling else "STANDARD"]

    def on_power_up(self):
        self.streaming = False
        self.formats = {b: "POSITION/ANGLES" for b in self.birds}
        self.hemispheres = {b: "FORWARD" for b in self.birds}
        self.group = False
        self.configured = 0 if not self.standalone else 1
        self.error = 0
        self.scaling = 0
        self._pending = bytearray()
        self._target = None

    def true_pose(self, address, tick):
        return self.motion(address, tick / self.rate)

    def _records(self, tick, addresses):
        out = bytearray()
        for b in addresses:
            pos, ang = self.true_pose(b, tick)
            out += encode_record(self.formats[b], pos, ang, self.range_inches, b if self.group else None)
        return bytes(out)

    def _active(self):
        return [b for b in self.birds if b <= self.configured] if self.group else [self._target or self.birds[0]]

    def tick(self, now):
        self.sent.append((self.tick_count, now))
        self.send(self._records(self.tick_count, self._active()))
        self.tick_count += 1

    def on_bytes(self, data):
        self._pending.extend(data)
        while self._pending:
            if not self._command():
                break

    def _command(self):
        """Consume one complete command from the pending bytes; False when it needs more."""
        p = self._pending
        c = p[0]
        if RS232_TO_FBB < c <= RS232_TO_FBB + 14:
            if len(p) < 2:
                return False
            self._target = c - RS232_TO_FBB
            del p[0]
            if self._target not in self.birds:
                self.error = 13
            return True
        target = self._target or self.birds[0]
        if c in COMMAND_RECORD:
            del p[0]
            if target in self.formats:
                self.formats[target] = COMMAND_RECORD[c]
            self._target = None
            return True
        if c == HEMISPHERE[0]:
            if len(p) < 3:
                return False
            axis_sign = (p[1], p[2])
            names = {v: k for k, v in HEMISPHERES.items()}
            if axis_sign in names and target in self.hemispheres:
                self.hemispheres[target] = names[axis_sign]
            else:
                self.error = 6
            del p[:3]
            self._target = None
            return True
        if c == CHANGE_VALUE[0]:
            if len(p) < 2:
                return False
            param = p[1]
            size = PARAM_SIZES.get(param, 1)
            if len(p) < 2 + size:
                return False
            value = bytes(p[2:2 + size])
            del p[:2 + size]
            if param == PARAM_GROUP_MODE:
                self.group = bool(value[0])
            elif param == PARAM_AUTOCONFIG:
                self.configured = value[0]
            elif param == PARAM_POSITION_SCALING:
                self.scaling = value[0] | value[1] << 8
            else:
                self.error = 6
            return True
        if c == EXAMINE_VALUE[0]:
            if len(p) < 2:
                return False
            param = p[1]
            del p[:2]
            self.send(self._examine(param))
            return True
        del p[0]
        self._target = None
        if c == POINT[0]:
            self.streaming = False
            self.send(self._records(self.tick_count, self._active()))
            self.tick_count += 1
        elif c == STREAM[0]:
            self.streaming = True
        elif c in (RUN[0], SLEEP[0]):
            self.streaming = False
        else:
            self.error = 6  # Invalid RS232 command
        return True

    def _examine(self, param):
        if param == PARAM_ERROR_CODE:
            code, self.error = self.error, 0
            return bytes([code])
        if param == PARAM_MODEL:
            return (b"6DERC" if self.extended_range else b"6DFOB").ljust(10)
        if param == PARAM_POSITION_SCALING:
            return bytes([self.scaling & 0xFF, self.scaling >> 8])
        if param == PARAM_SYSTEM_STATUS:
            status = bytearray(14)
            for a in range(1, self.configured + 1):
                status[a - 1] = STATUS_ACCESSIBLE | STATUS_RUNNING | (STATUS_RECEIVER if a in self.birds else 0)
            return bytes(status)
        if param == PARAM_GROUP_MODE:
            return bytes([int(self.group)])
        if param == PARAM_HEMISPHERE:
            return bytes(HEMISPHERES[self.hemispheres[self.birds[0]]])
        if param in PARAM_SIZES:
            return bytes(PARAM_SIZES[param])
        self.error = 6
        return b""
