"""Xsens MVN real-time network streaming (UDP) as a device of the live session.

Source: Xsens, "MVN real-time network streaming Protocol Specification" (revision N, 2018);
section numbers below are that document's.

- Datagrams are UDP, default port 9763 (2.3), big-endian (2.5.11). Each starts with a 24-byte
  header (2.4.1): ID string "MXTP" + the two-character message type (2.4.1.1), sample counter
  u32 (2.4.1.2), datagram counter u8 (bit 7 set on the last datagram of a sample, the low 7
  bits its index: 0x80 when the sample fits one datagram, 2.4.1.3), number of items u8
  (2.4.1.4), time code u32 in ms (2.4.1.5), character ID u8 (2.4.1.6: one per actor, several
  actors each send their own datagrams), body segments u8 (23), props u8 (0-4), finger
  tracking segments u8 (0 or 40), 2 reserved bytes, payload size u16 (2.4.1.11: used to skip
  message types we do not read).
- Pose data, quaternion (type 02, 2.5.3): per item a segment ID (i32) then position x, y, z and
  the rotation quaternion q1 (re), q2 (i), q3 (j), q4 (k) as 32-bit floats, 32 bytes; Z-up,
  right-handed; positions in cm (2.5.6); the quaternion is normalised, sign free (2.5.8).
  Items come as body segments, props, left then right hand fingers (2.5.1); segment IDs are
  the index + 1 of Table 1 (3.1).
- Meta data (type 12, 2.6.1): "tag:value" lines; 'name' names the actor.
- The sample counter grows by one for every sample sent (2.4.1.2): a jump is samples lost on
  the network; a sample split over several datagrams (2.4.1.3) is put together before use and
  counted lost when a part never came.

Every segment of every actor becomes a 'pose' sample on channel "actor<ID>/<Segment>" holding
its position (m) and orientation (w, x, y, z) in MVN's Z-up world, marked frame 'z_up'
(samples.tracker_reading turns it into the converter's tracker convention), so MVN takes the
same calibration (the anatomical converter, performer in the rig's rest pose), recording,
reconnection and counters as the Flock of Birds. Types 01 (Euler, whose rotation order the
specification does not define), 03, 05 and 20-25 are skipped by their payload size (counted
in `skipped`, not as garbage)."""

import struct

import numpy as np

from .device import DatagramDevice

DEFAULT_PORT = 9763
HEADER = struct.Struct(">6sIBBIBBBB2sH")
# a sample counter this far behind the last one is a datagram late on the network (discarded);
# further behind, the sender started counting again (MVN restarted, or a new recording)
REORDER_WINDOW = 16
ITEM_QUATERNION = struct.Struct(">i7f")
# Table 1 (3.1): index -> name; the segment ID sent is index + 1
SEGMENTS = ("Pelvis", "L5", "L3", "T12", "T8", "Neck", "Head", "RightShoulder", "RightUpperArm", "RightForearm",
            "RightHand", "LeftShoulder", "LeftUpperArm", "LeftForearm", "LeftHand", "RightUpperLeg",
            "RightLowerLeg", "RightFoot", "RightToe", "LeftUpperLeg", "LeftLowerLeg", "LeftFoot", "LeftToe")
# body segments to the rig's body roles (the converter shares turns along the spine's other bones)
SEGMENT_ROLES = {"Pelvis": "pelvis", "L5": "spine", "T8": "chest", "Neck": "neck", "Head": "head"}
for _side, _s in (("Right", "R"), ("Left", "L")):
    SEGMENT_ROLES.update({f"{_side}Shoulder": f"clavicle.{_s}", f"{_side}UpperArm": f"upper_arm.{_s}",
                          f"{_side}Forearm": f"forearm.{_s}", f"{_side}Hand": f"hand.{_s}",
                          f"{_side}UpperLeg": f"thigh.{_s}", f"{_side}LowerLeg": f"shin.{_s}",
                          f"{_side}Foot": f"foot.{_s}", f"{_side}Toe": f"toe.{_s}"})


class Datagram:
    __slots__ = ("kind", "sample", "index", "last", "items", "time_code", "actor", "body", "props", "fingers",
                 "payload")


def parse_header(data):
    """A Datagram with the header's fields, or None when `data` is not an MVN datagram."""
    if len(data) < HEADER.size:
        return None
    ident, sample, counter, items, time_code, actor, body, props, fingers, _, size = HEADER.unpack_from(data)
    if ident[:4] != b"MXTP" or not ident[4:].isdigit() or len(data) != HEADER.size + size:
        return None
    d = Datagram()
    d.kind, d.sample, d.index, d.last = ident[4:].decode(), sample, counter & 0x7F, bool(counter & 0x80)
    d.items, d.time_code, d.actor, d.body, d.props, d.fingers = items, time_code, actor, body, props, fingers
    d.payload = data[HEADER.size:]
    return d


