"""Motion generators that share a body (Huang 1996, sec. 6.4.3 and 6.4.4).

A generator moves a SCOPE (a subset of the body's degrees of freedom: here a set of bones) over a
time interval; several run at once. Its priority says what happens when scopes meet:

  default    it starts only once the previous generators sharing its scope have stopped;
  weighted   it runs with the others on its scope, mixed in with its weight (0-1);
  exclusive  it starts at its planned time and stops the others on its scope (on the bones it
             shares with them: a walk under a grasp keeps its legs);
  clearing   like exclusive, but it stops all of them, whatever their scope.

Generators are scheduled in the order of their planned start (ties: the order they were added);
later ones are layered over earlier ones, as NLA tracks are in Blender (the bridge turns each
scheduled generator into a strip whose action keys only its scope). An Actor holds one body's
stack; a Stage holds several actors, each with its own stack (sec. 6.4.4)."""

from dataclasses import dataclass, field

import numpy as np

from ..body_roles import SIDES, sided
from ..errors import HumanAnimError
from ..trajectories import Trajectories

PRIORITIES = ("default", "weighted", "exclusive", "clearing")
SCOPES = ("all", "legs", "arms", "arm.L", "arm.R", "hand.L", "hand.R", "spine", "head")


def scope_bones(skeleton, name):
    """Bone names of a named scope (roles and their descendants), or of an explicit list."""
    if not isinstance(name, str):
        names = frozenset(name)
        unknown = [b for b in names if skeleton.find(b) is None]
        if unknown:
            raise HumanAnimError(f"the scope names bones the rig lacks: {', '.join(sorted(unknown))}")
        return names
    sk = skeleton

    def roles(*rs, descend=()):
        out = set()
        for r in rs + descend:
            for b in sk.roles.chain(r):
                out.add(b)
                if r in descend:
                    out.update(sk.names[k] for k in sk.descendants(sk.index(b)))
        return out

    if name == "all":
        return frozenset(sk.names)
    if name == "legs":
        return frozenset(roles(*(sided(r, s) for s in SIDES for r in ("thigh", "shin")),
                               descend=tuple(sided("foot", s) for s in SIDES)))
    if name == "arms":
        return scope_bones(sk, "arm.L") | scope_bones(sk, "arm.R")
    if name in ("arm.L", "arm.R"):
        s = name[-1]
        return frozenset(roles(sided("clavicle", s), sided("upper_arm", s), sided("forearm", s),
                               descend=(sided("hand", s),)))
    if name in ("hand.L", "hand.R"):
        return frozenset(roles(descend=(sided("hand", name[-1]),)))
    if name == "spine":
        return frozenset(roles("spine", "chest"))
    if name == "head":
        return frozenset(roles("neck", descend=("head",)))
    raise HumanAnimError(f"unknown scope {name!r} (scopes: {', '.join(SCOPES)}, or a list of bones)")


@dataclass
class Generator:
    """A motion on a scope. `motion` (Trajectories of the whole skeleton) is played from its first
    frame at `start`; the generator runs until `end` (default: the motion's length)."""

    name: str
    scope: frozenset
    motion: Trajectories
    start: float
    end: float = None
    priority: str = "default"
    weight: float = 1.0

    def __post_init__(self):
        if self.priority not in PRIORITIES:
            raise HumanAnimError(f"unknown priority {self.priority!r} (priorities: {', '.join(PRIORITIES)})")
        if not 0.0 <= self.weight <= 1.0:
            raise HumanAnimError(f"a generator's weight is between 0 and 1, not {self.weight:g}")
        self.scope = frozenset(self.scope)
        if self.end is None:
            self.end = self.start + (self.motion.frames[-1] - self.motion.frames[0])
        if self.end < self.start:
            raise HumanAnimError(f"generator '{self.name}' ends before it starts")

    @property
    def duration(self):
        return self.end - self.start


@dataclass
class Scheduled:
    generator: Generator
    start: float  # when it actually runs, after the priorities
    end: float
    cuts: dict = field(default_factory=dict)  # bone -> frame an exclusive generator stopped it there
    stopped_by: list = field(default_factory=list)  # names of the generators that stopped (part of) it

    @property
    def scope(self):
        return self.generator.scope

    @property
    def weight(self):
        return self.generator.weight if self.generator.priority == "weighted" else 1.0

    def bone_end(self, bone):
        return min(self.end, self.cuts.get(bone, np.inf))

    def stop(self, bones, frame, by):
        for b in bones:
            self.cuts[b] = max(self.start, min(self.cuts.get(b, np.inf), frame))
        self.stopped_by.append(by)

    def pieces(self):
        """(bones, start, end) spans over which the same bones run: an NLA strip each."""
        times = sorted({self.start, self.end} | {min(max(t, self.start), self.end) for t in self.cuts.values()})
        out = []
        for a, b in zip(times[:-1], times[1:]):
            bones = frozenset(x for x in self.scope if self.bone_end(x) >= b)
            if bones and b > a:
                if out and out[-1][0] == bones and out[-1][2] == a:
                    out[-1] = (bones, out[-1][1], b)
                else:
                    out.append((bones, a, b))
        return out


