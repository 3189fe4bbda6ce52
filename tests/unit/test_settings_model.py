"""The settings model is consistent in itself: one entry per setting, defaults inside their
ranges, enum defaults among their items, enum identifiers exactly core's, and the
``Settings`` value object generated from it (the Blender side is checked against it in
tests/bpy/addon/test_registration.py)."""
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
