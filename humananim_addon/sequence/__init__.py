"""Keyframe sequence manipulation in Blender (Huang 1996 ch. 5): the bridge between an action's
F-curves and solver.sequence.

What is processed. The selected F-curves of the action (Graph Editor), or the channels of the
selected pose bones (3D view), or every channel when nothing is selected (the report says so).
A rotation is processed as a rotation: selecting one component of a bone's quaternion, Euler or
axis-angle property takes its whole property. Quaternion (and axis-angle) properties are
filtered and blended in the tangent space about their mean and renormalised; Euler properties
are unrolled first. Locations and any other curve (object transforms, custom properties, shape
keys) are used as they are.

What is written. A new action named after the source (".eq", ".blend", ".compressed",
".warped", ".squeezed"), assigned to the object; every curve that was not processed is copied
into it unchanged (keys, handles, interpolation), and the source action keeps its keys and gets
a fake user. With `replace=True` the processed curves of the source action are rewritten in
place instead. Filtered, blended and resampled curves are keyed on every frame (linear); key
compression, time warping of keys and squeeze/stretch write Bezier keys with FREE handles.

Units. Rotation tolerances and errors are degrees (of the bone's rotation, not of one
component); location tolerances are centimetres (through the armature's scale and the scene's
unit scale); other curves use their own units. Compression also reports the largest distance
any bone's tail, and a point 10 cm beyond it, moved on any frame (error_measures.tail_error).

One module per concern: `channels` (which curves, sampled into working channels), `writing` (keys
and the new action), `measures` (errors), one per tool (`equalize`, `blend`, `compress`, `warp`), and
`settings` (the scene settings and the band list the panel shows)."""

from .blend import blend, nla_pair
from .channels import Selection, action_frames, select_channels, selection_for_context
from .compress import FEET_MM, compress, iter_compress
from .equalize import MAX_LEVELS, band_energies, band_labels, default_levels, equalize
from .settings import CLASSES, register, store_bands, unregister
from .warp import marker_constraints, parse_map, squeeze_stretch, warp
from .writing import read_keys

__all__ = ["CLASSES", "MAX_LEVELS", "Selection", "action_frames", "band_energies", "band_labels", "blend",
           "FEET_MM", "compress", "default_levels", "equalize", "iter_compress", "marker_constraints", "nla_pair",
           "parse_map", "read_keys", "register", "select_channels", "selection_for_context", "squeeze_stretch",
           "store_bands", "unregister", "warp"]
