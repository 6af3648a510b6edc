"""The walking generator: a rig walks a path (Boulic's model, Huang 1996 sec. 2.6 and 6.4.2).

The body's hip centre is driven along the path (Huang's "Global_motion"); footsteps are planned
from the model's cycle (steps.py); the pelvis oscillates as the model says, sinking where the
legs could not reach otherwise; the spine leans and counter-rotates, the arms swing; each leg is
solved by the analytic limb IK to its foot, which rolls over heel, sole and toe while it
supports and swings to its next footprint in between. The result is an ordinary motion
(Trajectories) with the support intervals as constraints (Oshita 2003 sec. 3.3: the supporting
constraints of action data)."""

from dataclasses import dataclass, field

import numpy as np

from .. import rotations
from ..progress import run_to_end
from ..skeleton import decompose
from ..trajectories import Trajectories
from . import model
from .body import KNEE_MIN, KNEE_STAND, UP, WalkerBody, standing_reference, axis_angle_matrix, rot_x, rot_z, rotation_between, unit
from .path import Path, progress_from_speed, speed_profile
from .steps import plan as plan_steps

STAND = 0.5  # seconds standing before the walk and after it


def flat_ground(height=0.0):
    def ground(x, y):
        return np.full(np.shape(x), float(height))
    return ground


@dataclass
class WalkResult:
    trajectories: Trajectories
    support: dict  # side -> (F,) bool
    constraints: list  # per footprint: side, start_frame, end_frame, position, heading
    plan: object
    body: WalkerBody
    times: np.ndarray  # (F,) seconds from when the body starts moving
    progress: object
    path: Path
    style: model.Style
    running: np.ndarray  # (F,) bool
    reached: np.ndarray  # (F, 2) the leg IK reached its foot (L, R)
    info: dict = field(default_factory=dict)
    skeleton: object = None  # the rig (its own rest pose); body.skeleton may stand in another

    def __post_init__(self):
        if self.skeleton is None:
            self.skeleton = self.body.skeleton

    @property
    def frames(self):
        return self.trajectories.frames


def walk(skeleton, path, speed=None, speed_keys=None, segment_speeds=None, progress=None,
         style=model.Style(), ground=None, fps=24.0, frame_start=1, armature_to_world=None, first_side="R",
         reference=None):
    """Generate the walk (see `iter_walk`)."""
    return run_to_end(iter_walk(skeleton, path, speed, speed_keys, segment_speeds, progress, style, ground,
                                fps, frame_start, armature_to_world, first_side, reference))


