"""CSM presets as a user meets them: the menu in the first CSM panel's header, the shipped
presets applied through Blender's own ``script.execute_preset``, and a preset of one's own
added and removed with the menu's + and - (``csm.preset_add``); and what the panels show
after a preset: every setting, greyed out exactly where it does not act."""
import ast
import os

import bpy
import pytest

from csm_engine.blender import presets, snapshot, ui
from csm_engine.core import settings_model
from csm_engine.core.settings_model import (BY_IDENTIFIER, PRESET_IDENTIFIERS, SETTINGS,
                                            default_settings, is_active)

SHIPPED = {"CS562 assignment", "Best quality", "Fast"}

# What each shipped preset promises (the rest of what it sets: the model's defaults).
EXPECTED = {
    "CS562 assignment": dict(
        cascade_count=3, resolution=2048, equal_resolution=False, split_scheme="HYBRID",
        split_lambda=0.5, fit_to_visible=False, cascade_selection="DEPTH", blend_band=2.0,
        shadow_filter="PCF", pcf_radius=1, pcf_sharpen=1.0, pcf_pattern="GRID",
        occluder_margin_auto=True, stabilize=True),
    "Best quality": {},
    "Fast": dict(cascade_count=2, resolution=1024, fit_to_visible=True, pcf_radius=0,
                 ambient_occlusion=False, fxaa=True),
}

# The controls the course's assignment asks a student to show working.
ASSIGNMENT_CONTROLS = ("cascade_count", "resolution", "split_scheme", "split_lambda",
                       "cascade_selection", "blend_band", "shadow_filter", "pcf_radius",
                       "pcf_pattern", "occluder_margin_auto", "stabilize")


@pytest.fixture(autouse=True)
def fresh_scene_afterwards():
    """Leave a factory scene behind: later test files read ``bpy.context.scene`` as new."""
    yield
    bpy.ops.wm.read_factory_settings(use_empty=True)


def shipped_paths():
    return {presets.display_name(path): path for path in presets.shipped_presets()}


def assignments(path):
    """(identifier, value) of every ``csm.<identifier> = <literal>`` line of a preset
    file; anything else in it but the imports and ``csm = bpy.context.scene.csm`` fails."""
    with open(path, encoding="utf-8") as handle:
        tree = ast.parse(handle.read(), path)
    found = []
    for node in tree.body:
        if isinstance(node, ast.Import):
            assert [alias.name for alias in node.names] == ["bpy"], ast.dump(node)
            continue
        assert isinstance(node, ast.Assign) and len(node.targets) == 1, ast.dump(node)
        target = node.targets[0]
        if isinstance(target, ast.Name):
            assert target.id == "csm" and ast.unparse(node.value) == "bpy.context.scene.csm"
            continue
        assert isinstance(target, ast.Attribute) and ast.unparse(target.value) == "csm", \
            ast.dump(node)
        found.append((target.attr, ast.literal_eval(node.value)))
    return found


def scrambled(csm):
    """Set every preset setting to something other than any shipped preset sets."""
    csm.cascade_count = 4
    csm.resolution = 512
    csm.equal_resolution = True
    csm.split_scheme = "UNIFORM"
    csm.split_lambda = csm.fitted_split_lambda = 0.1
    csm.fit_to_visible = not csm.fit_to_visible
    csm.cascade_selection = "MAP"
    csm.blend_band = 7.0
    csm.shadow_filter = "SOFT"
    csm.pcf_radius = 5
    csm.occluder_margin_auto = False
    csm.stabilize = False
    csm.ambient_occlusion = False
    csm.fxaa = False
    csm.depth_bias = 9.0


def test_the_preset_menu_and_operator_are_registered_in_the_first_panels_header():
    assert bpy.types.CSM_MT_presets.preset_subdir == presets.PRESET_SUBDIR
    assert bpy.types.CSM_MT_presets.preset_operator == "script.execute_preset"
    assert hasattr(bpy.ops.csm, "preset_add")
    headed = [cls for cls in ui.classes if "draw_header_preset" in vars(cls)]
    assert {(cls.bl_space_type, cls.bl_label) for cls in headed} == \
        {('PROPERTIES', "Cascades"), ('VIEW_3D', "Cascades")}


