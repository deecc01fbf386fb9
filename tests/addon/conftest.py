"""Fixtures shared by the add-on's tests."""

import tempfile

import pytest

import blender_addon


@pytest.fixture(scope="module")
def addon(tmp_path_factory):
    """The add-on registered in the bpy module for one test module's time (its tests need bpy)."""
    # Outside an installed extension the add-on writes its runs under the temporary folder.
    saved_tempdir = tempfile.tempdir
    tempfile.tempdir = str(tmp_path_factory.mktemp("addon_tmp"))
    blender_addon.register()
    yield
    blender_addon.unregister()
    tempfile.tempdir = saved_tempdir
