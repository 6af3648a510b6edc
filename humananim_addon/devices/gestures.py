"""Glove gesture commands (Huang 1996 §6.4.1, fig. 6-7): a flat hand is the neutral gesture;
pointing (index out), the V (index and middle out) and the fist (the calibration gesture)
give start recording, stop recording and recalibrate.

A finger counts as curled above `curl_on` and as extended below `curl_off`; in between it
keeps its last state (hysteresis), so a finger hovering at the threshold doesn't flicker. A
posture must be held `hold` seconds to count, and only a change of posture triggers its
command: holding the fist doesn't recalibrate again and again."""

from .glove_calibration import FIST_DEGREES

FINGER_NAMES = ("thumb", "index", "middle", "ring", "pinky")
# posture: (curled fingers), thumb ignored where None
POSTURES = {
    "neutral": {"index": False, "middle": False, "ring": False, "pinky": False},
    "start_recording": {"index": False, "middle": True, "ring": True, "pinky": True},
    "stop_recording": {"index": False, "middle": False, "ring": True, "pinky": True},
    "recalibrate": {"index": True, "middle": True, "ring": True, "pinky": True},
}


def finger_curls(angles):
    """Flexion of each finger as a fraction of a fist (0 flat, 1 fist) from calibrated angles."""
    out = {}
    for f in FINGER_NAMES:
        joints = [(f, k) for k in (0, 1, 2) if (f, k, "flex") in angles and (f, k) in FIST_DEGREES]
        if not joints:
            continue
        total = sum(FIST_DEGREES[j] for j in joints)
        import math
        out[f] = sum(angles[(f, k, "flex")] for f_, k in joints) / math.radians(total)
    return out


class GestureRecognizer:
    def __init__(self, curl_on=0.65, curl_off=0.35, hold=0.25, enabled=True):
        self.curl_on, self.curl_off, self.hold = curl_on, curl_off, hold
        self.enabled = enabled
        self.curled = {}
        self.posture = None  # the stable posture
        self._candidate, self._since = None, None

    def classify(self, curls):
        for f, c in curls.items():
            if c > self.curl_on:
                self.curled[f] = True
            elif c < self.curl_off:
                self.curled[f] = False
            else:
                self.curled.setdefault(f, c >= 0.5)
        for name, pattern in POSTURES.items():
            if all(self.curled.get(f) == v for f, v in pattern.items()):
                return name
        return None

    def update(self, t, angles):
        """The command triggered at time t by calibrated angles, or None."""
        posture = self.classify(finger_curls(angles))
        if posture != self._candidate:
            self._candidate, self._since = posture, t
            return None
        if posture is None or posture == self.posture or t - self._since < self.hold:
            return None
        self.posture = posture
        return posture if self.enabled else None
