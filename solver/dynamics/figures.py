"""Test and benchmark figures: an 18-segment, 39-DOF human like Oshita's (2003, fig. 2.2), and a
length-proportional mass model for rigs without one.

Segment masses are de Leva's (1996) adjustments of Zatsiorsky-Seluyanov's data (fractions of body
mass for a young adult male); dimensions are those of a 1.75 m, 72 kg man. Each segment is a solid
cylinder along its bone (Y axis, Blender's convention) with a radius from typical girths.
"""

import numpy as np

from .. import rotations
from ..body_roles import RoleMap
from ..skeleton import Skeleton


def bone_frame(head, tail, roll=0.0):
    """Rest frame (4, 4) of a bone from head to tail: Y along the bone, the smallest rotation from
    +Y as Blender's vec_roll_to_mat3 does for roll 0, then `roll` about Y."""
    head = np.asarray(head, float)
    y = np.asarray(tail, float) - head
    y = y / np.linalg.norm(y)
    axis = np.cross([0.0, 1.0, 0.0], y)
    s, c = np.linalg.norm(axis), y[1]
    if s < 1e-9:
        rot = np.eye(3) if c > 0 else np.diag([-1.0, -1.0, 1.0])
    else:
        angle = np.arctan2(s, c)
        rot = rotations.to_matrix(rotations.from_axis_angle(np.r_[angle, axis / s]))
    rot = rot @ rotations.to_matrix(rotations.axis_rotation(1, roll))
    out = np.eye(4)
    out[:3, :3] = rot
    out[:3, 3] = head
    return out


def cylinder_inertia(mass, length, radius):
    """Inertia (3, 3) of a solid cylinder along Y about its centre."""
    axial = 0.5 * mass * radius ** 2
    transverse = mass * (3.0 * radius ** 2 + length ** 2) / 12.0
    return np.diag([transverse, axial, transverse])


# name, parent, head, tail, free axes (local x y z), mass fraction, radius (m), role,
# limits (degrees, per local axis; with Y down the limbs, +X swings a limb backwards). Two free axes
# make a universal joint R = R_first(a) R_second(b) in x, y, z order (model.py): the clavicles and
# hands turn about x then z, the forearms and feet about x then about the bone's own y.
# Facing -Y (Blender's front view), left side at +X. de Leva (1996) male fractions: head 6.94,
# trunk 43.46 (upper 15.96 minus 2 x 1.0 for the clavicles, middle 16.33, lower 11.17), upper arm
# 2.71, forearm 1.62, hand 0.61, thigh 14.16, shank 4.33, foot 1.37 (per cent).
_OSHITA = (
    ("pelvis", None, (0, 0, 0.95), (0, 0, 1.05), "xyz", 11.17, 0.14, "pelvis",
     ((-180, 180), (-180, 180), (-180, 180))),
    ("spine", "pelvis", (0, 0, 1.05), (0, 0, 1.25), "xyz", 16.33, 0.14, "spine",
     ((-20, 45), (-30, 30), (-25, 25))),
    ("chest", "spine", (0, 0, 1.25), (0, 0, 1.45), "xyz", 13.96, 0.15, "chest",
     ((-20, 40), (-30, 30), (-25, 25))),
    ("head", "chest", (0, 0, 1.50), (0, 0, 1.75), "xyz", 6.94, 0.09, "head",
     ((-50, 60), (-70, 70), (-40, 40))),
    ("clavicle.L", "chest", (0.02, 0, 1.42), (0.18, 0.02, 1.42), "xz", 1.0, 0.04, "clavicle.L",
     ((-15, 30), (0, 0), (-20, 15))),
    ("upper_arm.L", "clavicle.L", (0.18, 0.02, 1.42), (0.20, 0.02, 1.12), "xyz", 2.71, 0.045, "upper_arm.L",
     ((-180, 60), (-90, 90), (-30, 170))),
    ("forearm.L", "upper_arm.L", (0.20, 0.02, 1.12), (0.21, 0.0, 0.86), "xy", 1.62, 0.035, "forearm.L",
     ((-150, 0), (-80, 80), (0, 0))),
    ("hand.L", "forearm.L", (0.21, 0.0, 0.86), (0.21, 0.0, 0.68), "xz", 0.61, 0.03, "hand.L",
     ((-70, 80), (0, 0), (-25, 35))),
    ("clavicle.R", "chest", (-0.02, 0, 1.42), (-0.18, 0.02, 1.42), "xz", 1.0, 0.04, "clavicle.R",
     ((-15, 30), (0, 0), (-15, 20))),
    ("upper_arm.R", "clavicle.R", (-0.18, 0.02, 1.42), (-0.20, 0.02, 1.12), "xyz", 2.71, 0.045, "upper_arm.R",
     ((-180, 60), (-90, 90), (-170, 30))),
    ("forearm.R", "upper_arm.R", (-0.20, 0.02, 1.12), (-0.21, 0.0, 0.86), "xy", 1.62, 0.035, "forearm.R",
     ((-150, 0), (-80, 80), (0, 0))),
    ("hand.R", "forearm.R", (-0.21, 0.0, 0.86), (-0.21, 0.0, 0.68), "xz", 0.61, 0.03, "hand.R",
     ((-70, 80), (0, 0), (-35, 25))),
    ("thigh.L", "pelvis", (0.09, 0, 0.92), (0.09, 0, 0.50), "xyz", 14.16, 0.075, "thigh.L",
     ((-120, 20), (-45, 45), (-30, 45))),
    ("shin.L", "thigh.L", (0.09, 0, 0.50), (0.09, 0.01, 0.08), "x", 4.33, 0.05, "shin.L",
     ((0, 145), (0, 0), (0, 0))),
    ("foot.L", "shin.L", (0.09, 0.01, 0.08), (0.09, -0.13, 0.02), "xy", 1.37, 0.035, "foot.L",
     ((-20, 45), (-35, 20), (0, 0))),
    ("thigh.R", "pelvis", (-0.09, 0, 0.92), (-0.09, 0, 0.50), "xyz", 14.16, 0.075, "thigh.R",
     ((-120, 20), (-45, 45), (-45, 30))),
    ("shin.R", "thigh.R", (-0.09, 0, 0.50), (-0.09, 0.01, 0.08), "x", 4.33, 0.05, "shin.R",
     ((0, 145), (0, 0), (0, 0))),
    ("foot.R", "shin.R", (-0.09, 0.01, 0.08), (-0.09, -0.13, 0.02), "xy", 1.37, 0.035, "foot.R",
     ((-20, 45), (-20, 35), (0, 0))),
)


