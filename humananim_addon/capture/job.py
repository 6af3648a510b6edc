"""Live capture in Blender (issue 10): device settings, the live session on the active armature,
the display step that applies the newest sample of every device to the pose bones, recording
into a new action, glove calibration, grasping of scene objects and its viewport overlay.

Everything that talks to a device runs in bpy-free reader threads (humananim_addon/devices); this module
only runs on the main thread: `step()` is what the modal operator calls on every timer event,
and what tests and batch jobs call in a loop (timers never fire in the bpy module)."""

import collections
import gc
import logging
import time

import bpy
import numpy as np

from ...solver import rotations
from ...solver.body_roles import FINGERS, sided
from ..devices import cyberglove, fob, hidglove, mvn, sim_fob, sim_glove, sim_mvn, vmc
from ...solver.anatomical_converter import AnatomicalConverter, CalibrationError
from ..devices.glove_calibration import GloveCalibration, joint_rotations
from ...solver.hands.grasp_automaton import GraspAutomaton
from ...solver.hands.sensors import Box, Sphere, default_hand_sensors, sensor_centres
from ..devices.replay import ReplayDevice
from ..devices.samples import tracker_reading
from ..devices.session import Session, Take
from ...solver.errors import HumanAnimError, MotionError
from ...solver.trajectories import Trajectories
from .. import actions
from ..armature import armature_to_world, skeleton_from_armature
from .drawing import disable_overlay, enable_overlay, overlay_geometry  # noqa: F401 (the operators' and tests' names)
from .properties import DEVICE_KINDS, GLOVE_KINDS, _register, _unregister  # noqa: F401 (DEVICE_KINDS: the operator's name)

log = logging.getLogger(__name__)

LIVE = None  # the running LiveCapture (memory only, never in the .blend)


def register():
    _register()


def unregister():
    global LIVE
    if LIVE is not None:
        LIVE.close()
        LIVE = None
    disable_overlay()
    _unregister()


# -- devices from settings ------------------------------------------------------------------------------
def _ints(text, what):
    try:
        out = tuple(int(x) for x in text.replace(";", ",").split(",") if x.strip())
    except ValueError:
        raise HumanAnimError(f"{what}: write numbers separated by commas, not '{text}'") from None
    if not out:
        raise HumanAnimError(f"{what}: none given")
    return out


def build_device(item):
    """(driver, simulator or None) for one device's settings."""
    name = item.name or item.kind.lower()
    if item.kind == "FLOCK":
        birds = _ints(item.birds, f"{name}: Birds")
        sim = None
        port = item.port
        if item.standalone and len(birds) != 1:
            raise HumanAnimError(f"{name}: a standalone bird is one bird (Birds: {item.birds})")
        if item.simulate:
            if item.extended_range and 1 in birds:
                raise HumanAnimError(f"{name}: an Extended Range Controller is address 1; its birds start at 2")
            sim = sim_fob.FlockSimulator(birds=birds, extended_range=item.extended_range, rate=item.rate or 100.0,
                                         standalone=item.standalone)
            port = sim.port
        dev = fob.FlockOfBirds(name, port, item.baud, birds=birds, record=item.record, mode=item.mode,
                               hemisphere=item.hemisphere, standalone=item.standalone,
                               settle=0.05 if item.simulate else 0.3)
        return dev, sim
    if item.kind == "CYBERGLOVE":
        n = int(item.sensors)
        sim = sim_glove.CyberGloveSimulator(sensors=n, rate=item.rate or 100.0) if item.simulate else None
        dev = cyberglove.CyberGlove(name, sim.port if sim else item.port, item.baud, sensors=n,
                                    mode="POLL" if item.mode == "POINT" else "STREAM", hand=item.hand,
                                    settle=0.02 if sim else 0.1, time_stamp=item.time_stamp,
                                    status_byte=item.status_byte)
        return dev, sim
    if item.kind == "HID_GLOVE":
        return hidglove.HidGlove(name, decoder=item.decoder, hand=item.hand), None
    if item.kind == "MVN":
        sim = None
        if item.simulate:
            if item.mvn_port == 0:
                raise HumanAnimError(f"{name}: a simulated MVN stream needs a UDP port")
            sim = sim_mvn.MVNSender(port=item.mvn_port, host=item.host, actors=(item.actor,), rate=item.rate or 60.0)
        return mvn.MVNReceiver(name, host=item.host, port=item.mvn_port), sim
    if item.kind == "VMC":
        return vmc.VMCReceiver(name, host=item.host, port=item.vmc_port), None
    if item.kind == "REPLAY":
        path = bpy.path.abspath(item.filepath)
        if path.lower().endswith(".json"):  # a take saved by Save Take
            try:
                return ReplayDevice(name, Take.load(path)), None
            except (OSError, ValueError, KeyError) as exc:
                raise HumanAnimError(f"cannot read the take '{path}': {exc}") from None
        return ReplayDevice(name, path, rate=item.rate or None), None
    raise HumanAnimError(f"unknown device kind {item.kind}")