def test_the_shipped_presets_are_found():
    assert set(shipped_paths()) == SHIPPED
    for path in shipped_paths().values():
        assert os.path.dirname(path) == presets.SHIPPED_DIR


@pytest.mark.parametrize("name", sorted(SHIPPED))
def test_a_preset_file_sets_every_preset_setting_of_the_model_and_nothing_else(name):
    found = assignments(shipped_paths()[name])
    identifiers = [identifier for identifier, _value in found]
    assert identifiers == list(PRESET_IDENTIFIERS), "in the model's order, each once"
    for identifier, value in found:
        setting = BY_IDENTIFIER[identifier]
        assert setting.preset
        if setting.kind == settings_model.ENUM:
            assert value in setting.identifiers, (identifier, value)
        elif setting.kind == settings_model.FLOAT_VECTOR:
            assert len(value) == setting.size
        else:
            assert isinstance(value, setting.value_type) or \
                (setting.kind == settings_model.FLOAT and isinstance(value, int)), identifier
        if setting.is_number:
            low, high = setting.hard_range
            assert all(low <= v <= high for v in (value if setting.size else (value,)))


@pytest.mark.parametrize("name", sorted(SHIPPED))
def test_execute_preset_applies_a_shipped_preset(empty_scene, name):
    scene = empty_scene
    scrambled(scene.csm)
    scene.csm.debug_view = "CASCADES"    # a diagnostic view: no preset changes it
    scene.csm.ambient_strength = 0.25    # the scene's own lighting: no preset changes it
    result = bpy.ops.script.execute_preset(filepath=shipped_paths()[name],
                                           menu_idname="CSM_MT_presets")
    assert result == {'FINISHED'}
    expected = default_settings(debug_view="CASCADES", ambient_strength=0.25,
                                **EXPECTED[name])
    assert snapshot.settings_snapshot(scene) == expected
    # The menu in the header now names the preset applied.
    assert bpy.types.CSM_MT_presets.bl_label == name


def test_the_assignment_preset_makes_every_control_of_the_assignment_act():
    values = dict(assignments(shipped_paths()["CS562 assignment"]))
    settings = default_settings(**values)
    for identifier in ASSIGNMENT_CONTROLS:
        assert is_active(BY_IDENTIFIER[identifier], settings), identifier
    # The defaults pick cascades by shadow map, where the band width hardly acts.
    assert not is_active(BY_IDENTIFIER["blend_band"], default_settings())


def test_best_quality_is_the_models_defaults():
    values = dict(assignments(shipped_paths()["Best quality"]))
    assert default_settings(**values) == default_settings()


@pytest.fixture
def user_preset_folder(tmp_path, monkeypatch):
    """Blender's user preset folder redirected to tmp_path (the test must not write into
    the real user's configuration)."""
    folder = tmp_path / "presets" / presets.PRESET_SUBDIR
    real_preset_paths = bpy.utils.preset_paths
    real_user_resource = bpy.utils.user_resource

    def user_resource(resource_type, *args, path="", create=False, **keywords):
        if resource_type == 'SCRIPTS' and path.replace(os.sep, "/").startswith("presets/"):
            target = tmp_path / path
            if create:
                target.mkdir(parents=True, exist_ok=True)
            return str(target)
        return real_user_resource(resource_type, *args, path=path, create=create, **keywords)

    def preset_paths(subdir):
        found = [path for path in real_preset_paths(subdir)]
        if subdir == presets.PRESET_SUBDIR and folder.is_dir():
            found.append(str(folder))
        return found

    monkeypatch.setattr(bpy.utils, "user_resource", user_resource)
    monkeypatch.setattr(bpy.utils, "preset_paths", preset_paths)
    return folder


