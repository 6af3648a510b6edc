"""Ascension Flock of Birds over RS-232: commands, the binary record format and the driver.
The simulator is in sim_fob.py, written separately from the same guide.

Protocol source: Ascension Technology, "The Flock of Birds Installation and Operation Guide"
(the guide itself is not in our reference library; the command table, record formats and
orientation definitions below follow its text as quoted by Ascension's laserBIRD guide of the
same protocol family and by the public drivers that implement it: VRPN vrpn_Tracker_Flock,
libflock, Atamai's flock.c).

- RS-232 Commands: POINT 'B', STREAM '@', RUN 'F', SLEEP 'G', CHANGE VALUE 'P', EXAMINE VALUE
  'O', HEMISPHERE 'L', the record-format commands, and RS232 TO FBB (0xF0 + FBB address,
  normal addressing) that sends the next command to one bird of the flock.
- Data Records: every value is a 14-bit two's-complement word sent as two bytes, the least
  significant first, 7 data bits each; bit 7 (the phasing bit) is set only on the first byte
  of a record. The word is ((MSbyte << 7) | (LSbyte & 0x7F)) << 2 as a signed 16-bit integer,
  +-full scale at +-32768: positions to +-36 in (72 in with POSITION SCALING 1, 144 in with an
  Extended Range Controller), angles to +-180 deg, matrix elements and quaternions to +-1. In
  group mode each bird's record is followed by its FBB address byte.
- Orientation (ANGLES, MATRIX, QUATERNION commands): azimuth A (about Z), elevation E (about Y)
  and roll R (about X) of the sensor in the transmitter's frame (X forward, Y right, Z down).
  The MATRIX output M has first row (cos E cos A, cos E sin A, -sin E): M is the transpose of
  Rz(A) Ry(E) Rx(R) and maps transmitter axes to sensor axes; it is sent column by column
  (M11, M21, M31, M12, ...). The QUATERNION output q0 (scalar), q1, q2, q3 is "extracted from
  the MATRIX output" (Shepperd's algorithm): the quaternion of M.

One convention for every format (`decode_record`): a sample's 'quaternion' (w, x, y, z) is the
sensor's orientation in the transmitter frame, the rotation Rz(A) Ry(E) Rx(R) = M^T that takes
sensor axes to transmitter axes; a QUATERNION record is therefore conjugated. Test:
tests/devices/test_capture_fob.py::test_every_format_gives_one_rotation_for_the_same_pose.

Connecting from any state (`FlockOfBirds._open`, every connect and reconnect): POINT (ends a
stream), RUN (wakes a flock left asleep, e.g. by our own disconnect), the stale error code
read away, FBB AUTO-CONFIGURATION with the number of units (a power-up needs it; the guide
asks for a pause of at least 300 ms around it), the flock status checked for every bird,
GROUP MODE set explicitly on (several birds) or off (one bird: a flock left in group mode
would stream every bird), record format and hemisphere sent to each bird through RS232 TO
FBB, the error code checked, then STREAM or POINT to the master (group mode) or through
RS232 TO FBB to the one bird (its address need not be 1, e.g. behind an Extended Range
Controller, which is the master at address 1 without a receiver)."""

import time

import numpy as np

