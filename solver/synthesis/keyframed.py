"""Procedural keyframed actions on any rig with leg roles (the thesis's test set, sec. 3.6: still,
step forward, kick), built from one standing pose with the analytic leg IK. Used by the tests, the
benchmark and the CLI's demo."""

import numpy as np

from .. import rotations
from ..motion_control.limb_ik import LimbIK
from ..trajectories import Trajectories
from .action import from_trajectories
from .transitions import smootherstep


def _standing(tr):
    return Trajectories(tr.frames[:1], tr.fps, tr.rotations[:1], tr.translations[:1], tr.armature_to_world)


def forward_of(sk, tr):
    """Horizontal unit direction the feet point to in the first frame."""
    w = tr.world_frames(sk)[0]
    d = sum(w[sk.role_index(f"foot.{s}")][:3, 1] for s in "LR")
    d[2] = 0.0
    return d / np.linalg.norm(d)


CROUCH = 0.04  # m the root is lowered in every action, so that the knees are bent and the legs reach
PHASES = {"initial_duration": 0.4, "terminal_duration": 0.4}  # s, the initial and terminal phases (sec. 3.3)


def _build(sk, pose, n, root_offset, foot_offset, fps):
    """n frames of `pose` with the root moved by root_offset (n, 3) and each foot by
    foot_offset[side] (n, 3), legs by IK keeping the standing swivel."""
    root_offset = root_offset - np.array([0.0, 0.0, CROUCH])
    rot = np.repeat(pose.rotations[:1], n, axis=0)
    trans = np.repeat(pose.translations[:1], n, axis=0)
    base = Trajectories(np.arange(n, dtype=float) + pose.frames[0], fps, rot, trans, pose.armature_to_world)
    p, q = base.root_pose(sk)
    base = base.with_root_pose(sk, p + root_offset, q)
    w0 = pose.world_frames(sk)[0]
    basis, world = base.basis(), base.world_frames(sk)
    rot = base.rotations.copy()
    for side in "LR":
        ik = LimbIK(sk, side, basis=basis[0])
        sw = ik.swivel(w0)
        for f in range(n):
            tgt = w0[ik.end].copy()
            tgt[:3, 3] += foot_offset[side][f]
            qs, _, _ = ik.solve(ik.parent_frame(world[f]), tgt, sw)
            rot[f, [ik.upper, ik.lower, ik.end]] = qs
    return Trajectories(base.frames, fps, rotations.make_continuous(rot), base.translations, base.armature_to_world)


def still(sk, tr, seconds=1.0, fps=30.0):
    pose = _standing(tr)
    n = int(round(seconds * fps)) + 1
    z = np.zeros((n, 3))
    return from_trajectories("still", sk, _build(sk, pose, n, z, {"L": z, "R": z}, fps), **PHASES)


def step_forward(sk, tr, length=0.3, lift=0.08, seconds=2.0, fps=30.0, lead="R"):
    """Two steps: the lead foot forward by `length`, then the other joins it; the root follows
    half way each step. Starts and ends in the standing pose."""
    pose = _standing(tr)
    n = int(round(seconds * fps)) + 1
    fwd = forward_of(sk, pose)
    t = np.linspace(0.0, 1.0, n)
    other = "L" if lead == "R" else "R"
    # share of the action: lead swing [.25, .5], the other foot [.6, .85]; the root moves half the
    # step length before each landing
    def swing(a, b):
        u = smootherstep((t - a) / (b - a))
        up = np.sin(np.pi * np.clip((t - a) / (b - a), 0, 1))
        return length * u[:, None] * fwd + lift * up[:, None] * np.array([0, 0, 1.0])
    feet = {lead: swing(0.25, 0.5), other: swing(0.6, 0.85)}
    root = 0.5 * length * (smootherstep((t - 0.2) / 0.35) + smootherstep((t - 0.5) / 0.3))[:, None] * fwd
    act = from_trajectories("step", sk, _build(sk, pose, n, root, feet, fps), **PHASES)
    act.meta["length"] = length
    return act


def kick(sk, tr, side="R", reach=0.35, height=0.3, seconds=1.8, fps=30.0):
    """A front kick: the root shifts towards the base foot, the kicking foot goes forward and up
    and comes back to where it was. Like the thesis's set, the initial and terminal phases (the
    first and last 0.4 s) are in the standing posture, so any action joins it."""
    pose = _standing(tr)
    n = int(round(seconds * fps)) + 1
    fwd = forward_of(sk, pose)
    w0 = pose.world_frames(sk)[0]
    base = "L" if side == "R" else "R"
    lateral = w0[sk.role_index(f"foot.{base}")][:3, 3] - w0[sk.role_index(f"foot.{side}")][:3, 3]
    lateral[2] = 0.0
    t = np.linspace(0.0, 1.0, n)
    quiet = 0.4 / seconds
    shift = np.sin(np.pi * np.clip((t - quiet) / (1 - 2 * quiet), 0, 1)) ** 2
    root = 0.4 * lateral * shift[:, None]
    bump = np.sin(np.pi * np.clip((t - 0.38) / 0.24, 0, 1)) ** 2
    feet = {side: bump[:, None] * (reach * fwd + np.array([0, 0, height])), base: np.zeros((n, 3))}
    return from_trajectories("kick", sk, _build(sk, pose, n, root, feet, fps), **PHASES)


def stance(sk, tr, offsets, seconds=1.0, fps=30.0, name="stance"):
    """The standing pose with feet moved by offsets[side] (3,) (the root half way), held."""
    pose = _standing(tr)
    n = int(round(seconds * fps)) + 1
    feet = {s: np.repeat(np.asarray(offsets.get(s, (0.0, 0.0, 0.0)), float)[None], n, axis=0) for s in "LR"}
    root = 0.5 * (feet["L"] + feet["R"])
    root[:, 2] = 0.0
    return from_trajectories(name, sk, _build(sk, pose, n, root, feet, fps), **PHASES)
