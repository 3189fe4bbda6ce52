"""The settings model is consistent in itself: one entry per setting, defaults inside their
ranges, enum defaults among their items, enum identifiers exactly core's, and the
``Settings`` value object generated from it (the Blender side is checked against it in
tests/bpy/addon/test_registration.py); when a setting acts (the panels grey it out
otherwise, the tooltip says why), labels short enough for the sidebar, every number's
unit, and what presets set."""
import dataclasses
import math
import re
import types
from pathlib import Path

import pytest

from csm_engine.core import frame_layout, settings_model
from csm_engine.core.settings_model import (SETTINGS, Settings, default_settings,
                                            BY_IDENTIFIER)

# The enums the shaders switch on: their identifiers and order belong to frame_layout.
CORE_ENUMS = {
    "split_scheme": frame_layout.SPLIT_SCHEMES,
    "pcf_pattern": frame_layout.PCF_PATTERNS,
    "debug_view": frame_layout.DEBUG_VIEWS,
    "shadow_filter": frame_layout.SHADOW_FILTERS,
    "cascade_selection": frame_layout.CASCADE_SELECTIONS,
    # PER_LIGHT resolves to one of the others per light before anything reaches the GPU.
    "light_falloff": ("PER_LIGHT",) + frame_layout.LIGHT_FALLOFFS,
}


def _ids(setting):
    return setting.identifier


def test_identifiers_are_unique_python_names():
    identifiers = [setting.identifier for setting in SETTINGS]
    assert len(identifiers) == len(set(identifiers))
    assert len(identifiers) >= 35
    for identifier in identifiers:
        assert identifier.isidentifier() and identifier == identifier.lower(), identifier
        assert identifier != "name", "a PropertyGroup's own 'name' would shadow it"
    assert set(BY_IDENTIFIER) == set(identifiers)


@pytest.mark.parametrize("setting", SETTINGS, ids=_ids)
def test_every_setting_is_fully_described(setting):
    assert setting.kind in settings_model.KINDS
    assert setting.group in settings_model.GROUPS
    assert setting.name and setting.name[0].isupper()
    assert len(setting.description) > 40, "a tooltip says more than the label does"
    assert isinstance(setting.default, setting.value_type) and \
        not (setting.kind == settings_model.INT and isinstance(setting.default, bool))
    if setting.kind != settings_model.ENUM:
        assert setting.items == ()
    if not setting.is_number:
        assert (setting.min, setting.max, setting.soft_min, setting.soft_max) == (None,) * 4
        assert setting.subtype is None and setting.unit is None
    assert setting.unit in (None, "LENGTH")
    assert setting.subtype in (None, "PIXEL", "FACTOR")


@pytest.mark.parametrize("setting", [s for s in SETTINGS if s.is_number], ids=_ids)
def test_defaults_lie_within_the_soft_range_within_the_hard_range(setting):
    hard_min, hard_max = setting.hard_range
    soft_min, soft_max = setting.soft_range
    assert hard_min <= soft_min < soft_max <= hard_max
    values = setting.default if setting.kind == settings_model.FLOAT_VECTOR else \
        (setting.default,)
    for value in values:
        assert isinstance(value, (float, int)) and math.isfinite(value)
        assert soft_min <= value <= soft_max, (setting.identifier, value)
    if setting.kind == settings_model.FLOAT_VECTOR:
        assert setting.size == len(setting.default) > 1
    else:
        assert setting.size is None


def test_unbounded_limits_are_the_stored_types_range():
    shadow_distance = BY_IDENTIFIER["shadow_distance"]
    assert shadow_distance.hard_range == (0.0, settings_model.FLOAT32_MAX)
    assert shadow_distance.soft_range == (0.0, 10000.0)
    assert BY_IDENTIFIER["cascade_count"].hard_range == (1, 4)
    assert BY_IDENTIFIER["fxaa"].hard_range is None


@pytest.mark.parametrize("setting", [s for s in SETTINGS if s.kind == settings_model.ENUM],
                         ids=_ids)
def test_enum_defaults_are_among_their_items(setting):
    identifiers = setting.identifiers
    assert len(identifiers) == len(set(identifiers)) > 1
    assert setting.default in identifiers
    for item in setting.items:
        assert isinstance(item, settings_model.EnumItem)
        assert item.label and len(item.description) > 10, item


def test_enums_are_core_enums_in_core_order():
    enums = {s.identifier: s.identifiers for s in SETTINGS if s.kind == settings_model.ENUM}
    assert enums == CORE_ENUMS


