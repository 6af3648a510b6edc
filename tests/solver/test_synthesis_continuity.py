"""The Motion Queue's requests between real clips (Bandai Namco's corpus, as Blender imports it)
are continuous or refused: in the transition's window no joint turns more in one frame than 1.5x
its own fastest step in either clip plus 6 deg, and no held foot drifts more than 1 cm; a request
that would pop or slide is refused with its reason, never reported accepted. Walk -> bow and
bow -> guide once turned the thighs 85-94 deg between two frames (the clips' own fastest: 3-10
deg); they are now accepted and continuous."""

import numpy as np
import pytest

from humananim.solver import rotations
from humananim.solver.synthesis.action import from_trajectories
from humananim.solver.synthesis.synthesizer import Synthesizer

from corpus_clips import load

PAIRS = (("walk_normal_001", "bow_normal_001"), ("bow_normal_001", "guide_normal_001"),
         ("walk_happy_001", "walk_normal_001"), ("guide_normal_001", "bow_normal_001"))


def actions(first, second):
    sk, tr1 = load(first)
    return from_trajectories(first, sk, tr1), from_trajectories(second, sk, load(second)[1])


def steps(rot):
    return np.degrees(rotations.angle_between(rot[1:], rot[:-1]))


@pytest.mark.parametrize("mode", ("blend", "connect", "inertialize"))
@pytest.mark.parametrize("pair", PAIRS, ids=lambda p: f"{p[0]}->{p[1]}")
def test_a_request_is_continuous_or_refused(pair, mode):
    a1, a2 = actions(*pair)
    syn = Synthesizer(a1)
    request = syn.queue(a2, mode)
    if not request.accepted:
        assert request.reason.strip()
        return
    own = np.maximum(steps(a1.trajectories.rotations).max(axis=0), steps(a2.trajectories.rotations).max(axis=0))
    w0, w1 = request.window
    window = steps(syn.trajectories.rotations)[max(w0 - 1, 0):w1 + 1]
    assert np.all(window <= 1.5 * own + 6.0 + 1e-9)
    world = syn.trajectories.world_frames(a1.skeleton)
    for side, held in request.held.items():
        frames = np.flatnonzero(held)
        foot = a1.skeleton.role_index(f"foot.{side}")
        if len(frames):  # one held run at the join
            assert np.linalg.norm(world[frames, foot, :2, 3] - world[frames[0], foot, :2, 3], axis=1).max() <= 0.01


def test_bandai_namco_transitions_are_accepted_and_continuous():
    """Issue 23: walk -> bow and bow -> guide were refused (before, accepted) with the thighs
    turning 85-94 deg between two frames: the legs' IK, asked for a foot just beyond reach, went
    dead straight, where its bend plane comes from the captured knee's offset along its hinge.
    Blending bow -> guide twisted the held feet's ankles 18 deg a frame: the guide was turned
    70 deg onto the bow by the line between its staggered feet, now by the feet's headings."""
    for (first, second), mode in ((("walk_normal_001", "bow_normal_001"), "connect"),
                                  (("walk_normal_001", "bow_normal_001"), "inertialize"),
                                  (("bow_normal_001", "guide_normal_001"), "blend"),
                                  (("bow_normal_001", "guide_normal_001"), "connect"),
                                  (("guide_normal_001", "bow_normal_001"), "blend")):
        a1, a2 = actions(first, second)
        request = Synthesizer(a1).queue(a2, mode)
        assert request.accepted, (first, second, mode, request.reason)