def iter_walk(skeleton, path, speed=None, speed_keys=None, segment_speeds=None, progress=None,
              style=model.Style(), ground=None, fps=24.0, frame_start=1, armature_to_world=None, first_side="R",
              reference=None):
    """Steps of the walk: yields progress in [0, 1], returns a WalkResult.

    path: a Path (metres, world); speed (m/s), speed_keys ((arc length, speed) pairs) or
    segment_speeds (one per stretch between the path's corners), or `progress` (keyed root
    positions: path.from_keys); ground(x, y) -> z (arrays), flat at z = 0 by default.
    reference: a motion of the rig (Trajectories), needed when its rest pose does not stand: the
    walk is made on its best standing frame and returned on the rig's own rest pose."""
    ground = ground or flat_ground(0.0)
    a2w = np.eye(4) if armature_to_world is None else np.asarray(armature_to_world, float)
    own = skeleton
    standing, b0, hinges = standing_reference(skeleton, reference)
    body = WalkerBody(standing, hinges)
    skeleton = body.skeleton
    if progress is None:
        asked = [speed] if speed is not None else [v for _, v in np.reshape(speed_keys, (-1, 2))] \
            if speed_keys is not None else list(np.ravel(segment_speeds if segment_speeds is not None else []))
        if asked:
            model.check_rv(max(asked) / body.ht, body.ht)  # refuse what the model can't do, however short the path
        progress = progress_from_speed(*speed_profile(path, speed, speed_keys, segment_speeds))
    steps = plan_steps(body, path, progress, style, ground, first_side, fps)
    yield 0.1
    n0 = int(round(STAND * fps))
    n = int(np.ceil((steps.t_end + STAND) * fps)) + n0 + 1
    times = (np.arange(n) - n0) / fps
    gait = _gait_state(body, steps, style, times)
    feet = {s: _foot_tracks(body, steps.footprints[s], times, ground) for s in "LR"}
    yield 0.3
    pelvis = _pelvis(body, path, progress, gait, feet, times, fps)
    traj, reached = yield from _pose(body, skeleton, pelvis, gait, feet, times, fps, frame_start, a2w)
    if b0 is not None:
        traj = _on_rest(traj, b0)
    support = {s: feet[s]["support"] for s in "LR"}
    frames = traj.frames
    constraints = []
    for s in "LR":
        for fp in steps.footprints[s]:
            on = frames[feet[s]["support"] & (times >= fp.t_on - 1e-9) & (times <= fp.t_off + 1e-9)]
            if len(on):
                constraints.append({"side": s, "start_frame": float(on[0]), "end_frame": float(on[-1]),
                                    "position": [round(float(v), 5) for v in fp.sole[:3, 3]],
                                    "heading": round(float(fp.heading), 5), "final": fp.final})
    constraints.sort(key=lambda c: c["start_frame"])
    info = {"thigh_height_m": body.ht, "steps": len(steps.strikes), "seconds": float(times[-1] - times[0]),
            "path_length_m": path.length, "running_frames": int(gait["running"].sum()),
            "unreached_frames": int((~reached).any(axis=1).sum())}
    return WalkResult(traj, support, constraints, steps, body, times, progress, path, style,
                      gait["running"], reached, info, own)


def _on_rest(traj, b0):
    """Trajectories on the standing skeleton turned into bases on the rig's own rest pose:
    basis = B0 @ basis' (the same world frames)."""
    t, q = decompose(b0[None] @ traj.basis())
    return Trajectories(traj.frames, traj.fps, rotations.make_continuous(q), t, traj.armature_to_world)


def _smoothstep(x):
    x = np.clip(x, 0.0, 1.0)
    return x * x * (3 - 2 * x)


def _min_jerk(x):
    x = np.clip(x, 0.0, 1.0)
    return x ** 3 * (10 - 15 * x + 6 * x * x)


def _gait_state(body, steps, style, times):
    """Per frame: cycle phase (0 at a right heel strike), relative velocity, running, and the gait
    weight that brings the oscillations in from standing and back out."""
    st = steps.strikes
    t_k = np.array([s[0] for s in st])
    # unwrapped phase: half a cycle per step, 0 at a right heel strike
    phi_k = (0.0 if st[0][1] == "R" else 0.5) + 0.5 * np.arange(len(st))
    dc_k = np.array([s[3] for s in st])
    t_ext = np.r_[t_k[0] - dc_k[0] / 2, t_k, t_k[-1] + dc_k[-1] / 2]
    phi_ext = np.r_[phi_k[0] - 0.5, phi_k, phi_k[-1] + 0.5]
    phase = np.interp(times, t_ext, phi_ext, left=None, right=None)
    before, after = times < t_ext[0], times > t_ext[-1]
    phase[before] = phi_ext[0] - (t_ext[0] - times[before]) / dc_k[0]
    phase[after] = phi_ext[-1] + (times[after] - t_ext[-1]) / dc_k[-1]
    rv = np.interp(times, t_k, [s[2] for s in st])
    running = np.interp(times, t_k, [float(s[4]) for s in st]) > 0.5
    t_last2 = t_k[-2] if len(t_k) > 1 else t_k[-1] - dc_k[-1] / 2
    weight = _smoothstep((times + 0.15) / (t_k[0] + 0.15)) * (1 - _smoothstep((times - t_last2) / (t_k[-1] + 0.25 - t_last2)))
    osc = [model.oscillations(r, body.ht, style, bool(run)) for r, run in zip(rv, running)]
    amp = {k: np.array([getattr(o, k) for o in osc]) for k in model.Oscillations.__dataclass_fields__}
    ds_share = np.array([model.durations(r, body.ht, style)[1] / model.durations(r, body.ht, style)[0] for r in rv])
    return {"phase": phase, "rv": rv, "running": running, "weight": weight, "amp": amp, "ds_share": ds_share,
            "style": style}


