"""Action data (Oshita 2003, sec. 3.3): joint and root trajectories, total/initial/terminal
durations, and per frame a constraint on the root and each limb (angular, spatial or supporting).

Supporting intervals of the legs come from the motion (contacts.support_intervals: contact height
and speed with hysteresis) and can be overridden per frame by the animator (`Action.edit`); arms
default to angular constraints, the root to spatial. End-effector trajectories come from forward
kinematics (`end_effectors`).
"""

from dataclasses import dataclass, field

import numpy as np

from .. import rotations
from ..errors import MotionError
from ..motion_control.contacts import support_intervals
from ..skeleton import compose, decompose
from ..trajectories import Trajectories

ANGULAR, SPATIAL, SUPPORT = 0, 1, 2
CONSTRAINT_NAMES = {ANGULAR: "angular", SPATIAL: "spatial", SUPPORT: "supporting"}
CONSTRAINT_CODES = {v: k for k, v in CONSTRAINT_NAMES.items()}
# limb -> (side, kind); the end effector is the foot or hand role bone
LIMBS = {"foot.L": ("L", "leg"), "foot.R": ("R", "leg"), "hand.L": ("L", "arm"), "hand.R": ("R", "arm")}


@dataclass
class Action:
    """A unit motion. `constraints` maps "root" and each limb of LIMBS to a per-frame int array
    (ANGULAR, SPATIAL or SUPPORT). Durations in seconds."""

    name: str
    skeleton: object
    trajectories: Trajectories
    constraints: dict
    initial_duration: float = 0.25
    terminal_duration: float = 0.25
    fall: bool = False  # a falling action (no transition out of it is required)
    meta: dict = field(default_factory=dict)

    @property
    def fps(self):
        return self.trajectories.fps

    @property
    def frame_count(self):
        return self.trajectories.frame_count

    @property
    def total_duration(self):
        return (self.frame_count - 1) / self.fps

    def frames_of(self, seconds):
        return int(np.clip(round(seconds * self.fps), 1, self.frame_count - 1))

    def limbs(self):
        return [k for k in LIMBS if k in self.constraints]

    def constraint_at(self, frame):
        return {k: int(v[frame]) for k, v in self.constraints.items()}

    def supporting(self, frame):
        return [k for k in self.limbs() if self.constraints[k][frame] == SUPPORT]

    def edit(self, limb, start_frame, end_frame, constraint):
        """Set `limb`'s constraint (name or code) on Blender frames start..end inclusive."""
        code = CONSTRAINT_CODES[constraint] if isinstance(constraint, str) else int(constraint)
        if limb not in self.constraints:
            raise MotionError(f"no limb {limb!r} in action {self.name!r}")
        f = self.trajectories.frames
        self.constraints[limb][(f >= start_frame) & (f <= end_frame)] = code
        return self

    def end_effectors(self):
        """World frames (F, 4, 4) of each limb's end effector, by forward kinematics."""
        world = self.trajectories.world_frames(self.skeleton)
        return {k: world[:, self.skeleton.role_index(k)] for k in self.limbs()}


def from_trajectories(name, skeleton, trajectories, initial_duration=0.25, terminal_duration=0.25,
                      overrides=(), arm_constraint=ANGULAR, **support_kw):
    """An Action with the legs' supporting intervals detected from the motion; `overrides` are
    (limb, start_frame, end_frame, constraint) edits applied afterwards."""
    sk, tr = skeleton, trajectories
    if tr.frame_count < 2:
        raise MotionError(f"action {name!r} needs at least two frames")
    for role in ("foot.L", "foot.R"):
        if sk.role_index(role) is None:
            raise MotionError("the rig needs foot roles on both sides to synthesize motion")
    support = support_intervals(sk, tr, **support_kw)
    f = tr.frame_count
    cons = {"root": np.full(f, SPATIAL, np.int8)}
    for limb, (side, kind) in LIMBS.items():
        if sk.role_index(limb) is None:
            continue
        if kind == "leg":
            cons[limb] = np.where(support.get(side, np.zeros(f, bool)), SUPPORT, ANGULAR).astype(np.int8)
        else:
            cons[limb] = np.full(f, arm_constraint, np.int8)
    act = Action(name, sk, tr, cons, initial_duration, terminal_duration)
    for o in overrides:
        act.edit(*o)
    return act