def mvn_attachments(sk, name, actor):
    """{(device, channel): bone} of an MVN actor's body segments on the rig, through body roles;
    the segments without a bone of their role (the rig has no such bone) are not attached."""
    out = {}
    for segment, role in mvn.SEGMENT_ROLES.items():
        bone = sk.roles.bone(role)
        if bone is not None and bone not in out.values():
            out[(name, mvn.channel(actor, segment))] = bone
    if not out:
        raise HumanAnimError(f"{name}: the rig has none of the body roles MVN's segments drive")
    return out


def glove_resolution(item):
    """One step of the glove's raw values."""
    return 1.0 if item.kind == "CYBERGLOVE" else hidglove.DECODERS[item.decoder].resolution


def glove_layout(item):
    if item.kind == "CYBERGLOVE":
        return cyberglove.LAYOUTS[int(item.sensors)]
    if item.decoder not in hidglove.DECODERS:
        raise HumanAnimError(f"{item.name}: no HID glove decoder '{item.decoder}' (known: "
                             f"{', '.join(sorted(hidglove.DECODERS))})")
    return hidglove.DECODERS[item.decoder].layout


# -- the live session ---------------------------------------------------------------------------------
class LiveCapture:
    """A session on one armature: devices, converter, glove calibrations, grasping, recording."""

    def __init__(self, obj, scene, settings):
        from ..rig.capability import refuse_control_rig
        refuse_control_rig(obj, "Live Capture", "capture onto a plain FK armature (a BVH import, the metarig)")
        self.obj_name = obj.name
        self.skeleton = sk = skeleton_from_armature(obj, scene, require=False)
        self.sims, devices, self.attach, self.gloves = [], [], {}, {}
        self.glove_resolution = {}
        root_key = None
        try:
            for item in settings.devices:
                name = item.name or item.kind.lower()
                if item.kind == "FLOCK":  # even a device not in use: a replayed take of it drives the rig
                    birds = _ints(item.birds, f"{name}: Birds")
                    for bird, bone in zip(birds, [b.strip() for b in item.bones.split(",")]):
                        if not bone:
                            continue
                        if sk.find(bone) is None:
                            raise HumanAnimError(f"{name}: no bone named '{bone}' in '{obj.name}'")
                        key = (name, f"bird{bird}")
                        self.attach[key] = bone
                        if sk.index(bone) == sk.root and root_key is None:
                            root_key = key
                if item.kind == "MVN":  # every body segment on the bone of its role, for the converter
                    for key, bone in mvn_attachments(sk, name, item.actor).items():
                        self.attach[key] = bone
                        if sk.index(bone) == sk.root and root_key is None:
                            root_key = key
                if item.kind in GLOVE_KINDS:
                    self.gloves[name] = (item.hand, glove_layout(item))
                    self.glove_resolution[name] = glove_resolution(item)
                if not item.use:
                    continue
                dev, sim = build_device(item)
                devices.append(dev)
                if sim is not None:
                    self.sims.append(sim.start())
            if not devices:
                raise HumanAnimError("no device is in use")
        except Exception:
            for sim in self.sims:
                sim.stop()
            raise
        self.session = Session(devices)
        self.session.gestures.enabled = settings.gestures
        self.session.take_name = settings.take_name
        self.converter = AnatomicalConverter(sk, self.attach, root=root_key) if self.attach else None
        self.session.converter = self.converter
        for name, (_, layout) in self.gloves.items():
            self.session.glove_calibrations[name] = GloveCalibration.nominal(layout)
        self.glove_poses = {}
        self.grasp = {}
        for name, (side, _) in self.gloves.items():
            if sk.role_index(sided("hand", side)) is not None and any(sk.roles.chain(sided(f, side)) for f in FINGERS):
                self.grasp[side] = GraspAutomaton(sk, default_hand_sensors(sk, side), side)
        self.flex_sign = {side: _flex_sign(sk, side) for side in "LR"}
        self.pose_order = np.array([obj.pose.bones.find(n) for n in sk.names])
        self.rest_local = sk.rest_local
        self.rest_q = rotations.from_matrix(sk.rest[:, :3, :3])
        self.held = None  # (object name, automaton side) of a grasped object
        self.applied = 0
        self.latency = collections.deque(maxlen=4096)  # seconds from a sample's decoding to its pose
        self.step_cpu = collections.deque(maxlen=4096)
        self.record_frame = scene.frame_current
        self.overlay = None
        self.reduction = None
        self._take_seen = None
        self._takes_written = 0
        self.gesture_actions = []
        self._skeleton_maps = {}
        if settings.quaternion_bones:
            for n in sk.names:
                pb = obj.pose.bones[n]
                if pb.rotation_mode != "QUATERNION":
                    q = _pose_bone_quaternion(pb)
                    pb.rotation_mode = "QUATERNION"
                    pb.rotation_quaternion = q
        # Python's cyclic garbage collector stops every thread (readers, pump, display step) while
        # it runs; its full passes over Blender's whole Python heap take hundreds of milliseconds
        # on a loaded machine. What exists now is left out of them until the session closes.
        gc.collect()
        gc.freeze()
        self.session.start()

    def close(self):
        gc.unfreeze()
        self.session.stop()
        for sim in self.sims:
            sim.stop()
        self.sims = []

    # -- solving one pose ---------------------------------------------------------------------
    def solve(self, newest, basis=None):
        """Local bases (J, 4, 4) from the newest samples (sample-and-hold between devices)."""
        sk = self.skeleton
        if basis is None:
            basis = np.tile(np.eye(4), (sk.joint_count, 1, 1))
        pose = {k: tracker_reading(s) for k, s in newest.items()
                if s.kind == "pose" and "quaternion" in s.data and k in self.attach}
        if pose and self.converter is not None and self.converter.calibrated:
            basis = self.converter.solve(pose)
        for key, s in newest.items():
            if s.kind == "skeleton":
                self._apply_skeleton(basis, s)
        for key, s in newest.items():
            if s.kind == "glove" and s.device in self.gloves:
                self._apply_glove(basis, s)
        return basis

    def _apply_skeleton(self, basis, s):
        sk = self.skeleton
        d = s.data
        mapping = self._skeleton_map(s.device, d)
        for j, name in mapping.items():
            entry = d["bones"].get(name)
            if entry is None:
                continue
            q = np.asarray(entry[1], float)
            if j == sk.root and d.get("root") is not None:  # VMC: the root object carries the hips
                q = rotations.multiply(np.asarray(d["root"][1], float), q)
            a = self.rest_q[j]
            basis[j, :3, :3] = rotations.to_matrix(rotations.multiply(rotations.multiply(rotations.conjugate(a), q), a))
        r = sk.root
        head = None
        if d.get("root_position") is not None:
            head = np.asarray(d["root_position"], float)
        elif d.get("root") is not None and any(j == r for j in mapping):
            root_p, root_q = d["root"]
            hips = d["bones"][mapping[r]][0]
            head = np.asarray(root_p, float) + rotations.rotate(np.asarray(root_q, float), np.asarray(hips, float))
        if head is not None and r in mapping:
            basis[r, :3, 3] = sk.rest[r, :3, :3].T @ (head - sk.rest[r, :3, 3])

    def _skeleton_map(self, device, d):
        """{rig joint: sample bone name}: same names first, else through body roles."""
        key = (device, len(d["bones"]))
        if key in self._skeleton_maps:
            return self._skeleton_maps[key]
        sk, out = self.skeleton, {}
        roles = d.get("roles", {})
        for name in d["bones"]:
            j = sk.find(name)
            if j is None and name in roles:
                role, k = roles[name]
                chain = sk.roles.chain(role)
                j = sk.find(chain[k]) if k < len(chain) else None
            if j is not None:
                out[j] = name
        self._skeleton_maps[key] = out
        return out

    def _apply_glove(self, basis, s):
        sk = self.skeleton
        side, _ = self.gloves[s.device]
        angles = self.session.glove_calibrations[s.device].angles(s.data["raw"])
        sign = self.flex_sign[side]
        angles = {k: (v * sign if k[2] == "flex" else v) for k, v in angles.items()}
        joints, quats = [], []
        for (finger, k), q in joint_rotations(angles, side).items():
            if finger == "palm":
                continue
            if finger == "hand":
                j = sk.role_index(sided("hand", side))
                if j is None or any(sk.index(b) == j for b in self.attach.values()):
                    continue  # a 6-D sensor on the hand wins over the glove's wrist sensors
            else:
                chain = sk.roles.chain(sided(finger, side))
                if k >= len(chain):
                    continue
                j = sk.index(chain[k])
            joints.append(j)
            quats.append(q)
        if joints:
            basis[joints, :3, :3] = rotations.to_matrix(np.array(quats))

    # -- the display step ---------------------------------------------------------------------------
    def step(self, context):
        """Apply the newest sample of every device to the rig; True when something was applied."""
        t0, c0 = time.perf_counter(), time.thread_time()
        obj = bpy.data.objects.get(self.obj_name)
        if obj is None:
            raise HumanAnimError(f"the captured armature '{self.obj_name}' is gone")
        self.session.pump()
        self._gesture_takes(context)
        newest = self.session.newest()
        if not newest:
            return False
        self.last_applied = newest  # what this step showed (the pump thread moves on meanwhile)
        basis = self.solve(newest)
        if self.grasp:
            basis = self._grasp(context, obj, basis)
        self._write_pose(obj, basis)
        now = time.perf_counter()
        self.latency.extend(now - s.time for s in newest.values() if s.time > getattr(self, "_last_time", 0.0))
        self._last_time = max(s.time for s in newest.values())
        self.applied += 1
        self.step_cpu.append((time.thread_time() - c0, now - t0))
        return True

    def _gesture_takes(self, context):
        """Recording started or stopped by a glove gesture (in the pump thread): the take starts at
        the current frame, and a finished take becomes an action here, on the main thread."""
        take = self.session.take if self.session.recording else None
        if take is not None and take is not self._take_seen:
            self._take_seen = take
            self.record_frame = context.scene.frame_current
        for take in self.session.takes[self._takes_written:]:
            self._takes_written += 1
            if take.count():
                self.gesture_actions.append(self.write_take(context, take))

    def _write_pose(self, obj, basis):
        sk = self.skeleton
        n = len(obj.pose.bones)
        quats = np.empty(n * 4)
        obj.pose.bones.foreach_get("rotation_quaternion", quats)
        quats = quats.reshape(n, 4)
        q = rotations.from_matrix(basis[:, :3, :3])
        quats[self.pose_order] = q
        obj.pose.bones.foreach_set("rotation_quaternion", quats.ravel())
        for j, name in enumerate(sk.names):
            pb = obj.pose.bones[name]
            if pb.rotation_mode == "AXIS_ANGLE":
                pb.rotation_axis_angle = rotations.to_axis_angle(q[j])
            elif pb.rotation_mode != "QUATERNION":
                pb.rotation_euler = rotations.to_euler(q[j], pb.rotation_mode)
        r = sk.root
        obj.pose.bones[sk.names[r]].location = basis[r, :3, 3] / sk.unit_scale
        obj.update_tag()

    def _world_of(self, obj, scene):
        """Forward kinematics to world frames with the rest frames solved once."""
        base = armature_to_world(obj, scene)
        parents, rest_local = self.skeleton.parents, self.rest_local

        def fk(basis):
            local = rest_local @ basis
            world = np.empty_like(local)
            for j, p in enumerate(parents):
                world[j] = (base if p < 0 else world[p]) @ local[j]
            return world
        return fk

    def _grasp(self, context, obj, basis):
        scene = context.scene
        settings = scene.humananim_capture
        objects = list(settings.grasp_collection.all_objects) if settings.grasp_collection else []
        shapes = [shape_of(o) for o in objects]
        world_of = self._world_of(obj, scene)
        self.overlay = []
        for side, ga in self.grasp.items():
            basis, world = ga.update(basis, shapes, world_of)
            held = ga.object_pose(world)
            if held is not None and ga.object is not None:
                target = objects[ga.object]
                scale = np.diag(list(target.matrix_world.to_scale()) + [1.0])
                target.matrix_world = _matrix(held @ scale)
            centres = sensor_centres(ga.sensors, world, self.skeleton)
            self.overlay.append((ga.state, ga.colour, centres, ga.touching.copy(), world, ga))
        return basis

    # -- calibration and recording -------------------------------------------------------------------
    def calibrate(self):
        if self.converter is None:
            raise CalibrationError("no 6-D sensor is strapped on a bone (Bones of the Flock of Birds device)")
        self.session.pump()
        self.converter.calibrate(self.session.pose_readings())

    def calibrate_glove(self, pose):
        """Store the newest glove record as the flat hand or the fist; both give the calibration."""
        self.session.pump()
        newest = self.session.newest()
        done = []
        for name, (_, layout) in self.gloves.items():
            s = newest.get((name, "glove"))
            if s is None:
                raise CalibrationError(f"{name}: no glove record yet")
            poses = self.glove_poses.setdefault(name, {})
            poses[pose] = np.array(s.data["raw"], float)
            if "FLAT" in poses and "FIST" in poses:
                self.session.glove_calibrations[name] = GloveCalibration.from_poses(
                    layout, poses["FLAT"], poses["FIST"], self.glove_resolution[name])
                done.append(name)
            elif "FLAT" in poses:
                cal = self.session.glove_calibrations[name]
                cal.offsets = poses["FLAT"].copy()
        return done

    def start_recording(self, scene):
        self.record_frame = scene.frame_current
        self._take_seen = self.session.start_recording(scene.humananim_capture.take_name)

    def stop_recording(self, context):
        """The take as a new action on the rig (None when nothing was recorded)."""
        take = self.session.stop_recording()
        self._takes_written = len(self.session.takes)  # written here, not again by the step
        if take is None or take.count() == 0:
            return None, take
        return self.write_take(context, take), take

    def take_trajectories(self, scene, take):
        """The take's poses at every sample time (samples within 1 ms make one pose: Take.poses)."""
        obj = bpy.data.objects[self.obj_name]
        fps = actions.scene_fps(scene)
        poses = take.poses()
        t_first = poses[0][0]
        # until a channel's first sample in the take, hold that sample (a full pose from the start)
        latest = {k: v[0] for k, v in take.samples.items() if v}
        times, bases = [], []
        for t, group in poses:
            for s in group:
                latest[(s.device, s.channel)] = s
            times.append(t)
            bases.append(self.solve(latest))
        bases = np.array(bases)
        frames = self.record_frame + (np.array(times) - t_first) * fps
        trans = bases[:, :, :3, 3].copy()
        quats = rotations.make_continuous(rotations.from_matrix(bases[:, :, :3, :3]))
        return Trajectories(frames, fps, quats, trans, armature_to_world(obj, scene))

    def write_take(self, context, take):
        obj = bpy.data.objects[self.obj_name]
        traj = self.take_trajectories(context.scene, take)
        if traj.frame_count < 2:
            raise MotionError("the take has a single pose: record longer")
        ad = obj.animation_data
        source = ad.action if ad else None
        action = actions.write_action(obj, self.skeleton, traj, take.name, source=source)
        settings = context.scene.humananim_capture
        if settings.reduce_keys:
            from .. import sequence
            sel = sequence.select_channels(obj, context.scene, action, "ALL")
            self.reduction = sequence.compress(obj, context.scene, action, sel, degrees=settings.reduce_degrees,
                                               centimetres=0.5, replace=True)
        return action

    def status(self):
        out = self.session.status()
        for d in out:
            d["latency_ms"] = round(1000 * float(np.median(self.latency)), 2) if self.latency else None
        return out


