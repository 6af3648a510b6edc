"""Live capture's settings on the scene (scene.humananim_capture): the devices and the session."""

import bpy
from bpy.props import (BoolProperty, CollectionProperty, EnumProperty, FloatProperty, IntProperty, PointerProperty,
                       StringProperty)

from ..devices import fob, hidglove, mvn, vmc
from ..properties import settings_registration


DEVICE_KINDS = (
    ("FLOCK", "Flock of Birds", "Ascension Flock of Birds on an RS-232 port"),
    ("CYBERGLOVE", "CyberGlove", "Virtual Technologies CyberGlove (18 or 22 sensors) on an RS-232 port"),
    ("HID_GLOVE", "USB Glove", "A USB HID data glove through hidapi (5DT Data Glove Ultra, ...)"),
    ("MVN", "Xsens MVN", "Xsens MVN network stream (UDP pose datagrams, several actors)"),
    ("VMC", "VMC", "VMC protocol (OSC over UDP) from a capture tool"),
    ("REPLAY", "Replay", "A BVH file played back at its own rate, looping"),
)
POSE_KINDS = {"FLOCK"}
GLOVE_KINDS = {"CYBERGLOVE", "HID_GLOVE"}




class HumanAnimCaptureDevice(bpy.types.PropertyGroup):
    name: StringProperty(name="Name", default="device")
    use: BoolProperty(name="Use", default=True,
                      description="Open this device when connecting (off: only its bone mapping is used, e.g. "
                                  "by a replayed take of it)")
    kind: EnumProperty(name="Device", items=DEVICE_KINDS)
    simulate: BoolProperty(name="Simulate", description="No hardware: run the device's simulator on a "
                                                        "pseudo-terminal and read it through the real driver")
    port: StringProperty(name="Port", default="/dev/ttyUSB0", description="Serial port (COM3, /dev/ttyUSB0)")
    baud: IntProperty(name="Baud", default=115200, min=2400, max=230400)
    rate: FloatProperty(name="Rate", default=100.0, min=0.0, soft_max=240.0,
                        description="Samples per second of a simulator, or of a replay (0: the file's own)")
    record: EnumProperty(name="Record", items=[(k, k.title().replace("/", " / "), f"{k} records")
                                               for k in fob.RECORDS], default="POSITION/QUATERNION")
    mode: EnumProperty(name="Mode", items=(("STREAM", "Stream", "The device sends records continuously"),
                                           ("POINT", "Point", "Ask for every record (poll)")))
    birds: StringProperty(name="Birds", default="1", description="FBB addresses of the birds, e.g. 1,2,3 "
                                                               "(several birds use group mode)")
    bones: StringProperty(name="Bones", default="",
                          description="The bone each bird is strapped on, in the order of Birds, e.g. "
                                      "Hips, Chest, LeftWrist; the first bird with a bone on the root bone moves "
                                      "the body")
    hemisphere: EnumProperty(name="Hemisphere", items=[(k, k.title(), f"{k} hemisphere") for k in fob.HEMISPHERES])
    extended_range: BoolProperty(name="Extended Range", description="Simulate an Extended Range "
                                                                    "Controller (144 in; it is address 1, its "
                                                                    "birds start at 2)")
    standalone: BoolProperty(name="Standalone", description="One bird without the Fast Bird Bus (no FBB "
                                                            "addressing, no auto-configuration)")
    sensors: EnumProperty(name="Model", items=(("18", "18 Sensors", "CyberGlove with 18 sensors"),
                                               ("22", "22 Sensors", "CyberGlove with 22 sensors")))
    time_stamp: BoolProperty(name="Time Stamp", description="CyberGlove: records carry the glove's time "
                                                            "stamp (set on the glove at every connect)")
    status_byte: BoolProperty(name="Status Byte", description="CyberGlove: records carry the glove status byte "
                                                              "(set on the glove at every connect)")
    hand: EnumProperty(name="Hand", items=(("R", "Right", "Right hand"), ("L", "Left", "Left hand")))
    # a name, not an enum: decoders are plug-ins registered at run time (and a dynamic enum's
    # items callback crashes the bpy 4.2 module at exit)
    decoder: StringProperty(name="Decoder", default="5dt_ultra_14",
                            description="The report decoder: " + ", ".join(sorted(hidglove.DECODERS))
                                        + " or one registered with hidglove.register_decoder")
    host: StringProperty(name="Host", default="127.0.0.1")
    vmc_port: IntProperty(name="UDP Port", default=vmc.DEFAULT_PORT, min=0, max=65535)
    mvn_port: IntProperty(name="UDP Port", default=mvn.DEFAULT_PORT, min=0, max=65535,
                          description="MVN's Network Streamer sends here (its default is 9763)")
    actor: IntProperty(name="Actor", default=0, min=0, max=255,
                       description="The MVN character ID that drives this rig (every actor is recorded)")
    filepath: StringProperty(name="File", subtype="FILE_PATH",
                             description="The .bvh file, or a take saved as .json, to replay")


class HumanAnimCapture(bpy.types.PropertyGroup):
    devices: CollectionProperty(type=HumanAnimCaptureDevice)
    device_index: IntProperty()
    display_rate: FloatProperty(name="Display Rate", default=60.0, min=1.0, max=240.0,
                                description="How often the rig is updated (timer events per second)")
    gestures: BoolProperty(name="Gestures", default=True,
                           description="Glove postures give commands: point starts recording, V stops it, "
                                       "a fist recalibrates, a flat hand is neutral")
    grasp_collection: PointerProperty(name="Graspable", type=bpy.types.Collection,
                                      description="Objects the gloved hand can pick up (spheres and boxes)")
    take_name: StringProperty(name="Take", default="capture")
    reduce_keys: BoolProperty(name="Reduce Keys", description="After recording, reduce the take's keys "
                                                               "(one per sample) with the sequence tools' key "
                                                               "reduction, within the tolerance below")
    reduce_degrees: FloatProperty(name="Tolerance", default=0.5, min=0.01, max=10.0,
                                  description="Largest rotation error of the reduced keys, degrees")
    quaternion_bones: BoolProperty(name="Quaternion Bones", default=True,
                                   description="Turn the captured rig's bones to quaternion rotation, so the "
                                               "recorded keys are quaternions (they blend in the NLA)")


CLASSES = (HumanAnimCaptureDevice, HumanAnimCapture)
_register, _unregister = settings_registration(CLASSES, bpy.types.Scene, "humananim_capture", HumanAnimCapture)