def oshita_figure(total_mass=72.0):
    """An 18-segment human with 39 rotational DOF plus the 6-DOF pelvis, standing at rest (arms
    down, feet flat with soles at z = 0), Z up, facing -Y."""
    names = [row[0] for row in _OSHITA]
    index = {n: i for i, n in enumerate(names)}
    n = len(names)
    parents = np.array([-1 if row[1] is None else index[row[1]] for row in _OSHITA])
    rest = np.array([bone_frame(row[2], row[3]) for row in _OSHITA])
    lengths = np.array([np.linalg.norm(np.subtract(row[3], row[2])) for row in _OSHITA])
    dof = np.array([[a in row[4] for a in "xyz"] for row in _OSHITA])
    mass = np.array([row[5] for row in _OSHITA]) / 100.0 * total_mass
    com = np.zeros((n, 3))
    com[:, 1] = 0.5 * lengths
    inertia = np.array([cylinder_inertia(m, L, row[6]) for m, L, row in zip(mass, lengths, _OSHITA)])
    limits = np.radians(np.array([row[8] for row in _OSHITA], dtype=float))
    connected = np.array([row[1] is not None and np.allclose(row[2], _OSHITA[index[row[1]]][3])
                          for row in _OSHITA])
    roles = {}
    for row in _OSHITA:
        roles[row[7]] = roles.get(row[7], ()) + (row[0],)
    return Skeleton(names=names, parents=parents, rest=rest, lengths=lengths, connected=connected,
                    dof=dof, limits=limits, mass=mass, com=com, inertia=inertia,
                    roles=RoleMap(roles))


def length_mass_model(skeleton, total_mass=70.0, radius_ratio=0.12):
    """(mass, com, inertia) giving each bone mass in proportion to its length, centred on the bone,
    as a cylinder of radius `radius_ratio` x length: a crude stand-in for rigs without a mass
    model (benchmarks, imported BVH)."""
    lengths = np.asarray(skeleton.lengths, float)
    mass = total_mass * lengths / lengths.sum()
    com = np.zeros((len(lengths), 3))
    com[:, 1] = 0.5 * lengths
    inertia = np.array([cylinder_inertia(m, L, max(radius_ratio * L, 0.01)) for m, L in zip(mass, lengths)])
    return mass, com, inertia


# de Leva (1996) male mass fractions (per cent) by body role, with the head's share split with a
# neck bone, 1 % of the upper trunk for each clavicle and 0.3 % of each foot for its toes.
ROLE_MASS = {"pelvis": 11.17, "spine": 16.33, "chest": 13.96, "neck": 2.0, "head": 4.94,
             "clavicle": 1.0, "upper_arm": 2.71, "forearm": 1.62, "hand": 0.61, "thigh": 14.16,
             "shin": 4.33, "foot": 1.07, "toe": 0.3}
ROLE_RADIUS = {"pelvis": 0.12, "spine": 0.12, "chest": 0.13, "neck": 0.05, "head": 0.09,
               "clavicle": 0.03, "upper_arm": 0.045, "forearm": 0.035, "hand": 0.03,
               "thigh": 0.075, "shin": 0.05, "foot": 0.035, "toe": 0.02}


def role_mass_model(skeleton, total_mass=70.0, min_radius=0.02):
    """(mass, com, inertia) from body roles: de Leva's fractions per role (split by length over a
    role's bones), what is left over by length on bones without a role; each bone a cylinder of
    its role's radius (at least `min_radius`), centred on the bone."""
    sk = skeleton
    lengths = np.maximum(np.asarray(sk.lengths, float), 1e-3)
    J = sk.joint_count
    role_of = {}
    for role, names in sk.roles.bones.items():
        for n in names:
            role_of[sk.index(n)] = role.split(".")[0]
    share = np.zeros(J)
    for role in set(sk.roles.bones):
        bones = [sk.index(n) for n in sk.roles.chain(role)]
        share[bones] = ROLE_MASS.get(role.split(".")[0], 0.0) * lengths[bones] / lengths[bones].sum()
    rest = [j for j in range(J) if j not in role_of]
    left = max(100.0 - share.sum(), 0.0)
    if rest and left > 0.0:
        share[rest] = left * lengths[rest] / lengths[rest].sum()
    mass = total_mass * share / share.sum()
    com = np.zeros((J, 3))
    com[:, 1] = 0.5 * lengths
    radius = [max(ROLE_RADIUS.get(role_of.get(j), 0.1 * lengths[j]), min_radius) for j in range(J)]
    inertia = np.array([cylinder_inertia(m, L, r) for m, L, r in zip(mass, lengths, radius)])
    return mass, com, inertia