def _stance_pose(foot, fp, t):
    """Foot pitch relative to its footprint and which point it pivots on at time t of a stance."""
    if np.isfinite(fp.t_on) and fp.heel_roll > 0 and t - fp.t_on < fp.heel_roll:
        return fp.heel * (1 - _smoothstep((t - fp.t_on) / fp.heel_roll)), "heel"
    if np.isfinite(fp.t_off) and fp.toe_roll > 0 and fp.t_off - t < fp.toe_roll:
        x = (t - (fp.t_off - fp.toe_roll)) / fp.toe_roll
        return -fp.toe_off * np.clip(x, 0, 1) ** 2, "ball"
    return 0.0, "heel"


def _stance_frame(foot, fp, t):
    """World frame of the foot bone, the toe's pitch relative to the foot, sole z."""
    theta, pivot = _stance_pose(foot, fp, t)
    m = fp.sole.copy()
    local = np.eye(4)
    local[:3, :3] = rot_x(theta)
    if pivot == "ball":
        b = foot.ball_local
        local[:3, 3] = b - local[:3, :3] @ b
    return m @ local @ foot.rel_foot, (-theta if pivot == "ball" else 0.0)


def _foot_tracks(body, prints, times, ground):
    """Per frame: the foot bone's world frame (F, 4, 4), the toe's pitch relative to the foot,
    support (bool), the sole's height under the body, the progress through the swing."""
    foot = body.feet[prints[0].side]
    n = len(times)
    frames, toe, support, sole_z = np.empty((n, 4, 4)), np.zeros(n), np.zeros(n, bool), np.zeros(n)
    swing = np.zeros(n)  # progress through the swing (0 at toe off, 1 at heel strike; 0 in support)
    stance = np.full(n, np.nan)  # progress through a stance (NaN standing)
    for i, t in enumerate(times):
        k = next((k for k, fp in enumerate(prints) if fp.t_on <= t <= fp.t_off), None)
        if k is not None:
            fp = prints[k]
            frames[i], toe[i] = _stance_frame(foot, fp, t)
            support[i], sole_z[i] = True, fp.sole[2, 3]
            if np.isfinite(fp.t_on) and np.isfinite(fp.t_off):
                stance[i] = (t - fp.t_on) / max(fp.t_off - fp.t_on, 1e-9)
            continue
        k = max(j for j, fp in enumerate(prints) if fp.t_off < t)
        a, b = prints[k], prints[k + 1]
        tau = swing[i] = (t - a.t_off) / (b.t_on - a.t_off)
        frames[i], toe[i] = _swing_frame(body, foot, a, b, tau, ground)
        sole_z[i] = (1 - tau) * a.sole[2, 3] + tau * b.sole[2, 3]
    return {"frames": frames, "toe": toe, "support": support, "sole_z": sole_z, "swing": swing,
            "stance": stance}


def _quintic(x0, rate0, x1, tau):
    """Quintic Hermite from x0 leaving at rate0 (per unit tau) with no acceleration to x1
    arriving at rest: min-jerk when rate0 = 0. Carries the foot's motion at toe off into its
    swing, so velocity and acceleration stay continuous (the swing starting from rest while the
    foot was rolling over its toes jerked the knee 20-60 deg/frame^2)."""
    t = np.clip(tau, 0.0, 1.0)
    h5 = t ** 3 * (10 - 15 * t + 6 * t * t)
    h1 = t - 6 * t ** 3 + 8 * t ** 4 - 3 * t ** 5
    return (1 - h5) * np.asarray(x0) + h1 * np.asarray(rate0) + h5 * np.asarray(x1)