def test_settings_has_one_field_per_setting_defaulting_to_the_model():
    fields = dataclasses.fields(Settings)
    assert [f.name for f in fields] == [s.identifier for s in SETTINGS]
    defaults = default_settings()
    for setting in SETTINGS:
        assert getattr(defaults, setting.identifier) == setting.default
    assert Settings() == defaults
    assert Settings.__module__ == settings_model.__name__


def test_default_settings_overrides_and_stays_frozen():
    settings = default_settings(cascade_count=2, split_scheme="LOG", manual_splits=[0.2, 0.4, 0.8])
    assert (settings.cascade_count, settings.split_scheme) == (2, "LOG")
    assert settings.manual_splits == (0.2, 0.4, 0.8)
    assert settings.resolution == BY_IDENTIFIER["resolution"].default
    with pytest.raises(dataclasses.FrozenInstanceError):
        settings.cascade_count = 4
    assert hash(settings) == hash(default_settings(cascade_count=2, split_scheme="LOG",
                                                   manual_splits=(0.2, 0.4, 0.8)))
    assert dataclasses.replace(settings, cascade_count=4).cascade_count == 4
    with pytest.raises(TypeError, match="cascades"):
        default_settings(cascades=2)


def test_the_model_holds_no_mutable_module_state():
    mutable = (list, dict, set, bytearray)
    for name, value in vars(settings_model).items():
        if name.startswith("__"):
            continue
        assert not isinstance(value, mutable), name
        if isinstance(value, tuple):
            assert not any(isinstance(item, mutable) for item in value), name
    assert isinstance(BY_IDENTIFIER, types.MappingProxyType)
    for setting in SETTINGS:
        assert isinstance(setting.items, tuple)
        assert not isinstance(setting.default, mutable), setting.identifier


def test_no_setting_default_is_restated_outside_the_model():
    """Defaults exist once: nothing reads a setting with a fallback value of its own."""
    package = Path(settings_model.__file__).resolve().parents[1]
    names = "|".join(settings_model.BY_IDENTIFIER)
    restated = re.compile(r"getattr\(\s*[\w.]+\s*,\s*['\"](%s)['\"]\s*," % names)
    found = [f"{path.relative_to(package)}:{text.count(chr(10), 0, match.start()) + 1} "
             f"{match.group(1)}"
             for path in sorted(package.rglob("*.py"))
             for text in [path.read_text(encoding="utf-8")]
             for match in restated.finditer(text)]
    assert not found, found


# --- when a setting acts, labels, units, presets ------------------------------------------

@pytest.mark.parametrize("setting", [s for s in SETTINGS if s.active_when], ids=_ids)
def test_conditions_name_other_settings_and_values_they_can_hold(setting):
    for alternative in setting.active_when:
        assert alternative and isinstance(alternative, tuple)
        for condition in alternative:
            assert isinstance(condition, settings_model.Condition)
            other = BY_IDENTIFIER[condition.identifier]
            assert other is not setting
            assert other.kind in (settings_model.BOOLEAN, settings_model.ENUM,
                                  settings_model.INT), condition
            for value in condition.values:
                if other.kind == settings_model.ENUM:
                    assert value in other.identifiers, condition
                elif other.kind == settings_model.BOOLEAN:
                    assert isinstance(value, bool), condition
                else:
                    low, high = other.hard_range
                    assert low <= value <= high, condition


def test_the_tooltip_of_a_setting_that_can_be_inactive_ends_with_the_reason():
    for setting in SETTINGS:
        has_reason = "Inactive unless " in setting.description
        assert has_reason == bool(setting.active_when), setting.identifier
    assert BY_IDENTIFIER["blend_band"].description.endswith(
        "Inactive unless Selection is View Depth and Cascades is 2 or more")
    assert BY_IDENTIFIER["pcf_radius"].description.endswith("Inactive unless Filter is PCF")
    assert BY_IDENTIFIER["debug_shadow_map"].description.endswith(
        "Inactive unless View is Shadow map, or Inset is on")


def test_is_active_follows_the_settings_a_control_depends_on():
    def active(identifier, **values):
        return settings_model.is_active(BY_IDENTIFIER[identifier], default_settings(**values))

    assert not active("blend_band")                        # default: map selection
    assert active("blend_band", cascade_selection="DEPTH")
    assert not active("blend_band", cascade_selection="DEPTH", cascade_count=1)
    assert active("fitted_split_lambda") and not active("split_lambda")
    assert active("split_lambda", fit_to_visible=False)
    assert not active("split_lambda", fit_to_visible=False, split_scheme="MANUAL")
    assert active("manual_splits", split_scheme="MANUAL")
    assert not active("manual_splits")
    for identifier in ("pcf_radius", "pcf_sharpen", "pcf_pattern"):
        assert active(identifier) and not active(identifier, shadow_filter="HARD")
        assert not active(identifier, shadow_filter="SOFT")
    assert not active("fade_fraction", fade_out=False)
    assert not active("occluder_margin") and active("occluder_margin",
                                                    occluder_margin_auto=False)
    assert not active("ao_distance", ambient_occlusion=False)
    assert not active("debug_shadow_map")
    assert active("debug_shadow_map", debug_view="SHADOW_MAP")
    assert active("debug_shadow_map", debug_inset=True)
    assert active("cascade_count") and active("fit_to_visible")