def segment_name(segment_id, props=0):
    """The name of a segment ID of the quaternion protocol (3.1, Tables 1 and 2). Table 1 lists
    Prop1-4 at indexes 24-27, but Table 2 puts the left carpus at index 23 + prop count: the
    props follow the body segments directly (indexes 23.., IDs 24..) in the only reading where
    the two tables do not collide, and the data order of 2.5.1 says the same."""
    index = segment_id - 1
    if 0 <= index < len(SEGMENTS):
        return SEGMENTS[index]
    if 23 <= index < 23 + props:
        return f"Prop{index - 22}"
    finger = index - 23 - props
    if 0 <= finger < 40:
        return f"{'Left' if finger < 20 else 'Right'}Finger{finger % 20}"
    return None


def parse_pose_quaternion(d):
    """{segment name: (position m, quaternion w,x,y,z)} of a type-02 datagram; None when the
    payload is not that (wrong size, unknown segment, not a unit quaternion, not finite)."""
    if len(d.payload) != d.items * ITEM_QUATERNION.size:
        return None
    values = np.frombuffer(d.payload, dtype=">f4").reshape(d.items, 8)
    ids = np.frombuffer(d.payload, dtype=">i4").reshape(d.items, 8)[:, 0]
    xyz, quats = values[:, 1:4].astype(float) / 100.0, values[:, 4:8].astype(float)
    if not (np.all(np.isfinite(xyz)) and np.all(np.isfinite(quats))):
        return None
    norms = np.linalg.norm(quats, axis=1)
    if np.any(np.abs(norms - 1.0) > 1e-3):
        return None
    quats /= norms[:, None]
    out = {}
    for seg, p, q in zip(ids.tolist(), xyz, quats):
        name = segment_name(seg, d.props)
        if name is None or name in out:
            return None
        out[name] = (p, q)
    return out


def channel(actor, segment):
    """The session channel of one actor's segment (stable: the actor's name comes later, with
    the meta data)."""
    return f"actor{actor}/{segment}"


def parse_meta(d):
    text = d.payload.decode("utf-8", "replace")
    return dict(line.split(":", 1) for line in text.splitlines() if ":" in line)


class MVNReceiver(DatagramDevice):
    """Listens on host:port for MVN datagrams of any number of actors."""

    kind = "mvn"
    what = "MVN datagrams"

    def __init__(self, name, host="127.0.0.1", port=DEFAULT_PORT, timeout=0.05, watchdog=1.0, **kw):
        super().__init__(name, host, port, timeout, watchdog, **kw)
        self.actors = {}  # character ID -> name (meta data) or "actor<ID>"
        self.skipped = 0  # datagrams of message types not read (by their payload size)
        self._last_sample = {}  # actor -> last complete sample counter
        self._parts = {}  # actor -> (sample counter, {index: segments}, last index or None)

    def _datagram(self, data, now):
        d = parse_header(data)
        if d is None:
            return self._garbage(data, "not an MVN datagram")
        if d.kind == "12":
            self.actors[d.actor] = parse_meta(d).get("name", self.actors.get(d.actor, f"actor{d.actor}")).strip()
            return []
        if d.kind != "02":
            self.skipped += 1
            return []
        segments = parse_pose_quaternion(d)
        if segments is None:
            return self._garbage(data, "a pose datagram that does not hold what its header says")
        self.resyncing = False
        whole = self._assemble(d, segments)
        if whole is None:
            return []
        self.actors.setdefault(d.actor, f"actor{d.actor}")
        info = {"frame": "z_up", "sample_counter": d.sample, "time_code": d.time_code, "actor": d.actor}
        return [self.make_sample(channel(d.actor, seg), "pose", dict(info, position=p, quaternion=q), now)
                for seg, (p, q) in whole.items()]

    def _garbage(self, data, why):
        self.discarded_bytes += len(data)
        self.resyncs += 1
        self.last_error = f"{self.name}: {why} ({len(data)} bytes discarded)"
        return []

    def _assemble(self, d, segments):
        """The whole sample once its last datagram is in, else None; counts samples lost (a gap
        in the sample counter, or a part that never came) and drops stale or repeated ones."""
        last = self._last_sample.get(d.actor)
        if last is not None:
            ahead = (d.sample - last) & 0xFFFFFFFF
            if ahead == 0 or ahead > 0x80000000:
                if ahead and (last - d.sample) & 0xFFFFFFFF > REORDER_WINDOW:  # the sender restarted its counter
                    self._last_sample.pop(d.actor)
                    self._parts.pop(d.actor, None)
                else:  # late or repeated: that sample was already used or counted
                    self.discarded_bytes += HEADER.size + len(d.payload)
                    return None
        pending = self._parts.get(d.actor)
        if pending is not None and pending[0] != d.sample:
            pending = None  # a split sample that never completed: the counter's gap counts it
        if pending is None:
            pending = (d.sample, {}, None)
        sample, parts, final = pending
        if d.index in parts:  # the same part twice
            self.discarded_bytes += HEADER.size + len(d.payload)
            return None
        parts[d.index] = segments
        final = d.index if d.last else final
        if final is None or len(parts) < final + 1:
            self._parts[d.actor] = (sample, parts, final)
            return None
        self._parts.pop(d.actor, None)
        last = self._last_sample.get(d.actor)
        if last is not None:
            self.lost += ((d.sample - last) & 0xFFFFFFFF) - 1
        self._last_sample[d.actor] = d.sample
        whole = {}
        for k in sorted(parts):
            whole.update(parts[k])
        return whole