def _toe_off_rates(foot, a, h=1e-3):
    """Ankle velocity (m/s) and pitch rate (rad/s) of the foot rolling over its toes at toe off."""
    f1, _ = _stance_frame(foot, a, a.t_off)
    f0, _ = _stance_frame(foot, a, a.t_off - h)
    pitch_rate = -2.0 * a.toe_off / a.toe_roll if a.toe_roll > 0 and np.isfinite(a.t_on) else 0.0
    return (f1[:3, 3] - f0[:3, 3]) / h, pitch_rate


def _swing_frame(body, foot, a, b, tau, ground):
    fa, _ = _stance_frame(foot, a, a.t_off)
    fb, _ = _stance_frame(foot, b, b.t_on)
    duration = b.t_on - a.t_off
    velocity, pitch_rate = _toe_off_rates(foot, a)
    sig = _min_jerk(tau)
    pa, pb = fa[:3, 3], fb[:3, 3]
    p = _quintic(pa, velocity * duration, pb, tau)
    clearance = model.oscillations(max(b.rv, model.RV_MIN), body.ht, running=b.running).clearance
    # the lift over the straight path: sin^2 leaves and lands with no vertical jerk (the toe
    # roll's own rise carries into the swing through the quintic)
    bump = np.sin(np.pi * tau) ** 2
    # keep the sole above the ground under the swing (uneven ground)
    grid = np.linspace(0, 1, 9)
    path = np.array([_quintic(pa, velocity * duration, pb, g) for g in grid])
    need = ground(path[:, 0], path[:, 1]) + foot.ankle_height + 0.5 * clearance - \
        (path[:, 2] + clearance * np.sin(np.pi * grid) ** 2)
    p[2] += clearance * bump + max(0.0, float(need.max())) * bump
    pitch_a, pitch_b = a.ground_pitch - a.toe_off, b.ground_pitch + b.heel
    pitch = float(_quintic(pitch_a, pitch_rate * duration, pitch_b, tau))
    dpsi = (b.heading - a.heading + np.pi) % (2 * np.pi) - np.pi
    psi = a.heading + sig * dpsi
    m = np.eye(4)
    m[:3, :3] = rot_z(psi) @ foot.rest_sole[:3, :3] @ rot_x(pitch) @ foot.rel_foot[:3, :3]
    m[:3, 3] = p
    # the toe stays as flat as the foot is pitched heel up (a smooth max(0, -pitch), 5 deg wide),
    # so its tip never points into the floor; it follows the foot's rate from toe off
    heel_up = -(pitch - ((1 - sig) * a.ground_pitch + sig * b.ground_pitch))
    toe = 0.5 * (heel_up + np.sqrt(heel_up ** 2 + np.radians(5.0) ** 2))
    return m, toe


def _box(x, width):
    if width <= 1:
        return x
    k = np.ones(width) / width
    pad = np.r_[np.full(width, x[0]), x, np.full(width, x[-1])]
    return np.convolve(pad, k, mode="same")[width:-width]


def _erode(x, width):
    h = width // 2
    pad = np.r_[np.full(h, x[0]), x, np.full(h, x[-1])]
    return np.array([pad[i:i + width].min() for i in range(len(x))])


def _draw_in(track, hip, d_max):
    """Softly bring swinging ankles within d_max of the hip (radially, a smooth saturation).

    The pull fades in and out over the swing (sin(pi tau)^2, zero with its rate at toe off and
    heel strike), so the foot leaves and meets its footprints without a jump: a pull applied
    from the first swing frame at full strength moved the ankle by centimetres in one frame and
    snapped thigh and knee 20-60 deg. At the swing's ends the pelvis drops instead (_pelvis)."""
    swing = ~track["support"]
    v = track["frames"][:, :3, 3] - hip
    r = np.linalg.norm(v, axis=1)
    r0 = 0.9 * d_max
    over = swing & (r > r0)
    scale = (r0 + (d_max - r0) * np.tanh((r[over] - r0) / (d_max - r0))) / r[over]
    fade = np.sin(np.pi * np.clip(track["swing"][over], 0.0, 1.0)) ** 2
    scale = 1.0 + fade * (scale - 1.0)
    track["frames"][over, :3, 3] = hip[over] + v[over] * scale[:, None]


