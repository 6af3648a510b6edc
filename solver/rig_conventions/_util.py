"""Helpers for writing the tables."""


def mirror(table_l, swap):
    """Right-side entries from left-side ones: `swap(name)` turns a left bone name into the right one."""
    out = {}
    for role, names in table_l.items():
        role_r = role[:-2] + ".R"
        out[role_r] = swap(names) if isinstance(names, str) else tuple(swap(n) for n in names)
    return out


def both_sides(centre, left, swap):
    table = dict(centre)
    table.update(left)
    table.update(mirror(left, swap))
    return table
