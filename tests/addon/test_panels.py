"""Every panel draws without error, and every property it shows exists (headless: a recording layout)."""

import pytest

bpy = pytest.importorskip("bpy")

from humananim import panels  # noqa: E402


class RecordingLayout:
    """Stands in for UILayout: checks each property reference, records labels and operators."""

    def __init__(self, log):
        self.log = log
        self.use_property_split = False

    def __getattr__(self, name):
        if name in ("row", "column", "box", "split", "column_flow"):
            return lambda *a, **k: RecordingLayout(self.log)
        if name in ("separator", "progress"):
            return lambda *a, **k: None
        raise AttributeError(name)

    def prop(self, data, name, **_):
        assert name in data.bl_rna.properties, f"{type(data).__name__} has no property {name!r}"
        self.log.append(("prop", name))

    def prop_search(self, data, name, search_data, search_name, **_):
        self.prop(data, name)
        assert search_name in search_data.bl_rna.properties

    def label(self, text="", **_):
        self.log.append(("label", text))

    def operator(self, idname, **_):
        module, op = idname.split(".")
        getattr(getattr(bpy.ops, module), op).get_rna_type()  # KeyError if not registered
        self.log.append(("operator", idname))

    def template_list(self, list_type, _id, data, name, active_data, active_name, **_):
        assert list_type in dir(bpy.types)
        self.prop(data, name)
        self.prop(active_data, active_name)


def draw_all(context):
    log = []
    for cls in panels.CLASSES:
        if issubclass(cls, bpy.types.Panel) and cls.poll(context):
            cls.draw(type("P", (), {"layout": RecordingLayout(log)})(), context)
    return log


def test_panels_draw_on_a_fresh_rig_and_after_set_up(metarig):
    log = draw_all(bpy.context)
    assert ("operator", "humananim.detect_roles") in log
    assert ("operator", "humananim.compute_mass_model") in log
    bpy.ops.humananim.detect_roles()
    bpy.ops.humananim.compute_mass_model()
    metarig.data.humananim.mass_source = "MESH"
    log = draw_all(bpy.context)
    assert any(kind == "label" and "segments" in text for kind, text in log)
    assert ("prop", "thigh_l") in log and ("prop", "density") in log
