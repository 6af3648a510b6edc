"""Control-rig discovery: which control the animator keys to turn a deform bone.

On a control rig (a generated Rigify rig) the deform bones copy mechanism bones that copy the FK
or IK controls, and an IK/FK switch property (a custom property of a pose bone) drives the
influence of those constraints: keys on the deform bones do nothing. A deform bone's FK control
is found by following its constraints' targets and parents upstream, keeping the controls whose
rest frame matches the bone's, and checking each one by turning it and watching the bone (with the
switch values, fewest changes first, that make it drive). Nothing here is name-based."""

import itertools
import re
from dataclasses import dataclass, field, replace

import bpy
import numpy as np

from ...solver import rotations
from ...solver.errors import HumanAnimError

_CON_PATH = re.compile(r'^pose\.bones\["((?:[^"\\]|\\.)*)"\]\.constraints\[')
_PROP_PATH = re.compile(r'^pose\.bones\["((?:[^"\\]|\\.)*)"\]\["((?:[^"\\]|\\.)*)"\]$')
_PROBE_ANGLE = 0.3  # radians the probe turns a candidate control


@dataclass
class ControlRig:
    frozen: tuple  # driven joints that are no role bone and no control: the solver keeps them
    controls: dict = field(default_factory=dict)  # joint -> (control bone, control rest in joint rest)
    switches: dict = field(default_factory=dict)  # (bone, property) -> value keyed so the controls drive
    fixed: dict = field(default_factory=dict)  # every switch value the mapping relied on
    stretched: tuple = ()  # connected driven joints: the FK controls keep their lengths
    actual: np.ndarray = None  # the last pose given to `rigid`, as read

    def rigid(self, basis):
        """Local bases (..., J, 4, 4) without the stretch a constraint-driven pose can carry (Rigify's
        IK stretch): the FK controls rebuild connected bones at their rest lengths."""
        self.actual = np.array(basis, dtype=float)  # what Blender shows: the controls' parents are read from it
        basis = self.actual.copy()
        basis[..., list(self.stretched), :3, 3] = 0.0
        return basis

    def solver_skeleton(self, skeleton):
        """The skeleton the solver moves: frozen joints lose their DOFs."""
        if not self.frozen:
            return skeleton
        dof = skeleton.dof.copy()
        dof[list(self.frozen)] = False
        return replace(skeleton, dof=dof)


@dataclass
class FKControl:
    """The control that turns a deform bone: its name, its rest frame in the bone's rest frame
    (metres), and the switch values {(bone, property): value} with which it drives the bone."""

    name: str
    offset: np.ndarray
    switches: dict = field(default_factory=dict)


# --- what the rig's bones are ----------------------------------------------------------------
def driven(pb):
    """True when a pose bone follows other bones through a constraint."""
    return any(not c.mute and c.influence > 0 for c in pb.constraints)


def is_control(obj, name):
    """A bone the animator keys: no constraints, some free rotation, shown in a visible collection."""
    bone, pb = obj.data.bones[name], obj.pose.bones[name]
    if bone.hide or any(not c.mute for c in pb.constraints) or all(pb.lock_rotation):
        return False
    collections = list(getattr(bone, "collections", ()))
    return not collections or any(c.is_visible for c in collections)


def followed(obj, pb):
    """The bones a pose bone's constraints take their targets from."""
    out = []
    for c in pb.constraints:
        if c.mute:
            continue
        pairs = [(getattr(c, "target", None), getattr(c, "subtarget", ""))]
        pairs += [(t.target, t.subtarget) for t in getattr(c, "targets", ())]  # Armature constraint
        out += [n for t, n in pairs if t == obj and n in obj.pose.bones]
    return out


def upstream(obj, name, depth=8):
    """{bone: steps} of the bones `name` follows (constraint targets and parents, recursively)."""
    seen, queue = {name: 0}, [name]
    while queue:
        x = queue.pop(0)
        if seen[x] >= depth:
            continue
        pb = obj.pose.bones[x]
        for y in followed(obj, pb) + ([pb.parent.name] if pb.parent else []):
            if y not in seen:
                seen[y] = seen[x] + 1
                queue.append(y)
    return seen


