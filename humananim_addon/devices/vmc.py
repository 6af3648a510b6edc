"""The VMC (Virtual Motion Capture) protocol: OSC over UDP, sent by many current capture tools.
We listen on 127.0.0.1 (port 39539 by default, the performer side's usual port) for
/VMC/Ext/Root/Pos (name, position, quaternion), /VMC/Ext/Bone/Pos (Unity humanoid bone name,
position, quaternion), /VMC/Ext/Blend/Val (name, value) and /VMC/Ext/Blend/Apply.

VMC speaks Unity's left-handed, Y-up frame; samples are converted to Z-up right-handed
metres: (x, y, z) -> (-x, -z, y), and a rotation keeps its angle about the mapped axis
(quaternion (w, x, y, z) -> (w, x, z, -y))."""

import socket

import numpy as np

from .device import DatagramDevice
from .osc import OSCError, encode_bundle, encode_message, parse

DEFAULT_PORT = 39539

# Unity HumanBodyBones to the rig's body roles: (role, index along a chain role)
_SIDE = {"Left": "L", "Right": "R"}
HUMANOID_ROLES = {"Hips": ("pelvis", 0), "Spine": ("spine", 0), "Chest": ("chest", 0), "Neck": ("neck", 0),
                  "Head": ("head", 0)}
for _u, _s in _SIDE.items():
    HUMANOID_ROLES.update({f"{_u}Shoulder": (f"clavicle.{_s}", 0), f"{_u}UpperArm": (f"upper_arm.{_s}", 0),
                           f"{_u}LowerArm": (f"forearm.{_s}", 0), f"{_u}Hand": (f"hand.{_s}", 0),
                           f"{_u}UpperLeg": (f"thigh.{_s}", 0), f"{_u}LowerLeg": (f"shin.{_s}", 0),
                           f"{_u}Foot": (f"foot.{_s}", 0), f"{_u}Toes": (f"toe.{_s}", 0)})
    for _f, _r in (("Thumb", "thumb"), ("Index", "index"), ("Middle", "middle"), ("Ring", "ring"),
                   ("Little", "pinky")):
        for _k, _j in (("Proximal", 0), ("Intermediate", 1), ("Distal", 2)):
            HUMANOID_ROLES[f"{_u}{_f}{_k}"] = (f"{_r}.{_s}", _j)


def from_unity(position, quaternion_xyzw):
    x, y, z = position
    qx, qy, qz, qw = quaternion_xyzw
    return np.array([-x, -z, y]), np.array([qw, qx, qz, -qy])


def to_unity(position, quaternion_wxyz):
    """The inverse of from_unity: what a VMC sender puts on the wire (x, y, z), (x, y, z, w)."""
    bx, by, bz = position
    w, x, y, z = quaternion_wxyz
    return (-bx, bz, -by), (x, -z, y, w)


class VMCReceiver(DatagramDevice):
    kind = "vmc"
    what = "VMC packets"

    def __init__(self, name, host="127.0.0.1", port=DEFAULT_PORT, timeout=0.05, watchdog=1.0, **kw):
        super().__init__(name, host, port, timeout, watchdog, **kw)
        self.bones, self.root, self.blendshapes = {}, None, {}
        self.bad_packets = 0

    def _datagram(self, data, now):
        try:
            messages = parse(data)
        except (OSCError, Exception) as exc:
            self.bad_packets += 1  # not a frame we can read: discarded, not counted as a lost frame
            self.discarded_bytes += len(data)
            self.resyncs += 1
            self.resyncing = True
            self.last_error = f"bad OSC packet: {exc}"
            return []
        self.resyncing = False
        changed = False
        for address, args in messages:
            try:
                changed |= self._message(address, args)
            except (ValueError, TypeError, IndexError):
                self.bad_packets += 1
        if not changed:
            return []
        data = {"bones": dict(self.bones), "root": self.root, "blendshapes": dict(self.blendshapes),
                "roles": HUMANOID_ROLES}
        return [self.make_sample("skeleton", "skeleton", data, now)]

    def _message(self, address, args):
        if address == "/VMC/Ext/Bone/Pos":
            self.bones[str(args[0])] = from_unity(args[1:4], args[4:8])
            return True
        if address == "/VMC/Ext/Root/Pos":
            self.root = from_unity(args[1:4], args[4:8])
            return True
        if address == "/VMC/Ext/Blend/Val":
            self.blendshapes[str(args[0])] = float(args[1])
            return False  # applied with /VMC/Ext/Blend/Apply
        if address == "/VMC/Ext/Blend/Apply":
            return True
        return False


class VMCSender:
    """Sends VMC bundles to a receiver (tests, demos, and a loopback for the benchmark)."""

    def __init__(self, host="127.0.0.1", port=DEFAULT_PORT):
        self.address = (host, int(port))
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)

    def frame(self, bones, root=None, blendshapes=None):
        """bones: {name: (position, quaternion w,x,y,z)} in Z-up metres."""
        msgs = []
        if root is not None:
            p, q = to_unity(*root)
            msgs.append(encode_message("/VMC/Ext/Root/Pos", "root", *map(float, p), *map(float, q)))
        for name, (pos, quat) in bones.items():
            p, q = to_unity(pos, quat)
            msgs.append(encode_message("/VMC/Ext/Bone/Pos", name, *map(float, p), *map(float, q)))
        for name, value in (blendshapes or {}).items():
            msgs.append(encode_message("/VMC/Ext/Blend/Val", name, float(value)))
        if blendshapes:
            msgs.append(encode_message("/VMC/Ext/Blend/Apply"))
        self.sock.sendto(encode_bundle(msgs), self.address)

    def raw(self, data):
        self.sock.sendto(bytes(data), self.address)

    def close(self):
        self.sock.close()
