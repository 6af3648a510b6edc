"""A Flock of Birds on a pseudo-terminal, written from Ascension's "Flock of Birds Installation
and Operation Guide" and independently of the driver in fob.py (it imports nothing from it: the
record encoding, the orientation outputs and the command table are written here again, so a
misreading in one is caught by the other).

What it models (guide section in brackets):
- the RS-232 command bytes (RS-232 Commands): POINT 'B', STREAM '@', RUN 'F', SLEEP 'G',
  CHANGE VALUE 'P', EXAMINE VALUE 'O', HEMISPHERE 'L', the seven record-format commands, and
  RS232 TO FBB (0xF0 + address, normal addressing) that sends the next command to one bird;
- the power-up state (Power-up / Auto-configuration): no bird runs until the master receives
  CHANGE VALUE FBB AUTO-CONFIGURATION (parameter 50) with the number of units; records are
  POSITION/ANGLES, hemisphere FORWARD, group mode off, not streaming; a standalone bird
  (no Fast Bird Bus) runs at power-up;
- SLEEP turns the transmitter off: data requests are ignored until RUN (SLEEP/RUN);
- GROUP MODE (CHANGE VALUE 35): one POINT or STREAM to the master gives the records of every
  running bird with a receiver, each followed by its FBB address byte; it persists until it
  is changed or the flock powers down (Group Mode);
- without group mode, a data request goes to the bird the RS232 TO FBB prefix names, or to
  the master (address 1) without it; an Extended Range Controller is the master at address 1
  and has no receiver, so its birds start at address 2 (Extended Range Controller);
- EXAMINE VALUE of bird status (0), position scaling (3), error code (10, cleared by reading),
  model (15: "6DFOB" or "6DERC"), group mode (35) and flock system status (36: one byte per
  address, bit 7 accessible, bit 6 running, bit 5 has a receiver, bit 4 is an ERT);
- the record formats and scaling (Data Records): 14-bit words sent LSbyte then MSbyte, 7 bits
  each, the phasing bit 7 set only on the first byte of a record; positions to +-36 in
  (+-72 in with POSITION SCALING 1, +-144 in on an Extended Range Controller), angles to
  +-180 deg, matrix elements and quaternions to +-1;
- the orientation outputs (ANGLES, MATRIX, QUATERNION commands): azimuth, elevation and roll;
  the matrix M whose first row is (cos E cos A, cos E sin A, -sin E), sent column by column;
  and the quaternion q0 (scalar), q1, q2, q3 "extracted from the MATRIX output" (Shepperd's
  algorithm), i.e. the quaternion whose rotation matrix is M.

Faults for tests and the soak: `inject()` (bytes on the line), `cut()` (the next n bytes
lost), `power_cycle()` (power-up state, the line kept), and the base's unplug/replug."""

import numpy as np

from .pty_sim import PtySimulator

# command bytes (RS-232 Commands)
_POINT, _STREAM, _RUN, _SLEEP = 0x42, 0x40, 0x46, 0x47
_CHANGE, _EXAMINE, _HEMI = 0x50, 0x4F, 0x4C
_FORMATS = {0x56: "POSITION", 0x57: "ANGLES", 0x58: "MATRIX", 0x59: "POSITION/ANGLES",
            0x5A: "POSITION/MATRIX", 0x5C: "QUATERNION", 0x5D: "POSITION/QUATERNION"}
_FBB = 0xF0
# CHANGE VALUE value sizes (Change Value / Examine Value tables)
_CHANGE_SIZE = {3: 2, 35: 1, 50: 1}
_HEMI_CODES = {(0x00, 0x00): "FORWARD", (0x00, 0x01): "AFT", (0x0C, 0x01): "UPPER",
               (0x0C, 0x00): "LOWER", (0x06, 0x01): "LEFT", (0x06, 0x00): "RIGHT"}
_ERR_INVALID, _ERR_NOT_INIT, _ERR_NO_RESPONSE = 6, 9, 13
_INCH = 0.0254


def words(values, full_scale):
    """Values to the guide's wire form: value / full_scale * 0x8000 as a 16-bit two's-complement
    integer, its top 14 bits sent as LSbyte (bits 2-8) and MSbyte (bits 9-15)."""
    out = bytearray()
    for v in values:
        n = int(np.clip(round(float(v) / full_scale * 32768.0), -32768, 32767)) & 0xFFFF
        out.append((n >> 2) & 0x7F)
        out.append((n >> 9) & 0x7F)
    out[0] |= 0x80  # the phasing bit: the first byte of a record
    return bytes(out)


def matrix_m(azimuth, elevation, roll):
    """The guide's MATRIX output from the angles (degrees)."""
    a, e, r = np.radians([azimuth, elevation, roll])
    ca, sa, ce, se, cr, sr = np.cos(a), np.sin(a), np.cos(e), np.sin(e), np.cos(r), np.sin(r)
    return np.array([
        [ce * ca, ce * sa, -se],
        [-cr * sa + sr * se * ca, cr * ca + sr * se * sa, sr * ce],
        [sr * sa + cr * se * ca, -sr * ca + cr * se * sa, cr * ce]])