def switch_drivers(obj):
    """(constrained bone, switch) pairs in the order of the object's drivers: the custom
    properties of pose bones that drive the influence of a bone's constraints (Rigify's IK_FK on
    the limb's parent bone)."""
    ad = obj.animation_data
    out = []
    for d in (ad.drivers if ad else ()):
        m = _CON_PATH.match(d.data_path)
        if not m:
            continue
        bone = bpy.utils.unescape_identifier(m.group(1))
        for v in d.driver.variables:
            if v.type != "SINGLE_PROP" or v.targets[0].id != obj:
                continue
            p = _PROP_PATH.match(v.targets[0].data_path or "")
            if not p:
                continue
            key = (bpy.utils.unescape_identifier(p.group(1)), bpy.utils.unescape_identifier(p.group(2)))
            if key[0] in obj.pose.bones and isinstance(obj.pose.bones[key[0]].get(key[1]), float):
                out.append((bone, key))
    return out


def switches_of(drivers, bones):
    """The switches (from `switch_drivers`) of the constraints of `bones`, each once."""
    return list(dict.fromkeys(key for bone, key in drivers if bone in bones))


def _rest_m(obj, name, scale):
    m = np.array(obj.data.bones[name].matrix_local, dtype=float)
    m[:3, :3] = rotations.to_matrix(rotations.from_matrix(m[:3, :3]))
    m[:3, 3] *= scale
    return m


def _same_rest(a, b, length):
    cos = (np.trace(a[:3, :3].T @ b[:3, :3]) - 1.0) / 2.0
    return np.arccos(np.clip(cos, -1.0, 1.0)) < np.radians(1.0) and np.linalg.norm(a[:3, 3] - b[:3, 3]) < 0.01 * length


def control_rig_for(obj, skeleton, joints):
    """None when none of `joints` (the ones a solver will move) follows a constraint (a plain FK
    rig); else the ControlRig whose joints still need their controls (`map_controls`). The pelvis,
    its ancestors and what moves it (a control rig's torso) and driven bones that are neither a
    role bone nor a control (twist segments, mechanism bones) are frozen."""
    pbs = obj.pose.bones
    if not any(driven(pbs[skeleton.names[j]]) for j in joints):
        return None
    pelvis = skeleton.role_index("pelvis")
    body = set()
    if pelvis is not None:
        body = set(skeleton.ancestors(pelvis)) | {pelvis}
        body |= {skeleton.index(n) for n in upstream(obj, skeleton.names[pelvis]) if skeleton.find(n) is not None}
    frozen = []
    for j in dict.fromkeys(joints):
        name = skeleton.names[j]
        role = skeleton.roles.role_of(name)
        if j in body or (role is None and not is_control(obj, name)):
            frozen.append(j)
    stretched = tuple(j for j in dict.fromkeys(joints) if skeleton.connected[j] and j not in body)
    return ControlRig(tuple(frozen), stretched=stretched)


# --- which control turns a bone ----------------------------------------------------------------
def carries(obj, bone, control):
    """True when turning `control` turns `bone` with it: the bone's head and tail stay put in the
    control's frame and the bone moves."""
    from mathutils import Matrix, Vector
    pbs, view_layer = obj.pose.bones, bpy.context.view_layer
    b, c = pbs[bone], pbs[control]

    def where():
        inv = np.linalg.inv(np.array(c.matrix))
        pts = np.array([tuple(b.head) + (1.0,), tuple(b.tail) + (1.0,)])
        return pts[:, :3], (pts @ inv.T)[:, :3]

    view_layer.update()
    p0, r0 = where()
    keep = c.matrix_basis.copy()
    c.matrix_basis = keep @ Matrix.Rotation(_PROBE_ANGLE, 4, Vector((1.0, 0.0, 0.6)).normalized())
    view_layer.update()
    p1, r1 = where()
    c.matrix_basis = keep
    length = obj.data.bones[bone].length
    return np.abs(r1 - r0).max() < 1e-3 * length and np.linalg.norm(p1 - p0, axis=1).max() > 0.02 * length