def _pelvis(body, path, progress, gait, feet, times, fps):
    """World position of the hip centre and the pelvis rotation (F, 3, 3) in armature axes."""
    amp, w, phase = gait["amp"], gait["weight"], gait["phase"]
    s = progress(np.clip(times, 0.0, None))
    h = path.heading(s)
    right = np.column_stack((h[:, 1], -h[:, 0], np.zeros(len(s))))
    fwd = np.column_stack((h, np.zeros(len(s))))
    centre = 0.5 * gait["ds_share"]  # mid-support of the right foot, as a share of the cycle
    # lowest just after each heel strike (mid double support) walking, at mid-stance running
    dds_mid = np.where(gait["running"], centre, 0.5 * (gait["ds_share"] - 0.5))
    lateral = w * amp["lateral"] * np.cos(2 * np.pi * (phase - centre))
    surge = w * amp["forward"] * np.sin(4 * np.pi * (phase - dds_mid))
    p = path.at(s)
    p[:, :2] += lateral[:, None] * right[:, :2] + surge[:, None] * fwd[:, :2]
    psi = np.arctan2(h[:, 1], h[:, 0]) - np.arctan2(body.forward[1], body.forward[0])
    yaw = w * amp["rotation"] * np.cos(2 * np.pi * phase)
    tilt = -w * amp["list"] * np.cos(2 * np.pi * (phase - centre))
    rot = rot_z(psi + yaw) @ axis_angle_matrix(body.forward, tilt)
    # a swinging foot that trails (or reaches) further than the leg does is drawn in towards
    # the hip: in early swing the knee folds and lifts it
    p[:, 2] = _pelvis_height(body, p, rot, gait, feet, fps)[0]
    for sd in "LR":
        hip = p + np.einsum("fij,j->fi", rot, body.hips[sd] - body.hip_centre)
        _draw_in(feet[sd], hip, 0.97 * body.reach(sd, KNEE_MIN + np.radians(1.0)))
    p[:, 2], drop = _pelvis_height(body, p, rot, gait, feet, fps)
    return {"position": p, "rotation": rot, "yaw": yaw, "tilt": tilt, "heading": h, "drop": drop}


NEUTRAL_KNEE = np.radians(12.0)  # the neutral style's stance knee flexion (model.oscillations)
SWING_KNEE = np.radians(60.0)  # the knee flexion a swinging leg allows the pelvis at mid-swing
STRIKE_KNEE = np.radians(20.0)  # the knee flexion a leg lands with: near straight, a millimetre of
# hip-ankle distance is a degree of knee, so a leg landing straight snaps as the hip passes over it


def _knee_plan(body, gait, track):
    """The knee flexion each leg would have (F,): in stance half the model's knee flexion, the
    other half a loading bump over the first 45 % (peak at 22 %), at least STRIKE_KNEE as it lands;
    in swing a bound that is
    the stance value at its ends and SWING_KNEE in between, so it only binds near strike and toe off."""
    amp = gait["weight"] * gait["amp"]["knee"]
    x = track["stance"]
    loading = np.where(np.isfinite(x) & (x < 0.45), np.sin(np.pi * np.nan_to_num(x) / 0.45) ** 2, 0.0)
    strike = KNEE_STAND + gait["weight"] * (STRIKE_KNEE - KNEE_STAND)
    early = np.where(np.isfinite(x), 1.0 - _smoothstep(np.nan_to_num(x) / 0.3), 0.0)  # from strike to loading
    # the model's knee flexion: half held through the stance and half in the loading bump; a style's
    # flexion beyond the neutral walk's is held (a sneak walks low)
    held = 0.5 * amp + np.maximum(amp - gait["weight"] * NEUTRAL_KNEE, 0.0)
    knee = KNEE_STAND + held + (amp - held).clip(0.0) * loading + early * np.maximum(strike - KNEE_STAND - held, 0.0)
    # the trailing leg in pre-swing only has to reach (its knee folds as the heel rises and the
    # hip moves on): planning its toe-off flexion here would pull the pelvis down on the loading leg
    late = np.where(np.isfinite(x), _smoothstep((np.nan_to_num(x) - 0.5) / 0.5), 0.0)
    knee = knee + late * (KNEE_STAND - knee)
    swing = ~track["support"]
    tau = track["swing"][swing]
    end = np.where(tau < 0.5, KNEE_STAND, strike[swing])
    knee[swing] = end + (SWING_KNEE - end) * np.sin(np.pi * tau) ** 2
    return knee