def test_a_users_preset_is_added_applied_and_removed(empty_scene, user_preset_folder):
    scene = empty_scene
    scene.csm.cascade_count = 2
    scene.csm.blend_band = 5.5
    scene.csm.split_scheme = "LOG"
    scene.csm.debug_view = "CASCADES"
    assert bpy.ops.csm.preset_add(name="My Shadows") == {'FINISHED'}
    path = user_preset_folder / "My_Shadows.py"
    assert path.is_file()
    found = assignments(str(path))
    assert [identifier for identifier, _value in found] == list(PRESET_IDENTIFIERS)
    assert str(path) in presets.user_presets()

    scrambled(scene.csm)
    bpy.ops.script.execute_preset(filepath=str(path), menu_idname="CSM_MT_presets")
    applied = snapshot.settings_snapshot(scene)
    assert (applied.cascade_count, applied.split_scheme) == (2, "LOG")
    assert applied.blend_band == pytest.approx(5.5)

    assert bpy.ops.csm.preset_add(name="My Shadows", remove_name=True) == {'FINISHED'}
    assert not path.exists()


def test_a_users_preset_cannot_take_a_shipped_presets_name(empty_scene, user_preset_folder):
    assert bpy.ops.csm.preset_add(name="Fast") == {'CANCELLED'}
    assert not user_preset_folder.exists() or not any(user_preset_folder.iterdir())


def test_inactive_settings_read_the_scenes_values(empty_scene):
    csm = empty_scene.csm
    band = BY_IDENTIFIER["blend_band"]
    csm.cascade_selection = "MAP"
    assert not is_active(band, csm)
    csm.cascade_selection = "DEPTH"
    assert is_active(band, csm)
    csm.cascade_count = 1
    assert not is_active(band, csm)
    for setting in SETTINGS:     # every condition reads a value Blender has
        is_active(setting, csm)


class RecordingLayout:
    """Stands in for a panel's ``UILayout`` (panels cannot draw without a window): records
    each ``prop`` with whether it shows active (its own and every enclosing layout's
    ``active``)."""

    def __init__(self, drawn, parent=None):
        object.__setattr__(self, "drawn", drawn)
        object.__setattr__(self, "parent", parent)
        object.__setattr__(self, "active", True)
        object.__setattr__(self, "use_property_split", True)
        object.__setattr__(self, "use_property_decorate", True)

    def __setattr__(self, name, value):
        object.__setattr__(self, name, value)

    def shows_active(self):
        return self.active and (self.parent is None or self.parent.shows_active())

    def _child(self, *args, **keywords):
        return RecordingLayout(self.drawn, self)

    column = row = split = box = _child

    def prop(self, data, identifier, index=0, **keywords):
        if index == 0:     # a vector's fields after the first are the same setting
            self.drawn.append((identifier, self.shows_active()))

    def operator(self, *args, **keywords):
        return RecordingLayout([], self)

    def label(self, *args, **keywords):
        pass

    def separator(self, *args, **keywords):
        pass


def drawn_settings(context):
    """identifier -> shown active, for every CSM setting the render panels draw."""
    drawn = []
    for _key, _label, draw in ui.GROUPS:
        draw(RecordingLayout(drawn), context)
    csm_drawn = [(identifier, active) for identifier, active in drawn
                 if identifier in BY_IDENTIFIER]
    result = dict(csm_drawn)
    assert len(result) == len(csm_drawn), "each setting is drawn once"
    return result


@pytest.mark.parametrize("name", [None] + sorted(SHIPPED))
def test_the_panels_grey_out_exactly_the_settings_that_do_not_act(empty_scene, name):
    scene = empty_scene
    if name is not None:
        bpy.ops.script.execute_preset(filepath=shipped_paths()[name],
                                      menu_idname="CSM_MT_presets")
    variants = [{}, dict(shadow_filter="HARD", fade_out=False, ambient_occlusion=False,
                         occluder_margin_auto=False, debug_view="SHADOW_MAP",
                         split_scheme="MANUAL", cascade_count=1)]
    for variant in variants:
        for identifier, value in variant.items():
            setattr(scene.csm, identifier, value)
        drawn = drawn_settings(bpy.context)
        assert set(drawn) == set(BY_IDENTIFIER), "every setting has a place in the panels"
        for identifier, active in drawn.items():
            assert active == is_active(BY_IDENTIFIER[identifier], scene.csm), \
                (identifier, variant)
