"""Regenerate the real-rig fixtures from Blender.

Run with a Python that has bpy (e.g. /tmp/venvs/bpy50/bin/python make_fixtures.py [outdir]).
Writes JSON files holding bone names (parents before children), parent indices and rest
heads/tails in armature space (Z up), rounded to 1e-4:

- rigify_metarig.json     Rigify's human metarig (Add > Armature > Human (Meta-Rig))
- rigify_generated.json   the rig Rigify generates from it (all bones; DEF- bones deform)
- bvh_cmu_131.json        the CMU clips of /work/shared/data/mocap imported by Blender's BVH importer

Blender 4.2 gives the same metarig and generated rig (checked) but other tails for the
zero-length BVH bones (Chest2, LeftWrist, RightWrist): run on 4.x, the script writes only
bvh_cmu_131_b42.json.
"""

import json
import os
import sys

import bpy

HERE = os.path.dirname(os.path.abspath(__file__))
MOCAP = os.environ.get("HUMANANIM_MOCAP", "/work/shared/data/mocap")


def reset():
    bpy.ops.wm.read_factory_settings(use_empty=True)


def ordered_bones(arm):
    """Bones parents-before-children, siblings in Blender's own order."""
    out = []

    def visit(bone):
        out.append(bone)
        for child in bone.children:
            visit(child)

    for bone in arm.data.bones:
        if bone.parent is None:
            visit(bone)
    return out


def dump(arm, path, source):
    bones = ordered_bones(arm)
    index = {b.name: i for i, b in enumerate(bones)}
    data = {
        "source": source,
        "blender": bpy.app.version_string,
        "handmade": False,
        "names": [b.name for b in bones],
        "parents": [index[b.parent.name] if b.parent else -1 for b in bones],
        "heads": [[round(v, 4) for v in b.head_local] for b in bones],
        "tails": [[round(v, 4) for v in b.tail_local] for b in bones],
        "deform": [bool(b.use_deform) for b in bones],
    }
    with open(path, "w") as f:
        json.dump(data, f, indent=None, separators=(",", ":"))
        f.write("\n")
    print("wrote", path, len(bones), "bones")


def main(outdir):
    import addon_utils

    modern = bpy.app.version >= (5, 0, 0)
    cmu_name = "bvh_cmu_131.json" if modern else "bvh_cmu_131_b%d%d.json" % bpy.app.version[:2]
    reset()
    addon_utils.enable("rigify", default_set=True)
    bpy.ops.object.armature_human_metarig_add()
    metarig = bpy.context.active_object
    if modern:
        dump(metarig, os.path.join(outdir, "rigify_metarig.json"),
             "Rigify human metarig (bpy.ops.object.armature_human_metarig_add)")

    bpy.ops.object.mode_set(mode="OBJECT")
    bpy.ops.pose.rigify_generate()
    rig = next(o for o in bpy.data.objects if o.type == "ARMATURE" and o is not metarig)
    if modern:
        dump(rig, os.path.join(outdir, "rigify_generated.json"),
             "Rigify rig generated from the human metarig (bpy.ops.pose.rigify_generate)")

    skeletons = {}
    for name in sorted(os.listdir(MOCAP)):
        if not name.endswith(".bvh"):
            continue
        reset()
        bpy.ops.import_anim.bvh(filepath=os.path.join(MOCAP, name))
        arm = next(o for o in bpy.data.objects if o.type == "ARMATURE")
        bones = ordered_bones(arm)
        skeletons[name] = [(b.name, tuple(round(v, 4) for v in b.head_local),
                            tuple(round(v, 4) for v in b.tail_local)) for b in bones]
        if len(skeletons) == 1:
            dump(arm, os.path.join(outdir, cmu_name),
                 f"Blender BVH importer on {name} (CMU subject 131, 1 m units)")
    first = next(iter(skeletons.values()))
    for name, sk in skeletons.items():
        print(name, "same skeleton as the first:", sk == first)


if __name__ == "__main__":
    main(sys.argv[1] if len(sys.argv) > 1 else HERE)