def _flex_sign(sk, side):
    """+1 when a positive X rotation curls the fingers toward the palm on this rig, else -1: the
    palm side is where the thumb's base lies below the knuckles' line."""
    index, pinky, thumb = (sk.roles.chain(sided(f, side)) for f in ("index", "pinky", "thumb"))
    if not index or not thumb:
        return 1.0
    j = sk.index(index[0])
    head, y, z = sk.rest[j, :3, 3], sk.rest[j, :3, 1], sk.rest[j, :3, 2]
    palm = sk.rest[sk.index(thumb[0]), :3, 3] - head
    if pinky:
        across = sk.rest[sk.index(pinky[0]), :3, 3] - head
        n = np.cross(y, across)
        palm = n * np.sign(np.dot(n, palm)) if np.linalg.norm(n) > 1e-9 else palm
    # a positive rotation about X moves the bone's tail toward +Z
    return 1.0 if np.dot(z, palm) >= 0 else -1.0


def _pose_bone_quaternion(pb):
    if pb.rotation_mode == "AXIS_ANGLE":
        return rotations.from_axis_angle(np.array(pb.rotation_axis_angle))
    if pb.rotation_mode == "QUATERNION":
        return np.array(pb.rotation_quaternion)
    return rotations.from_euler(np.array(pb.rotation_euler), pb.rotation_mode)