def quaternion_of(m):
    """Shepperd's algorithm: the unit quaternion (q0 scalar first, q0 >= 0) whose rotation
    matrix [[q0²+q1²-q2²-q3², 2(q1q2-q0q3), 2(q1q3+q0q2)], ...] is m."""
    t = np.trace(m)
    cand = [1 + t, 1 + 2 * m[0, 0] - t, 1 + 2 * m[1, 1] - t, 1 + 2 * m[2, 2] - t]
    i = int(np.argmax(cand))
    q = np.empty(4)
    q[i] = 0.5 * np.sqrt(cand[i])
    f = 0.25 / q[i]
    if i == 0:
        q[1], q[2], q[3] = (m[2, 1] - m[1, 2]) * f, (m[0, 2] - m[2, 0]) * f, (m[1, 0] - m[0, 1]) * f
    elif i == 1:
        q[0], q[2], q[3] = (m[2, 1] - m[1, 2]) * f, (m[0, 1] + m[1, 0]) * f, (m[0, 2] + m[2, 0]) * f
    elif i == 2:
        q[0], q[1], q[3] = (m[0, 2] - m[2, 0]) * f, (m[0, 1] + m[1, 0]) * f, (m[1, 2] + m[2, 1]) * f
    else:
        q[0], q[1], q[2] = (m[1, 0] - m[0, 1]) * f, (m[0, 2] + m[2, 0]) * f, (m[1, 2] + m[2, 1]) * f
    return q if q[0] >= 0 else -q


def record(fmt, position_m, angles_deg, range_inches):
    """One data record as a bird sends it for a sensor at `position_m` (metres, transmitter
    frame) with orientation `angles_deg` (azimuth, elevation, roll)."""
    values, scales = [], []
    if fmt.startswith("POSITION"):
        values += list(np.asarray(position_m, float) / _INCH)
        scales += [range_inches] * 3
    if fmt.endswith("ANGLES"):
        values += list(angles_deg)
        scales += [180.0] * 3
    elif fmt.endswith("MATRIX"):
        values += list(matrix_m(*angles_deg).flatten(order="F"))  # M11, M21, M31, M12, ...
        scales += [1.0] * 9
    elif fmt.endswith("QUATERNION"):
        values += list(quaternion_of(matrix_m(*angles_deg)))
        scales += [1.0] * 4
    out = bytearray()
    for v, s in zip(values, scales):
        out += words([v], s)
    for k in range(2, len(out), 2):
        out[k] &= 0x7F  # only the record's first byte keeps the phasing bit
    return bytes(out)


def default_motion(address, t):
    """A performer's sensor moving smoothly: position (m) and angles (deg) at device time t."""
    k = float(address)
    pos = np.array([0.3 * np.sin(0.7 * t + k), 0.2 * np.cos(0.5 * t + 0.3 * k), 0.1 * k + 0.05 * np.sin(1.3 * t)])
    angles = np.array([150.0 * np.sin(0.4 * t + k), 60.0 * np.sin(0.3 * t + 0.5 * k), 170.0 * np.cos(0.6 * t + k)])
    return pos, angles


