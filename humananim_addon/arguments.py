"""The one argument-parsing layer of the `humananim` commands.

Every command's cli module (humananim_addon/<capability>/cli.py) builds its options from here:
the number types (a NaN, an infinity or a value out of range is a usage mistake), the option
builders the commands share (input file and armature, source action and frames, hand loads, pushes
and impulses, ground, strength, where the result goes, --json and --strict), and the one error
path: a mistake is one line on stderr and exit status 2, from argparse (`OneLineParser.error`) and
from the commands (`fail`) alike. Nothing here imports Blender."""

import argparse
import math
import os
import sys


class UsageError(Exception):
    """A mistake in the command line or its files: reported in one line."""


def one_line(error):
    """An error's message on one line (Blender's own messages may span several)."""
    return " ".join(str(error).split())


def fail(prog, error):
    """The one error path: `prog: error: message` on one line on stderr; the exit status 2."""
    print(f"{prog}: error: {one_line(error)}", file=sys.stderr)
    return 2


class OneLineParser(argparse.ArgumentParser):
    """argparse with its usage mistakes as one line on stderr (exit status 2), like every other
    mistake; --help still prints the usage."""

    def error(self, message):
        self.exit(2, f"{self.prog}: error: {message}\n")


def number(low=None, high=None, above=False, integer=False, what=None):
    """An argparse type: a finite number (an integer with `integer`) >= low (> low with `above`)
    and <= high. NaN, infinities and out-of-range values are usage mistakes."""
    bound = " ".join(filter(None, [f"{'>' if above else '>='} {low:g}" if low is not None else "",
                                   f"<= {high:g}" if high is not None else ""]))
    what = what or f"a{'' if integer else ' finite'} {'whole ' if integer else ''}number" + (f" {bound}" if bound else "")

    def convert(text):
        try:
            value = int(text) if integer else float(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected {what}, got {text!r}") from None
        if not math.isfinite(value) or (low is not None and (value <= low if above else value < low)) \
                or (high is not None and value > high):
            raise argparse.ArgumentTypeError(f"expected {what}, got {text!r}")
        return value
    convert.__name__ = "number"  # argparse names the type in its messages
    return convert


FINITE = number()
POSITIVE = number(0.0, above=True)
NON_NEGATIVE = number(0.0)
FRACTION = number(0.0, 1.0)
COUNT = number(1, integer=True)
FRAME = number(integer=True, what="a whole frame number")
FRAME_OR_ZERO = number(0, integer=True)  # 0: "the default frame" (the start, never, ...)


# ---- options the commands share ----------------------------------------------------------------

def add_common(p):
    """--mass, --scale, --json and --strict: every command has them."""
    p.add_argument("--mass", type=POSITIVE, help="total body mass in kg (default 70)")
    p.add_argument("--scale", type=POSITIVE, help="metres per BVH unit (default: guessed from the figure's "
                                                   "height; a figure no common unit makes 1.0-2.3 m tall is refused)")
    p.add_argument("--json", action="store_true", help="print one JSON object (its 'qa' key: the motion QA)")
    p.add_argument("--strict", action="store_true", help="exit with status 3 when the result fails the motion QA")


def add_input(p, help="a .blend or .bvh file", armature="the armature object in a .blend (default: the only one)",
              **file_options):
    """The positional input file and --armature."""
    p.add_argument("file", help=help, **file_options)
    p.add_argument("--armature", help=armature)


def add_source(p):
    """--action and --frames: the source motion of a job that follows an action."""
    p.add_argument("--action", help="source action (default: the armature's active action)")
    add_frames(p)


def add_frames(p, help="frame range"):
    p.add_argument("--frames", nargs=2, type=FRAME, metavar=("START", "END"), help=help)


def add_loads(p, pick_up=False):
    """--load-left and --load-right (kg in the hands), with `pick_up` --load-frame."""
    p.add_argument("--load-left", type=NON_NEGATIVE, default=0.0, help="kg carried in the left hand")
    p.add_argument("--load-right", type=NON_NEGATIVE, default=0.0, help="kg carried in the right hand")
    if pick_up:
        p.add_argument("--load-frame", type=FRAME_OR_ZERO, default=0,
                       help="frame the loads are picked up at (default: start)")


def add_arrows(p, option, help):
    """A repeatable force on a bone, FRAME:BONE:FX,FY,FZ[:SECONDS] (see cli.parse_arrow)."""
    p.add_argument(option, action="append", default=[], metavar="FRAME:BONE:FX,FY,FZ[:SECONDS]", help=help)


def add_strength(p):
    p.add_argument("--strength", type=POSITIVE, default=1.0, help="muscle strength scale (default 1)")


def add_ground_height(p, help):
    p.add_argument("--ground", type=FINITE, help=help)


def add_output(p):
    """--output: the result as the active action or as an NLA track."""
    p.add_argument("--output", choices=("ACTION", "NLA"), default="ACTION")


def add_out(p, name):
    """--out: the .blend the command writes (default out/<name>)."""
    p.add_argument("--out", default=os.path.join("out", name), help="the .blend to write")


def add_collider(p, help, radius_help="sphere radius along a colliding armature's bones (m, default 0.06)"):
    """--collide OBJECT and --collide-radius."""
    p.add_argument("--collide", metavar="OBJECT", help=help)
    p.add_argument("--collide-radius", type=POSITIVE, default=0.06, help=radius_help)