def fk_control(obj, bone, scale=1.0, fixed=None):
    """The FKControl that turns deform bone `bone` (the bone itself when the animator keys it),
    following its constraints upstream; None when no control turns it. `fixed` holds switch
    values the caller relies on already; `scale`: metres per armature unit (for the offset). The
    rig's switch values are left as they were."""
    pbs = obj.pose.bones
    drivers = switch_drivers(obj)
    saved = {k: pbs[k[0]][k[1]] for k in switches_of(drivers, set(pbs.keys()))}
    fixed = dict(fixed or {})
    try:
        for (b, p), v in fixed.items():
            pbs[b][p] = v
        if is_control(obj, bone):
            return FKControl(bone, np.eye(4))
        return _search_control(obj, bone, scale, saved, drivers, fixed)
    finally:
        for (b, p), v in saved.items():
            pbs[b][p] = v
        bpy.context.view_layer.update()


def _search_control(obj, name, scale, current, drivers, fixed):
    """The nearest control upstream of `name` whose rest frame matches the bone's (not shorter:
    tweak controls sit on top of the chain) and that turns it, trying the switches not in `fixed`
    with the fewest changes from `current` first. Leaves the found switch values set."""
    pbs = obj.pose.bones
    up = upstream(obj, name)
    rest = _rest_m(obj, name, scale)
    length = obj.data.bones[name].length
    candidates = sorted((d, i, c) for i, (c, d) in enumerate(up.items())
                        if d > 0 and is_control(obj, c) and obj.data.bones[c].length >= 0.9 * length
                        and _same_rest(rest, _rest_m(obj, c, scale), length * scale))
    free = [k for k in switches_of(drivers, set(up)) if k not in fixed]
    options = [tuple(dict.fromkeys((float(current[k]), 1.0, 0.0))) for k in free]
    combos = sorted(itertools.product(*options), key=lambda vs: sum(v != float(current[k]) for k, v in zip(free, vs)))
    for _, _, c in candidates:
        for values in combos:
            for k, v in zip(free, values):
                pbs[k[0]][k[1]] = v
            if carries(obj, name, c):
                return FKControl(c, np.linalg.solve(rest, _rest_m(obj, c, scale)), dict(zip(free, values)))
    return None


def map_controls(obj, skeleton, crig, joints, advice="key the FK controls yourself, or map the roles to them"):
    """Each of `joints` (parents first) gets the control carrying it (crig.controls), with the
    switch values that make it drive (crig.fixed; crig.switches: those that must change).
    Raises HumanAnimError for a driven joint no control carries (ending with `advice`)."""
    pbs = obj.pose.bones
    scale = skeleton.unit_scale
    drivers = switch_drivers(obj)
    saved = {k: pbs[k[0]][k[1]] for k in switches_of(drivers, set(pbs.keys()))}
    missing = []
    try:
        for k, v in crig.fixed.items():
            pbs[k[0]][k[1]] = v
        for j in joints:
            if j in crig.controls or j in crig.frozen:
                continue
            name = skeleton.names[j]
            if is_control(obj, name):
                crig.controls[j] = (name, np.eye(4))
                continue
            found = _search_control(obj, name, scale, saved, drivers, crig.fixed)
            if found is None:
                missing.append(name)
                continue
            crig.controls[j] = (found.name, found.offset)
            crig.fixed.update(found.switches)
            crig.switches.update((k, v) for k, v in found.switches.items() if v != float(saved[k]))
    finally:
        for (b, p), v in saved.items():
            pbs[b][p] = v
        bpy.context.view_layer.update()
    if missing:
        raise HumanAnimError(
            f"the bones {', '.join(missing[:4])}{' ...' if len(missing) > 4 else ''} follow other bones through "
            f"constraints and no control of the rig turns them (a control rig whose controls can't be found): keys "
            f"on them would be ignored; {advice}")
