"""Body roles: which bone is the pelvis, the left thigh, the right index finger."""

from dataclasses import dataclass, field
from typing import Mapping

SIDES = ("L", "R")
CENTRE_ROLES = ("pelvis", "chest", "neck", "head")
CENTRE_CHAINS = ("spine",)
SIDED_ROLES = ("clavicle", "upper_arm", "forearm", "hand", "thigh", "shin", "foot", "toe")
FINGERS = ("thumb", "index", "middle", "ring", "pinky")


def sided(role, side):
    return f"{role}.{side}"


SINGLE_ROLES = CENTRE_ROLES + tuple(sided(r, s) for s in SIDES for r in SIDED_ROLES)
CHAIN_ROLES = CENTRE_CHAINS + tuple(sided(f, s) for s in SIDES for f in FINGERS)
ALL_ROLES = SINGLE_ROLES + CHAIN_ROLES

# Without these a physical character cannot stand: such a rig is refused.
REQUIRED_ROLES = ("pelvis", "spine") + tuple(sided(r, s) for s in SIDES for r in ("thigh", "shin", "foot"))


@dataclass(frozen=True)
class RoleMap:
    """Role name to bone names: one bone for a single role, proximal-to-distal for a chain."""

    bones: Mapping[str, tuple] = field(default_factory=dict)

    def bone(self, role):
        names = self.bones.get(role, ())
        return names[0] if names else None

    def chain(self, role):
        return tuple(self.bones.get(role, ()))

    def missing(self, required=REQUIRED_ROLES):
        return [r for r in required if not self.bones.get(r)]

    def role_of(self, bone_name):
        for role, names in self.bones.items():
            if bone_name in names:
                return role
        return None

    def with_overrides(self, overrides):
        """Overrides map role to bone name(s); an empty value clears the role."""
        bones = dict(self.bones)
        for role, value in overrides.items():
            if role not in ALL_ROLES:
                raise KeyError(f"unknown body role {role!r}")
            value = (value,) if isinstance(value, str) else tuple(value)
            bones[role] = tuple(v for v in value if v)
        return RoleMap({r: v for r, v in bones.items() if v})

    def to_dict(self):
        return {r: list(v) for r, v in self.bones.items()}