from ...solver import rotations
from .device import Device, DeviceError, open_serial

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
        out["quaternion"] = rotations.conjugate(rotations.normalize(w[:4]))  # the quaternion of M = rot^T
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
    bytes has bit 7 set, its address byte (group mode) is one of `addresses`, and a quaternion
    or matrix is a rotation. A rejected candidate is dropped one byte at a time, so a real
    record hidden behind a partial one is still found.

    Counters, kept apart because they mean different things: `discarded_bytes` (bytes that
    belonged to no accepted record), `resyncs` (how many times the stream lost its framing and
    found it again) and `rejected` (candidates that failed the checks: not records lost, a
    record's bytes can make several candidates)."""

    def __init__(self, fmt, range_inches, addresses=None):
        self.fmt = fmt
        self.range_inches = range_inches
        self.addresses = None if addresses is None else set(addresses)
        self.size = record_size(fmt, addresses is not None)
        self.buf = bytearray()
        self.discarded_bytes = 0
        self.resyncs = 0
        self.rejected = 0
        self.resyncing = False

    def _lose_sync(self):
        if not self.resyncing:
            self.resyncing = True
            self.resyncs += 1

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
                self.discarded_bytes += i - start
                self._lose_sync()
            if n - i < size:
                break
            decoded = self._check(bytes(buf[i:i + size]))
            if decoded is None:
                self.rejected += 1
                self.discarded_bytes += 1
                self._lose_sync()
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
    """A flock on one RS-232 port: a standalone bird, or birds on the Fast Bird Bus addressed
    through the master (RS232 TO FBB), in group mode when more than one is read.

    `birds`: FBB addresses of the birds read; `units`: how many units the flock auto-configures
    (default: the highest address; an Extended Range Controller is unit 1); `mode`: 'STREAM'
    or 'POINT'. Every connect and reconnect brings the flock from any state to this one (see
    the module docstring)."""

    kind = "flock_of_birds"

    def __init__(self, name, port, baud=115200, birds=(1,), record="POSITION/QUATERNION", mode="STREAM",
                 hemisphere="FORWARD", standalone=False, units=None, settle=0.3, timeout=0.05, watchdog=1.0,
                 **kw):
        super().__init__(name, **kw)
        if record not in RECORDS:
            raise DeviceError(f"unknown Flock of Birds record '{record}' (one of {', '.join(RECORDS)})")
        if hemisphere not in HEMISPHERES:
            raise DeviceError(f"unknown hemisphere '{hemisphere}' (one of {', '.join(HEMISPHERES)})")
        birds = tuple(sorted(int(b) for b in birds))
        if not birds or len(set(birds)) != len(birds) or not all(1 <= b <= 14 for b in birds):
            raise DeviceError(f"Flock of Birds addresses are 1..14, each once (not {birds})")
        if standalone and len(birds) != 1:
            raise DeviceError("a standalone bird is a single bird")
        self.port, self.baud, self.birds = port, baud, birds
        self.record, self.mode, self.hemisphere = record, mode.upper(), hemisphere
        self.standalone, self.units = standalone, units or max(self.birds)
        self.settle, self.timeout, self.watchdog = settle, timeout, watchdog
        self.group = len(self.birds) > 1
        self.range_inches = None
        self.model = ""
        self._ser = None
        self._parser = None
        self._last_data = 0.0
        self._order = self.birds  # the group-mode birds in the order their records come
        self._held = []
        self._last_address = None

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

    def _quiet(self):
        time.sleep(self.settle)
        self._ser.reset_input_buffer()

    # -- the device ---------------------------------------------------------------------------
    def _open(self):
        self._ser = open_serial(self.port, self.baud, self.timeout)
        self._write(POINT)  # a flock left streaming stops (and answers one record, flushed)
        self._write(RUN)  # a flock left asleep wakes; an awake one ignores it
        self._quiet()
        self.error_code()  # an error left from before this session is read away (reading clears it)
        if not self.standalone:
            self.change(PARAM_AUTOCONFIG, [self.units])  # also what a flock needs after a power-up
            self._quiet()
            code = self.error_code()
            if code:
                raise DeviceError(f"{self.name}: the flock cannot auto-configure {self.units} units (error {code}: "
                                  f"{ERRORS.get(code, 'unknown error')}); is every unit up to address "
                                  f"{self.units} switched to FLY?")
            status = self.examine(PARAM_SYSTEM_STATUS)
            for b in self.birds:
                s = status[b - 1]
                if not (s & STATUS_ACCESSIBLE and s & STATUS_RUNNING and s & STATUS_RECEIVER):
                    raise DeviceError(f"{self.name}: bird {b} is not accessible, running and with a sensor "
                                      f"(flock status 0x{s:02x})")
            # a group-mode record holds every running bird with a receiver, in address order
            self._order = tuple(a for a in range(1, self.units + 1)
                                if status[a - 1] & STATUS_RUNNING and status[a - 1] & STATUS_RECEIVER)
            self.change(PARAM_GROUP_MODE, [1 if self.group else 0])  # set either way: it persists
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
        code = self.error_code()
        if code:
            raise DeviceError(f"{self.name}: flock error {code}: {ERRORS.get(code, 'unknown error')}")
        self._parser = self._new_parser(RecordParser(self.record, self.range_inches, self._order if self.group else None))
        self._held, self._last_address = [], None
        if self.mode == "STREAM":
            self._write(self._request(STREAM))
        self._last_data = time.perf_counter()

    def _request(self, command):
        """A data request: to the master in group mode or for a standalone bird, else through
        RS232 TO FBB to the one bird (without the prefix the master answers, and the master is
        not our bird when it sits at another address or is an Extended Range Controller)."""
        return command if self.group or self.standalone else self._to(self.birds[0]) + command

    def _read(self):
        if self.mode == "POINT":
            self._write(self._request(POINT))
            want = self._parser.size * (len(self._order) if self.group else 1)
            data = self._ser.read(want)
        else:
            data = self._read_stream(self._parser.size * len(self._order) if self.group else None)
        now = time.perf_counter()
        records = self._records(data, now)
        if records is None:
            return []
        if self.group:
            records = self._whole_records(records)
        samples = []
        for address, d in records:
            bird = self.birds[0] if address is None else address
            if bird in self.birds:  # a running bird we were not asked for is not a sample
                samples.append(self.make_sample(f"bird{bird}", "pose", d, now))
        return samples

    def _whole_records(self, records):
        """Group-mode birds held until their tick is whole: a read can end mid-record, and the
        birds of one tick must reach the take together. A bird missing between two that arrive
        (in the cyclic address order) is a record known lost."""
        out, order = [], self._order
        for address, d in records:
            if self._last_address is not None:
                gap = (order.index(address) - order.index(self._last_address) - 1) % len(order)
                self.lost += gap
            if self._held and address <= self._held[-1][0]:  # a new tick began
                out += self._held
                self._held = []
            self._held.append((address, d))
            self._last_address = address
            if address == order[-1]:
                out += self._held
                self._held = []
        return out

    def _close(self):
        ser, self._ser = self._ser, None
        if ser is not None:
            try:
                ser.write(POINT + SLEEP)  # transmitter off between sessions; the next connect sends RUN
            except Exception:
                pass
            ser.close()