# Labels Blender 3.4 showed whole in the 3D View sidebar at its default width (the
# narrowest place: about 11 characters beside a field, checked in a screenshot).
LABEL_CHARACTERS = 11
# Drawn without a label of their own, beside the control they belong to.
UNLABELLED = {"fade_fraction"}


@pytest.mark.parametrize("setting", SETTINGS, ids=_ids)
def test_labels_are_short_enough_for_the_sidebar(setting):
    if setting.identifier not in UNLABELLED:
        assert len(setting.name) <= LABEL_CHARACTERS, setting.name


def test_labels_are_unique_within_a_panel():
    for group in settings_model.GROUPS:
        names = [s.name for s in SETTINGS if s.group == group]
        assert len(names) == len(set(names)), group


# How a tooltip names a number's unit when Blender has none to show (texels) or the number
# has none (a count, a weight, an index).
UNIT_WORDS = ("texels", "scene units", "0 to 1", "(1 to 4)", "(1 to 64)", "multiplier",
              "0 = nearest", "fractions")


@pytest.mark.parametrize("setting", [s for s in SETTINGS if s.is_number], ids=_ids)
def test_every_number_shows_or_says_its_unit(setting):
    if setting.unit is None and setting.subtype is None:
        assert any(word in setting.description.lower() for word in UNIT_WORDS), \
            setting.description
    if setting.unit == "LENGTH":
        assert "scene units" in setting.description


def test_presets_set_the_method_not_the_views_or_the_scenes_lighting():
    preset = set(settings_model.PRESET_IDENTIFIERS)
    assert list(settings_model.PRESET_IDENTIFIERS) == \
        [s.identifier for s in SETTINGS if s.identifier in preset]
    for setting in SETTINGS:
        if setting.group == settings_model.DEBUG:
            assert setting.identifier not in preset
    assert {"ambient_strength", "light_falloff"}.isdisjoint(preset)
    assert {"cascade_count", "blend_band", "shadow_filter", "ambient_occlusion",
            "render_samples", "depth_bias", "occluder_margin_auto"} <= preset


# A setting the panels grey out must not change what the core plans: (setting, the other
# settings that make it inactive, a value it is changed to). Blend Band under Shadow Map
# selection is left out: the cascade fit still leaves room for it, so it changes the maps
# a little (its tooltip says the width hardly matters there).
INACTIVE_CHANGES = [
    ("split_lambda", dict(fit_to_visible=True), 0.0),
    ("split_lambda", dict(fit_to_visible=False, split_scheme="LOG"), 0.0),
    ("fitted_split_lambda", dict(fit_to_visible=False), 0.0),
    ("manual_splits", dict(fit_to_visible=False), (0.2, 0.25, 0.3)),
    ("split_scheme", dict(fit_to_visible=False, cascade_count=1), "UNIFORM"),
    ("equal_resolution", dict(fit_to_visible=False, cascade_count=1), True),
    ("occluder_margin", dict(fit_to_visible=False), 3.0),
    ("fade_fraction", dict(fit_to_visible=False, fade_out=False), 0.5),
]


@pytest.mark.parametrize("identifier, inactive, value", INACTIVE_CHANGES,
                         ids=[f"{i}-{'-'.join(map(str, s.values()))}"
                              for i, s, _ in INACTIVE_CHANGES])
def test_a_greyed_out_setting_does_not_change_the_plan(identifier, inactive, value):
    import numpy as np
    from tests.unit import test_shadow_plan as plans
    from csm_engine.core import shadow_plan

    base = dict(plans.SETTINGS, **inactive)
    assert not settings_model.is_active(BY_IDENTIFIER[identifier], default_settings(**base))
    pairs = np.empty((9, 16, 2))
    pairs[..., 0], pairs[..., 1] = 20.0, 100.0                   # what the view shows
    blocks = shadow_plan.depth_blocks_from_reduction(pairs, 16, 320, 180)
    frames = []
    for settings in (base, dict(base, **{identifier: value})):
        snap = plans._snapshot(**settings)
        plan = shadow_plan.plan_shadows(snap, plans.BOUNDS, blocks)
        frames.append((plan.splits.tobytes(), shadow_plan.pack_frame(snap, plan).tobytes()))
    assert frames[0] == frames[1]
