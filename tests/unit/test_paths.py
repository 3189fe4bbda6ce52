"""core/paths.py: the GLSL library is found in a checkout (the top-level shaders/ beside
the package) and in every installed form (shaders/ inside the package), and the installed
copy wins when both exist, so an installed add-on reads and reloads its own files."""

import os

import pytest

from csm_engine.core import paths


def _library(folder):
    os.makedirs(folder)
    with open(os.path.join(folder, paths.SHADER_MARKER), "w", encoding="utf-8") as handle:
        handle.write("void main() {}\n")
    return str(folder)


@pytest.fixture
def layout(tmp_path, monkeypatch):
    """A package folder inside a checkout folder, both empty."""
    package = tmp_path / "checkout" / "csm_engine"
    package.mkdir(parents=True)
    monkeypatch.setattr(paths, "PACKAGE_DIR", str(package))
    monkeypatch.setattr(paths, "CHECKOUT_DIR", str(package.parent))
    return package


def test_this_checkout_reads_its_top_level_shaders_folder():
    assert paths.shaders_dir() == os.path.join(paths.CHECKOUT_DIR, "shaders")
    assert os.path.isfile(os.path.join(paths.shaders_dir(), "lighting_frag.glsl"))
    assert not os.path.exists(os.path.join(paths.PACKAGE_DIR, "shaders"))


def test_a_checkout_layout_reads_shaders_beside_the_package(layout):
    top = _library(layout.parent / "shaders")
    assert paths.shaders_dir() == top


def test_an_installed_package_reads_its_own_copy_even_beside_another(layout):
    _library(layout.parent / "shaders")          # e.g. some other site-packages/shaders
    inside = _library(layout / "shaders")
    assert paths.shaders_dir() == inside


def test_a_folder_without_the_library_is_not_taken_and_none_is_a_clear_error(layout):
    (layout.parent / "shaders").mkdir()          # a stray folder of that name
    with pytest.raises(FileNotFoundError, match="GLSL library"):
        paths.shaders_dir()


def test_data_stays_inside_the_package():
    assert os.path.dirname(paths.data_dir()) == paths.PACKAGE_DIR
    assert os.path.isfile(paths.default_scene_path())
