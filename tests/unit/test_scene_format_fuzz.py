"""Property test: thousands of mutated scene files either load or give one clear error.

Mutations start from the documented samples and change values and types, drop, add and
rename keys, and cut or splice the text. Whatever comes out, the parser must return a
scene with only finite, valid numbers or raise ``SceneFormatError`` with a one-line
message naming the file; any other exception is a bug.
"""

import json
import math

from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from csm_engine.core.scene_format import SUPPORTED_MESH_EXTENSIONS, SceneFormatError, parse_scene

SOURCE = "fuzzed.json"

SAMPLES = [
    {
        "camera": {"translate": {"x": -190.0, "y": 40.0, "z": 50.0},
                   "rotate": {"x": 0.0, "y": 100, "z": 0.0},
                   "near": 0.1, "far": 500.0, "FOVy": 30.0},
        "objects": [{"mesh": "data/gltf/vokselia/vokselia.gltf",
                     "translate": {"x": 0.0, "y": 0.0, "z": 0.0},
                     "rotate": {"x": 0.0, "y": 0.0, "z": 0.0},
                     "scale": {"x": 100, "y": 100, "z": 100}}],
        "lights": [],
        "directional_light": {"direction": {"x": 0.3, "y": -0.6, "z": -0.7},
                              "color": {"x": 1.0, "y": 1.0, "z": 1.0}},
    },
    {
        "camera": {"translation": {"x": -90.0, "y": 40.0, "z": -20.0},
                   "rotate": {"x": 0.0, "y": 90.0, "z": 0.0},
                   "near": 0.1, "far": 500.0, "FOVy": 60.0},
        "objects": [{"mesh": "data/gltf/sponza/Sponza.gltf",
                     "translation": {"x": 0, "y": 0, "z": 0}, "rotate": {"x": 0, "y": 0, "z": 0},
                     "scale": {"x": 0.3, "y": 0.3, "z": 0.3}},
                    {"mesh": "extra/box.obj"}],
        "lights": [{"position": {"x": 0.0, "y": 60.0, "z": -40.0},
                    "color": {"x": 1.0, "y": 0.95, "z": 0.65}, "radius": 30},
                   {"position": {"x": 10.0, "y": 6.0, "z": 4.0},
                    "color": {"x": 0.2, "y": 0.3, "z": 1.0}, "radius": 12.5}],
    },
]

KEYS = ["camera", "objects", "lights", "directional_light", "translate", "translation",
        "rotate", "scale", "mesh", "position", "color", "radius", "direction", "near", "far",
        "FOVy", "x", "y", "z", "", "X", "extra"]

scalars = (st.none() | st.booleans() | st.integers(min_value=-10 ** 30, max_value=10 ** 30)
           | st.floats(allow_nan=True, allow_infinity=True)
           | st.sampled_from([0, -0.0, 1e-320, 1e308, -1e308, 10 ** 400, 179.9999, 180, 0.1])
           | st.text(max_size=12)
           | st.sampled_from(["a.gltf", "b.fbx", "c.OBJ", "", ".ply", "x/y.stl", "d\\e.glb"]))
json_values = st.recursive(
    scalars,
    lambda children: st.lists(children, max_size=4)
    | st.dictionaries(st.sampled_from(KEYS) | st.text(max_size=4), children, max_size=4),
    max_leaves=10)


def containers(node, path=()):
    """Every (path, container) in the document, the root included."""
    yield path, node
    children = node.items() if isinstance(node, dict) else enumerate(node) \
        if isinstance(node, list) else ()
    for key, child in children:
        if isinstance(child, (dict, list)):
            yield from containers(child, path + (key,))


