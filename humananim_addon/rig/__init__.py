"""The rig layer: what an armature's bones are and how the animator drives them (control rigs)."""
