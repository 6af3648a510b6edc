"""The corpus tests run the batch commands in a headless bpy session with the add-on registered."""

import os
import tempfile

import pytest

os.environ.setdefault("BLENDER_USER_RESOURCES", tempfile.mkdtemp(prefix="humananim-user-"))


@pytest.fixture(scope="session", autouse=True)
def humananim_registered():
    bpy = pytest.importorskip("bpy")
    import humananim
    if hasattr(bpy.types.Armature, "humananim"):
        yield
        return
    humananim.register()
    yield
    humananim.unregister()