def schedule(generators):
    """The generators' actual intervals after their priorities (sec. 6.4.3), in layer order.

    An exclusive generator stops the others on the bones it shares with them (a walk keeps its
    legs when a grasp takes its right arm); a clearing one stops everything."""
    order = sorted(range(len(generators)), key=lambda i: (generators[i].start, i))
    done = []
    for i in order:
        g = generators[i]
        start = g.start
        if g.priority == "default":
            moved = True
            while moved:  # wait until no earlier generator still runs on a shared bone
                moved = False
                for s in done:
                    shared = s.scope & g.scope
                    busy = max((s.bone_end(b) for b in shared), default=s.start)
                    if shared and s.start <= start < busy:
                        start, moved = busy, True
        elif g.priority in ("exclusive", "clearing"):
            for s in done:
                bones = s.scope if g.priority == "clearing" else s.scope & g.scope
                if bones and s.end > start:
                    s.stop(bones, start, g.name)
        done.append(Scheduled(g, start, start + g.duration))
    return done


def sample(motion, frames):
    """Local rotations (N, J, 4) and translations (N, J, 3) of a motion at (fractional) frames,
    held at its ends; quaternions blended linearly and normalised (as Blender's NLA does)."""
    f = np.clip(np.asarray(frames, float), motion.frames[0], motion.frames[-1])
    hi = np.clip(np.searchsorted(motion.frames, f, side="right"), 1, motion.frame_count - 1)
    lo = hi - 1
    span = np.maximum(motion.frames[hi] - motion.frames[lo], 1e-12)
    w = np.clip((f - motion.frames[lo]) / span, 0, 1)[:, None, None] if motion.frame_count > 1 else 0.0
    if motion.frame_count == 1:
        return motion.rotations[[0] * len(f)], motion.translations[[0] * len(f)]
    q = _nlerp(motion.rotations[lo], motion.rotations[hi], w)
    t = (1 - w) * motion.translations[lo] + w * motion.translations[hi]
    return q, t


def _nlerp(a, b, w):
    b = np.where(np.sum(a * b, axis=-1, keepdims=True) < 0, -b, b)
    q = (1 - w) * a + w * b
    return q / np.linalg.norm(q, axis=-1, keepdims=True)


@dataclass
class Actor:
    """One body and its stack of generators."""

    name: str
    skeleton: object
    generators: list = field(default_factory=list)

    def add(self, name, motion, start, scope="all", end=None, priority="default", weight=1.0):
        g = Generator(name, scope_bones(self.skeleton, scope), motion, float(start),
                      None if end is None else float(end), priority, float(weight))
        self.generators.append(g)
        return g

    def schedule(self):
        return schedule(self.generators)

    def evaluate(self, frames, fps=None, base=None, armature_to_world=None):
        """The body's motion at `frames`: each running generator, in layer order, replaces (or with
        its weight mixes into) the bones of its scope; bones no generator moves keep `base`
        (the rest pose by default)."""
        sk, frames = self.skeleton, np.asarray(frames, float)
        n, J = len(frames), sk.joint_count
        if base is None:
            rot = np.zeros((n, J, 4))
            rot[..., 0] = 1.0
            trans = np.zeros((n, J, 3))
        else:
            rot, trans = sample(base, frames)
        for s in self.schedule():
            motion = s.generator.motion
            for bones, t0, t1 in s.pieces():
                on = (frames >= t0 - 1e-9) & (frames <= t1 + 1e-9)
                if not on.any():
                    continue
                q, t = sample(motion, frames[on] - s.start + motion.frames[0])
                cols = np.array([sk.index(b) for b in sorted(bones, key=sk.index)])
                w = s.weight
                rot[np.ix_(on, cols)] = _nlerp(rot[np.ix_(on, cols)], q[:, cols], w)
                trans[np.ix_(on, cols)] = (1 - w) * trans[np.ix_(on, cols)] + w * t[:, cols]
        a2w = np.eye(4) if armature_to_world is None else armature_to_world
        return Trajectories(frames, fps or 24.0, rot, trans, a2w)


@dataclass
class Stage:
    """Several actors in one scene, each with its own stack (sec. 6.4.4)."""

    actors: dict = field(default_factory=dict)

    def actor(self, name, skeleton=None):
        if name not in self.actors:
            if skeleton is None:
                raise HumanAnimError(f"no actor named {name!r}")
            self.actors[name] = Actor(name, skeleton)
        return self.actors[name]

    def evaluate(self, frames, fps=None):
        return {name: a.evaluate(frames, fps) for name, a in self.actors.items()}


def walk_generator(actor, result, name="walk", scope="all", start=None, priority="default", weight=1.0):
    """A walk (WalkResult) as a generator of `actor` (Oshita 2003 sec. 3.3: a step generator as a
    source of action data)."""
    tr = result.trajectories
    return actor.add(name, tr, tr.frames[0] if start is None else start, scope, None, priority, weight)