def _matrix(m):
    from mathutils import Matrix
    return Matrix([list(r) for r in m])


def shape_of(obj):
    """A sphere or a box for a graspable object: an Empty shown as a sphere, a mesh whose vertices
    all lie at one distance from its centre, else its bounding box."""
    m = np.array(obj.matrix_world, float)
    scale = np.linalg.norm(m[:3, :3], axis=0)
    frame = m.copy()
    frame[:3, :3] /= scale
    if obj.type == "EMPTY":
        radius = obj.empty_display_size * float(scale.max())
        return Sphere(m[:3, 3], radius) if obj.empty_display_type == "SPHERE" else \
            Box(frame, np.full(3, radius))
    corners = np.array([list(c) for c in obj.bound_box])
    lo, hi = corners.min(axis=0), corners.max(axis=0)
    centre_local = (lo + hi) / 2
    if obj.type == "MESH" and len(obj.data.vertices) > 12:
        co = np.empty(len(obj.data.vertices) * 3)
        obj.data.vertices.foreach_get("co", co)
        r = np.linalg.norm((co.reshape(-1, 3) - centre_local) * scale, axis=1)
        if np.ptp(scale) < 1e-6 * scale.max() and np.ptp(r) < 0.03 * r.max():
            return Sphere(m[:3, :3] @ centre_local + m[:3, 3], float(r.mean()))
    frame[:3, 3] = m[:3, :3] @ centre_local + m[:3, 3]
    return Box(frame, (hi - lo) / 2 * scale)


# -- module-level entry points (operators, CLI, tests) ---------------------------------------------------
def connect(obj, scene):
    global LIVE
    if LIVE is not None:
        raise HumanAnimError("a capture session is already running: disconnect first")
    settings = scene.humananim_capture
    if len(settings.devices) == 0:
        raise HumanAnimError("add a device first")
    LIVE = LiveCapture(obj, scene, settings)
    return LIVE


def disconnect(context=None):
    """End the session; a take being recorded becomes an action first (nothing recorded is lost)."""
    global LIVE
    live, LIVE = LIVE, None
    if live is None:
        return None
    action = None
    try:
        if live.session.recording and context is not None:
            action, _ = live.stop_recording(context)
    finally:
        live.close()
    return action


def add_device(scene, kind, **values):
    settings = scene.humananim_capture
    item = settings.devices.add()
    item.kind = kind
    item.name = values.pop("name", f"{kind.lower()}{len(settings.devices)}")
    for k, v in values.items():
        setattr(item, k, v)
    settings.device_index = len(settings.devices) - 1
    return item