class FlockSimulator(PtySimulator):
    """`birds`: FBB addresses with a receiver; `extended_range`: an Extended Range Controller
    is the master at address 1 (no receiver); `standalone`: one bird without the Fast Bird Bus.
    Motion comes from `motion(address, t)` (device time t = tick / rate). Every streamed tick is
    logged in `sent` as (tick, perf_counter); `ticks_with_data` counts ticks that sent records."""

    def __init__(self, birds=(1,), extended_range=False, rate=100.0, speed=1.0, motion=default_motion,
                 standalone=False):
        self.birds = tuple(sorted(birds))
        if extended_range and 1 in self.birds:
            raise ValueError("an Extended Range Controller is address 1: its birds start at 2")
        if standalone and len(self.birds) != 1:
            raise ValueError("a standalone bird is a single bird")
        self.extended_range, self.standalone, self.motion = extended_range, standalone, motion
        self.units = (1,) + self.birds if extended_range else self.birds
        self.sent = []
        self.tick_count = 0
        self.power_ups = 0
        super().__init__("fob", rate, speed)
        self.on_power_up()

    # -- state ------------------------------------------------------------------------------
    def on_power_up(self):
        self.power_ups += 1
        self.streaming = False
        self.asleep = False
        self.configured = 1 if self.standalone else 0  # units running after auto-configuration
        self.group = False
        self.formats = {b: "POSITION/ANGLES" for b in self.birds}
        self.hemispheres = {b: "FORWARD" for b in self.birds}
        self.scaling = 0
        self.error = 0
        self.stream_target = None
        self._target = None
        self._pending = bytearray()

    @property
    def master(self):
        return self.units[0]

    @property
    def range_inches(self):
        if self.extended_range:
            return 144.0
        return 72.0 if self.scaling else 36.0

    def running(self, address):
        return not self.asleep and address in self.units and self.units.index(address) < self.configured

    def group_birds(self):
        return [b for b in self.birds if self.running(b)]

    def true_pose(self, address, tick):
        return self.motion(address, tick / self.rate)

    # -- data -------------------------------------------------------------------------------
    def records(self, tick, target):
        """The bytes one data request produces at `tick`: every group bird with its address, or
        the target bird's record; b'' when nothing answers."""
        if self.asleep:
            return b""
        if not self.standalone and self.configured == 0:
            self.error = _ERR_NOT_INIT
            return b""
        out = bytearray()
        if self.group:
            for b in self.group_birds():
                pos, ang = self.true_pose(b, tick)
                out += record(self.formats[b], pos, ang, self.range_inches) + bytes([b])
            return bytes(out)
        if target not in self.birds or not self.running(target):
            self.error = _ERR_NO_RESPONSE
            return b""
        pos, ang = self.true_pose(target, tick)
        return record(self.formats[target], pos, ang, self.range_inches)

    def tick(self, now):
        data = self.records(self.tick_count, self.stream_target)
        self.sent.append((self.tick_count, now))
        self.send(data)
        self.tick_count += 1

    # -- commands ---------------------------------------------------------------------------
    def on_bytes(self, data):
        self._pending.extend(data)
        while self._pending and self._command():
            pass

    def _command(self):
        """Consume one complete command; False when it needs more bytes."""
        p = self._pending
        c = p[0]
        if _FBB < c <= _FBB + 14:
            del p[0]
            if self.standalone:
                self.error = _ERR_INVALID
            else:
                self._target = c - _FBB
            return True
        target = self._target if self._target is not None else self.master
        if c == _HEMI or c == _CHANGE:
            need = 3 if c == _HEMI else 2 + _CHANGE_SIZE.get(p[1], 1) if len(p) > 1 else 2
            if len(p) < need:
                return False
        elif c == _EXAMINE and len(p) < 2:
            return False
        self._target = None
        if c != _EXAMINE and c != _CHANGE:
            self.streaming = False  # any other command ends STREAM mode
        if c in _FORMATS:
            del p[0]
            if target in self.formats:
                self.formats[target] = _FORMATS[c]
            else:
                self.error = _ERR_NO_RESPONSE
        elif c == _HEMI:
            code = (p[1], p[2])
            del p[:3]
            if code in _HEMI_CODES and target in self.hemispheres:
                self.hemispheres[target] = _HEMI_CODES[code]
            else:
                self.error = _ERR_INVALID
        elif c == _CHANGE:
            self._change(p[1], bytes(p[2:2 + _CHANGE_SIZE.get(p[1], 1)]))
            del p[:2 + _CHANGE_SIZE.get(p[1], 1)]
        elif c == _EXAMINE:
            param = p[1]
            del p[:2]
            self.send(self._examine(param))
        elif c == _POINT:
            del p[0]
            self.send(self.records(self.tick_count, target))
            self.tick_count += 1
        elif c == _STREAM:
            del p[0]
            if not self.asleep:
                self.streaming, self.stream_target = True, target
        elif c == _SLEEP:
            del p[0]
            self.asleep = True
        elif c == _RUN:
            del p[0]
            self.asleep = False
        else:
            del p[0]
            self.error = _ERR_INVALID
        return True

    def _change(self, param, value):
        if param == 35:
            self.group = bool(value[0])
        elif param == 50:
            n = value[0]
            if self.standalone or not 1 <= n <= len(self.units):
                self.error = _ERR_INVALID
            else:
                self.configured = n
        elif param == 3:
            self.scaling = value[0] | value[1] << 8
        else:
            self.error = _ERR_INVALID

    def _examine(self, param):
        if param == 10:
            code, self.error = self.error, 0
            return bytes([code])
        if param == 0:
            return bytes([0x00 if self.asleep else 0x01, 0x80 if self.streaming else 0x00])
        if param == 3:
            return bytes([self.scaling & 0xFF, self.scaling >> 8])
        if param == 15:
            return (b"6DERC" if self.extended_range else b"6DFOB").ljust(10)
        if param == 35:
            return bytes([int(self.group)])
        if param == 36:
            status = bytearray(14)
            for k, a in enumerate(self.units):
                s = 0x80
                if self.running(a):
                    s |= 0x40
                if a in self.birds:
                    s |= 0x20
                if self.extended_range and a == 1:
                    s |= 0x10
                status[a - 1] = s
            return bytes(status)
        self.error = _ERR_INVALID
        return b""