def _soft_min(a, b, k):
    """A smooth minimum (within k of the true one where a and b meet): no kink at the change of leg."""
    m = np.minimum(a, b)
    return m - k * np.log(np.exp((m - a) / k) + np.exp((m - b) / k))


def _pelvis_height(body, p, rot, gait, feet, fps):
    """Hip-centre heights (F,) from the legs: each leg, with the knee flexion it plans
    (_knee_plan), puts its hip at most this high over its ankle; the pelvis takes the lower of the
    two (a smooth minimum), so it vaults over the supporting leg and the knees follow smooth
    plans. Deriving the knee from a height fixed beforehand made it jump: near straight a
    centimetre of hip-ankle distance is 20 deg of knee. Also returns the height below standing."""
    grid = np.linspace(0, np.radians(120), 241)
    tops = []
    for sd in "LR":
        reach = np.array([body.reach(sd, k) for k in grid])
        d = np.interp(_knee_plan(body, gait, feet[sd]), grid, reach)
        offset = np.einsum("fij,j->fi", rot, body.hips[sd] - body.hip_centre)
        hip_xy = p[:, :2] + offset[:, :2]
        ankle = feet[sd]["frames"][:, :3, 3]
        horiz = np.linalg.norm(hip_xy - ankle[:, :2], axis=1)
        tops.append(ankle[:, 2] + np.sqrt(np.maximum(d ** 2 - horiz ** 2, 0.0)) - offset[:, 2])
    z = _soft_min(tops[0], tops[1], 0.01)
    win = max(3, int(0.1 * fps) | 1)
    z = _box(_box(_erode(z, 2 * win - 1), win), win)  # smoothed below the legs' bounds: they reach
    standing = max(t[0] for t in tops)
    return z, z - standing


def _trunk_rotations(body, sk, pelvis, gait):
    """Local rotations (F, 3, 3) of the spine bones: lean, counter-rotation against the pelvis
    (the shoulders turn the other way), the list taken out so the chest stays upright."""
    out = {}
    trunk = body.trunk
    if not trunk:
        return out
    lean = np.radians(gait["style"].torso_lean) * gait["weight"]
    n = len(trunk)
    for j in trunk:
        w = sk.rest[j][:3, :3]
        r = axis_angle_matrix(w.T @ body.left, lean / n) @ axis_angle_matrix(w.T @ UP, -1.3 * pelvis["yaw"] / n) \
            @ axis_angle_matrix(w.T @ body.forward, -pelvis["tilt"] / n)
        out[j] = r
    for j in body.neck:  # the head keeps looking ahead
        w = sk.rest[j][:3, :3]
        out[j] = axis_angle_matrix(w.T @ body.left, -0.6 * lean)
    return out


