"""Hands: grasping, manipulation, self-collision (issue 9): batch commands (being built)."""


def add_commands(sub, add_common_options):
    return {}