def mutate(data, document):
    targets = list(containers(document))
    _, container = targets[data.draw(st.integers(0, len(targets) - 1), label="container")]
    keys = list(container.keys()) if isinstance(container, dict) else list(range(len(container)))
    action = data.draw(st.sampled_from(["replace", "delete", "add", "rename", "duplicate"]),
                       label="action")
    if isinstance(container, list):
        if action == "add" or not keys:
            container.append(data.draw(json_values, label="new item"))
        elif action == "delete":
            del container[data.draw(st.sampled_from(keys))]
        else:
            container[data.draw(st.sampled_from(keys))] = data.draw(json_values, label="value")
        return
    if action == "add" or not keys:
        container[data.draw(st.sampled_from(KEYS) | st.text(max_size=5), label="key")] = \
            data.draw(json_values, label="value")
    elif action == "delete":
        del container[data.draw(st.sampled_from(keys), label="key")]
    elif action == "rename":
        key = data.draw(st.sampled_from(keys), label="key")
        container[data.draw(st.sampled_from(KEYS), label="new key")] = container.pop(key)
    else:
        container[data.draw(st.sampled_from(keys), label="key")] = \
            data.draw(json_values, label="value")


def check(text):
    try:
        scene = parse_scene(text, SOURCE)
    except SceneFormatError as err:
        message = str(err)
        assert message.startswith(SOURCE + ": ")
        assert "\n" not in message and "\r" not in message
        return
    # What loads is usable: finite numbers and values inside their documented ranges.
    numbers = []
    for item in scene.objects:
        assert item.mesh.lower().endswith(SUPPORTED_MESH_EXTENSIONS)
        numbers += [*item.translate.as_tuple(), *item.rotate.as_tuple(), *item.scale.as_tuple()]
        assert 0.0 not in item.scale.as_tuple()
    for light in scene.lights:
        numbers += [*light.position.as_tuple(), *light.color.as_tuple(), light.radius]
        assert light.radius > 0 and min(light.color.as_tuple()) >= 0
    if scene.camera is not None:
        camera = scene.camera
        numbers += [*camera.translate.as_tuple(), *camera.rotate.as_tuple()]
        assert 0 < camera.near < camera.far and 0 < camera.fov_y_degrees < 180
    if scene.directional_light is not None:
        numbers += scene.directional_light.direction.as_tuple()
        assert any(scene.directional_light.direction.as_tuple())
    assert all(isinstance(n, float) and math.isfinite(n) for n in numbers)


@settings(max_examples=2000, deadline=None, suppress_health_check=list(HealthCheck))
@given(st.data())
def test_mutated_documents_load_or_fail_clearly(data):
    document = json.loads(json.dumps(data.draw(st.sampled_from(SAMPLES), label="sample")))
    for _ in range(data.draw(st.integers(1, 4), label="mutations")):
        mutate(data, document)
    check(json.dumps(document, allow_nan=True))


SPLICE = st.text(alphabet='{}[]:,"0123456789.eE-+ \n\tNaInfinityultrsxyz\\/\x00\u00e9', max_size=8)


@settings(max_examples=2000, deadline=None, suppress_health_check=list(HealthCheck))
@given(st.data())
def test_mutated_text_loads_or_fails_clearly(data):
    document = data.draw(st.sampled_from(SAMPLES), label="sample")
    text = json.dumps(document, indent=data.draw(st.sampled_from([None, 1, 4])))
    for _ in range(data.draw(st.integers(1, 3), label="edits")):
        start = data.draw(st.integers(0, len(text)), label="start")
        end = data.draw(st.integers(start, min(len(text), start + 12)), label="end")
        edit = data.draw(st.sampled_from(["truncate", "delete", "insert", "replace"]))
        if edit == "truncate":
            text = text[:start]
        elif edit == "delete":
            text = text[:start] + text[end:]
        elif edit == "insert":
            text = text[:start] + data.draw(SPLICE, label="inserted") + text[start:]
        else:
            text = text[:start] + data.draw(SPLICE, label="replacement") + text[end:]
    check(text)


def test_deep_nesting_is_an_error_not_a_crash():
    check('{"objects": ' + "[" * 100000 + "]" * 100000 + "}")
    check("[" * 100000)
