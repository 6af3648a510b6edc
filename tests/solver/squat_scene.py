"""The thesis's squat (Oshita 2003, sec. 2.6, fig. 2.7-2.9), keyframed on the Rigify metarig
fixture: a figure squats holding a box in front of it with both hands.

Scene data shared by the motion-control experiments (test_motion_control_experiments.py) and
benchmarks/control.py. Built from the metarig's first frame at 30 fps (the thesis's 1/30 s step):
`hold` s standing, one squat of `seconds` s (down and up, cosine timing; the thesis's is 3 s, 90
frames), then `rest` s standing (to see the figure come back to the input after the motion):

- the pelvis goes down `depth` m; the trunk leans forward `lean` degrees at the bottom, over the
  knees (the lowest back bone takes `lean_share` of it, the next one the rest);
- the pelvis moves back as the trunk leans so that the centre of mass of the unloaded figure
  stays over the middle of the feet (`balance` m in front of it): a balanced input, as Oshita
  assumes ("input motion is already realistic");
- the legs are solved by LimbIK so that the feet stay where they stand (0.2 um);
- the arms by LimbIK so that the hands hold the box in front: `reach_standing` m forward of the
  shoulders and `drop_standing` m below them when standing (the box against the belly), moving
  out to `reach` and `drop` at the bottom, in the world, as the trunk leans (arms forward, the
  box in front of the knees).

With the default strength model, unloaded, no joint is over strength (at most 76 % of it: the
lower back at the bottom). 8 kg in the hands (4 kg each), under pure tracking: the lower back
(spine.001, extension) is over strength on 18 frames at the bottom and as the back rises (25 N m
at most), the shoulders (upper arms' swing axis) on 5 frames of the descent, barely (0.4 N m);
15 kg: lower back on 32 frames (88 N m), shoulders on 33 (7.7 N m), clavicles on 27.
"""

import numpy as np

from humananim.solver import rotations
from humananim.solver.dynamics import build_model, desired_motion
from humananim.solver.dynamics.kinematics import center_of_mass, point_positions
from humananim.solver.motion_control import LimbIK, Load
from humananim.solver.motion_control.comfort_control import body_parts
from humananim.solver.trajectories import Trajectories

from test_dynamics_closed_loop_rigs import load


def box_squat(seconds=3.0, depth=0.3, lean=60.0, lean_share=1.0, hold=0.5, rest=1.0, reach=0.45, drop=0.2,
              reach_standing=0.25, drop_standing=0.35, width=0.08, balance=0.0):
    """(skeleton, Trajectories) of the squat (see the module notes). The pelvis moves back as the
    trunk leans so that the centre of mass of the unloaded figure stays `balance` m in front of
    the middle of the feet (a balanced input: Oshita assumes the input is realistic)."""
    sk, tr = load("metarig_legs", frames=1)
    model = build_model(sk, reference_basis=tr.basis()[0])
    data = model.create_data()
    parts = body_parts(model)
    q0 = desired_motion(model, sk, tr)[0][0]
    feet = np.concatenate([point_positions(model, data, q0, j, p) for j, p in zip(parts.sole_joints, parts.sole_points)])
    centre = 0.5 * (feet[:, 1].min() + feet[:, 1].max()) - balance  # forward is -Y
    back = None
    for _ in range(4):  # the pelvis offset that puts the centre of mass over the middle of the feet
        sk, out = _squat(sk, tr, seconds, depth, lean, lean_share, hold, (reach_standing, reach), (drop_standing, drop), width, back, rest)
        com = np.array([center_of_mass(model, data, q)[1] for q in desired_motion(model, sk, out)[0]])
        back = (0.0 if back is None else back) - 1.2 * (com - centre)
    return _squat(sk, tr, seconds, depth, lean, lean_share, hold, (reach_standing, reach), (drop_standing, drop), width, back, rest)


def _squat(sk, tr, seconds, depth, lean, lean_share, hold, reach, drop, width, back, rest):
    reach = [reach[1] if reach[0] is None else reach[0], reach[1]]
    drop = [drop[1] if drop[0] is None else drop[0], drop[1]]
    fps = tr.fps
    n = int(round((seconds + hold + rest) * fps)) + 1
    t = np.maximum(np.arange(n) / fps - hold, 0.0)
    s = 0.5 * (1.0 - np.cos(2.0 * np.pi * np.minimum(t, seconds) / seconds))
    rot = np.repeat(tr.rotations[:1], n, axis=0)
    trans = np.repeat(tr.translations[:1], n, axis=0)
    w0 = tr.world_frames(sk)[0]
    chain = sk.roles.chain("spine")
    lower, upper = sk.index(chain[0]), sk.index(chain[1])
    for f in range(n):  # +X of the back bones leans the trunk forward (-Y)
        for j, share in ((lower, lean_share), (upper, 1.0 - lean_share)):
            turn = rotations.axis_rotation(0, np.radians(lean * share) * s[f])
            rot[f, j] = rotations.multiply(rot[0, j], turn)
    base = Trajectories(np.arange(n) + tr.frames[0], fps, rot, trans, tr.armature_to_world)
    pos, ori = base.root_pose(sk)
    pos = pos.copy()
    pos[:, 2] -= depth * s
    if back is not None:
        pos[:, 1] += back
    base = base.with_root_pose(sk, pos, ori)
    rot, basis, worlds = base.rotations.copy(), base.basis(), base.world_frames(sk)
    for f in range(n):
        for side, sign in (("L", 1.0), ("R", -1.0)):
            legs = LimbIK(sk, side, basis=basis[f])  # the feet stay where frame 0 has them
            q, _, reached = legs.solve(legs.parent_frame(worlds[f]), w0[legs.end], legs.swivel(w0))
            assert reached
            rot[f, [legs.upper, legs.lower, legs.end]] = q
            arm = LimbIK(sk, side, "arm", basis=basis[f])
            target = w0[arm.end].copy()  # the hands keep their rest orientation relative to the world
            target[:3, 3] = worlds[f][arm.upper][:3, 3] + np.array([-sign * width, -(reach[0] + s[f] * (reach[1] - reach[0])),
                                                                 -(drop[0] + s[f] * (drop[1] - drop[0]))])
            q, _, reached = arm.solve(arm.parent_frame(worlds[f]), target, arm.swivel(w0))
            assert reached
            rot[f, [arm.upper, arm.lower, arm.end]] = q
    return sk, Trajectories(base.frames, fps, rot, base.translations, tr.armature_to_world)


def hand_loads(sk, kg, start_time=0.0):
    """A box of `kg` held in both hands: half its mass at each hand."""
    return tuple(Load(sk.roles.bone(f"hand.{s}"), kg / 2, start_time) for s in "LR")