# ---- helpers on trajectories ------------------------------------------------------------------

def yaw_of(q):
    """Heading (rad about +Z) of orientations (..., 4): the direction their local axes' mean
    horizontal forward takes; for the yaw alignment only differences matter."""
    m = rotations.to_matrix(q)
    fwd = m[..., :, 1] + m[..., :, 2]  # robust to either bone axis pointing forward or up
    return np.arctan2(fwd[..., 1], fwd[..., 0])


def rigid_2d(src, dst):
    """Yaw angle and translation (2,) of the 2-D rigid map taking points src (k, 2) onto dst
    (least squares; k == 1 gives a pure translation)."""
    src, dst = np.atleast_2d(src), np.atleast_2d(dst)
    if len(src) == 1:
        return 0.0, dst[0] - src[0]
    cs, cd = src.mean(0), dst.mean(0)
    a, b = src - cs, dst - cd
    angle = np.arctan2((a[:, 0] * b[:, 1] - a[:, 1] * b[:, 0]).sum(), (a * b).sum())
    c, s = np.cos(angle), np.sin(angle)
    return angle, cd - np.array([[c, -s], [s, c]]) @ cs


def transformed(skeleton, tr, yaw=0.0, shift=(0.0, 0.0, 0.0), start_frame=None):
    """A copy of tr moved rigidly in the world (yaw about +Z through the origin, then shift),
    renumbered from start_frame."""
    pos, ori = tr.root_pose(skeleton)
    qz = np.array([np.cos(yaw / 2), 0.0, 0.0, np.sin(yaw / 2)])
    rz = rotations.to_matrix(qz)
    pos = pos @ rz.T + np.asarray(shift, float)
    ori = rotations.multiply(qz, ori)
    out = tr.with_root_pose(skeleton, pos, ori)
    if start_frame is not None:
        out.frames = np.arange(tr.frame_count, dtype=float) + start_frame
    return out


def sliced(tr, a, b):
    return Trajectories(tr.frames[a:b], tr.fps, tr.rotations[a:b], tr.translations[a:b], tr.armature_to_world)


def resampled(tr, fps):
    """tr at another frame rate (slerp of rotations, linear translations)."""
    if abs(tr.fps - fps) < 1e-6:
        return tr
    t = tr.times
    n = int(np.floor(t[-1] * fps + 1e-9)) + 1
    tt = np.arange(n) / fps
    x = tt * tr.fps
    i = np.clip(np.floor(x).astype(int), 0, tr.frame_count - 2)
    u = (x - i)[:, None, None]
    q0, q1 = tr.rotations[i], rotations.make_continuous(np.stack((tr.rotations[i], tr.rotations[i + 1])))[1]
    rot = slerp(q0, q1, u)
    trans = (1 - u) * tr.translations[i] + u * tr.translations[i + 1]
    return Trajectories(np.arange(n) + tr.frames[0], fps, rot, trans, tr.armature_to_world)


def slerp(q0, q1, w):
    """Great-circle interpolation, weight w of q1 (broadcast over (..., 1))."""
    from ..dynamics import spatial
    q0 = rotations.normalize(q0)
    q1 = rotations.normalize(q1)
    q1 = np.where((q0 * q1).sum(-1, keepdims=True) < 0, -q1, q1)
    d = spatial.quat_log(rotations.multiply(rotations.conjugate(q0), q1))
    return rotations.multiply(q0, spatial.quat_exp(np.asarray(w, float) * d))


def blend_frames(a, b, w):
    """Rigid frames (..., 4, 4): positions per axis and orientations by slerp, weight w of b."""
    pa, qa = decompose(a)
    pb, qb = decompose(b)
    w = np.asarray(w, float)[..., None]
    return compose((1 - w) * pa + w * pb, slerp(qa, qb, w))
