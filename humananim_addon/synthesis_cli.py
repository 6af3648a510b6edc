"""Motion synthesis: transitions and dynamic reactions (issue 5): batch commands (being built)."""


def add_commands(sub, add_common_options):
    return {}