def _arm_rotations(body, sk, gait):
    out = {}
    amp, w, phase = gait["amp"], gait["weight"], gait["phase"]
    for side, sign in (("R", -1.0), ("L", 1.0)):
        upper, fore = body.arms[side]
        if upper is None or fore is None:
            continue
        out_dir = body.right if side == "R" else body.left
        swing = sign * w * amp["arm"] * np.cos(2 * np.pi * phase)
        d0 = unit(-UP + np.tan(np.radians(8.0)) * out_dir)
        d = np.einsum("fij,j->fi", axis_angle_matrix(body.right, swing), d0)
        wu, wf = sk.rest[upper][:3, :3], sk.rest[fore][:3, :3]
        ru = rotation_between(np.broadcast_to(wu[:, 1], d.shape), d)
        elbow = w * amp["elbow"] * (1 + 0.5 * np.clip(swing / np.maximum(amp["arm"], 1e-6), 0, 1)) + (1 - w) * np.radians(5)
        e = np.einsum("fij,fj->fi", axis_angle_matrix(body.right, elbow), d)
        cur = ru @ wf
        rf = rotation_between(cur[:, :, 1], e)
        out[upper] = wu.T @ ru @ wu
        out[fore] = np.swapaxes(cur, 1, 2) @ rf @ cur
    return out


def _pose(body, sk, pelvis, gait, feet, times, fps, frame_start, a2w):
    n, J = len(times), sk.joint_count
    frames = frame_start + np.arange(n, dtype=float)
    basis = np.broadcast_to(np.eye(4), (n, J, 4, 4)).copy()
    for j, r in {**_trunk_rotations(body, sk, pelvis, gait), **_arm_rotations(body, sk, gait)}.items():
        basis[:, j, :3, :3] = r
    # the root: the rest pose carried by M = T(p) R T(-c0) from armature space to the world
    m = np.broadcast_to(np.eye(4), (n, 4, 4)).copy()
    m[:, :3, :3] = pelvis["rotation"]
    m[:, :3, 3] = pelvis["position"] - np.einsum("fij,j->fi", pelvis["rotation"], body.hip_centre)
    root = sk.root
    pos, quat = decompose(m @ sk.rest[root])
    tr = Trajectories(frames, fps, rotations.from_matrix(basis[..., :3, :3]), basis[..., :3, 3], a2w)
    tr = tr.with_root_pose(sk, pos, quat)
    basis = tr.basis()
    yield 0.5
    world = sk.world_frames(basis, a2w)
    reached = np.ones((n, 2), bool)
    for c, side in enumerate("LR"):
        ik = body.ik[side]
        foot = body.feet[side]
        fw = feet[side]["frames"]
        for f in range(n):
            parent = ik.parent_frame(world[f])
            target = fw[f]
            heading = target[:3, :3] @ foot.rel_foot[:3, :3].T[:, 1]
            knee_dir = unit(np.r_[heading[:2], 0.0])
            axis = target[:3, 3] - (parent @ ik.skeleton.rest_local[ik.upper])[:3, 3]
            nrm, u, v = ik.swivel_basis(parent, axis)
            swivel = np.arctan2(knee_dir @ v, knee_dir @ u)
            q, _, ok = ik.solve(parent, target, swivel)
            reached[f, c] = ok
            for j, qq in zip((ik.upper, ik.lower, ik.end), q):
                basis[f, j, :3, :3] = rotations.to_matrix(qq)
            if foot.toe is not None:
                basis[f, foot.toe, :3, :3] = _toe_local(foot, sk, feet[side]["toe"][f])
        yield 0.5 + 0.25 * (c + 1)
    t, q = decompose(basis)
    return Trajectories(frames, fps, rotations.make_continuous(q), t, a2w), reached


def _toe_local(foot, sk, pitch):
    """Local rotation of the toe bone pitched by `pitch` about the sole's lateral axis relative to
    the foot: while the foot rolls over the ball (heel up), this keeps the toe flat on the ground."""
    # toe world = sole R_x(p_foot + pitch) rel_toe; foot world = sole R_x(p_foot) rel_foot
    rl = sk.rest_local[foot.toe][:3, :3]
    return (foot.rel_foot[:3, :3] @ rl).T @ rot_x(pitch) @ foot.rel_toe[:3, :3]
