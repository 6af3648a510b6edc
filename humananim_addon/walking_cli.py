"""Procedural walking (issue 11): batch commands (being built)."""


def add_commands(sub, add_common_options):
    return {}
