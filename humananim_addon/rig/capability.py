"""What a capability reads and writes on any rig: the one switch between a plain FK skeleton and a
control rig.

On a plain FK rig (every deform role bone is a control: a BVH import, a metarig, a Mixamo-style
FBX) a capability works as it always has: the armature's skeleton, its F-curves, its bones keyed.
On a control rig it reads the physical skeleton (the deform bones as Blender evaluates them, hung
in the body's hierarchy: rig/physical.py) and writes through the controls (rig/writeback.py), then
compares Blender's evaluation with the solved pose; a result Blender can't show (more than
REFUSE_M off at a hand or foot) is removed and refused, never reported as done."""

from dataclasses import replace

import bpy
import numpy as np

from ...solver.errors import HumanAnimError
from ...solver.progress import run_to_end
from .. import action_api, actions
from ..armature import skeleton_from_armature
from .bones import classify
from .physical import physical_skeleton, physical_trajectories
from .writeback import plan_controls, write_pose_steps

REFUSE_M = 0.02  # a hand or foot this far from the solved pose: the rig can't show the result


def is_control_rig(obj):
    """True when some deform bone of `obj` is moved by other bones (constraints, IK, drivers)
    rather than keyed itself."""
    c = classify(obj)
    return bool(c.deform - c.control)


class RigView:
    """The skeleton a capability solves on, how it reads a motion and how it writes a result.
    `report`: after `write`, the control rig's write-back report (controls, modes, mismatch per
    role), or None on a plain rig."""

    def __init__(self, obj, scene, fk=False, total_mass=None):
        self.obj, self.scene, self.fk = obj, scene, fk
        self.control_rig = is_control_rig(obj)
        self.skeleton = (_role_joints_only(physical_skeleton(obj, scene, total_mass)) if self.control_rig
                         else skeleton_from_armature(obj, scene, total_mass))
        self.report = None

    def read(self, action=None, frame_range=None):
        """The Trajectories of `action` (the active one by default) over `frame_range`."""
        if self.control_rig:
            return physical_trajectories(self.obj, self.scene, self.skeleton, action, frame_range)
        return actions.read_action(self.obj, self.scene, self.skeleton, action, frame_range)

    def iter_read(self, action=None, frame_range=None):
        """`read` as a job step (yields progress on a plain rig's long reads)."""
        if self.control_rig:
            return self.read(action, frame_range)
        return (yield from actions.iter_read_action(self.obj, self.scene, self.skeleton, action,
                                                    frame_range=frame_range))

    def write(self, traj, name, output="ACTION", source=None, extra_channels=None):
        return run_to_end(self.iter_write(traj, name, output, source, extra_channels))

    def iter_write(self, traj, name, output="ACTION", source=None, extra_channels=None):
        """The new action showing `traj` (on this view's skeleton): the bones keyed on a plain rig,
        the controls on a control rig (checked against Blender's evaluation; there the scene's
        output setting decides between a new action and an NLA track). Yields progress."""
        if not self.control_rig:
            return actions.write_action(self.obj, self.skeleton, traj, name, output, source, extra_channels)
        obj, scene = self.obj, self.scene
        solved = self.skeleton.world_frames(traj.basis())
        ad = obj.animation_data
        keep = (ad.action, getattr(ad, "action_slot", None)) if ad else (None, None)
        plan = plan_controls(obj, self.skeleton, self.fk)
        action, report = yield from write_pose_steps(obj, scene, self.skeleton, traj.frames, solved, name,
                                                     plan=plan)
        self.report = report
        worst = max((v[0] for r, v in report["mismatch"].items() if r.split(".")[0] in ("hand", "foot")),
                    default=0.0)
        if worst > 1000 * REFUSE_M:
            _undo(obj, action, keep)
            role = max(report["mismatch"], key=lambda r: report["mismatch"][r][0])
            raise HumanAnimError(f"'{obj.name}' can't show the result through its controls: its {role} stays "
                                 f"{report['mismatch'][role][0]:.0f} mm from the solved pose "
                                 f"(controls: {', '.join(report['controls'][:6])}); nothing was written")
        if extra_channels:
            writer = action_api.ChannelWriter(action, obj, existing=True)
            for (data_path, group), values in extra_channels.items():
                writer.key_columns(data_path, group, traj.frames, values)
        return action

    def summary(self):
        """The write-back figures a capability adds to its summary ({} on a plain rig)."""
        if self.report is None:
            return {}
        mm, deg = worst_of(self.report)
        return {"controls_keyed": len(self.report["controls"]), "limbs": self.report["modes"],
                "switches": self.report["switches"], "mismatch_mm": mm, "mismatch_deg": deg,
                "mismatch_per_role": self.report["mismatch"]}


def _role_joints_only(skeleton):
    """The skeleton with the deform bones no body role names (twist segments, face, breasts)
    kept still on their parents: the rig moves them itself, from the role bones."""
    dof = skeleton.dof.copy()
    dof[[skeleton.roles.role_of(n) is None for n in skeleton.names]] = False
    return replace(skeleton, dof=dof)


def worst_of(report):
    """(largest mm at hands and feet, largest degrees at any role) of a write-back report."""
    m = report["mismatch"]
    mm = max((v[0] for r, v in m.items() if r.split(".")[0] in ("hand", "foot")), default=0.0)
    return mm, max((v[1] for v in m.values()), default=0.0)


def _undo(obj, action, keep):
    ad = obj.animation_data
    if ad is not None:
        if keep[0] is not None:
            action_api.assign_action(obj, keep[0], keep[1])
        else:
            ad.action = None
        for track in list(ad.nla_tracks):
            if any(s.action == action for s in track.strips):
                ad.nla_tracks.remove(track)
    bpy.data.actions.remove(action)


def with_control_channels(obj, scene, skeleton, traj, controls):
    """`traj` with the local poses of the `controls` taken from their own channels (pose-bone
    bases) as the action and NLA give them on each frame, not from their evaluated matrices: the
    top of an IK chain is turned by its IK, but its key is where that IK starts from."""
    from ...solver import rotations
    pick = [j for j, n in enumerate(skeleton.names) if n in controls]
    rot, trans = traj.rotations.copy(), traj.translations.copy()
    pbs = obj.pose.bones
    keep = scene.frame_current, scene.frame_subframe
    try:
        for k, f in enumerate(traj.frames):
            scene.frame_set(int(np.floor(f)), subframe=float(f - np.floor(f)))
            for j in pick:
                m = np.array(pbs[skeleton.names[j]].matrix_basis, dtype=float)
                r = m[:3, :3] / np.linalg.norm(m[:3, :3], axis=0)
                rot[k, j] = rotations.from_matrix(r)
                trans[k, j] = m[:3, 3] * skeleton.unit_scale
    finally:
        scene.frame_set(keep[0], subframe=keep[1])
    rot[:, pick] = rotations.make_continuous(rot[:, pick])
    return replace(traj, rotations=rot, translations=trans)


def refuse_control_rig(obj, capability, advice):
    """Raises before a capability that can't key a control rig's controls yet runs on one: keys on
    its deform bones would be overridden by their constraints, the character would not move."""
    c = classify(obj)
    moved = sorted(c.deform - c.control)
    if moved:
        raise HumanAnimError(f"{capability} can't drive '{obj.name}' yet: its deform bones ({', '.join(moved[:3])}"
                             f"{' ...' if len(moved) > 3 else ''}) follow its controls through constraints, so "
                             f"keys on them would not move the character; {advice}")
