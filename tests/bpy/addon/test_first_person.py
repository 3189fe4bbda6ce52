"""The first-person camera's modal keys, like Blender's Fly mode (pip bpy, in process).

The operator's own ``invoke`` and ``modal`` run on a real scene camera, fed with fake
events: pip bpy has no window, so a stand-in context carries the view (``region_data``),
the header and the timer. Esc and right-click put the camera back exactly; a left click
or Enter keeps the new view; a left drag looks around without confirming; the wheel
changes the Fly Speed (metres per second) the header shows.
"""

import math
from types import SimpleNamespace

import bpy
import mathutils
import numpy as np
import pytest

from csm_engine.blender import operators


class _Area:
    type = 'VIEW_3D'

    def __init__(self):
        self.headers = []

    def header_text_set(self, text):
        self.headers.append(text)

    def tag_redraw(self):
        pass


class _WindowManager:
    def __init__(self):
        self.timers = []
        self.handlers = []

    def event_timer_add(self, step, window=None):
        self.timers.append(object())
        return self.timers[-1]

    def event_timer_remove(self, timer):
        self.timers.remove(timer)

    def modal_handler_add(self, operator):
        self.handlers.append(operator)


def _event(kind, value='PRESS', x=0, y=0):
    return SimpleNamespace(type=kind, value=value, mouse_x=x, mouse_y=y)


class _Flight:
    """One first-person session: the operator's methods on a plain object."""

    def __init__(self, scene, perspective='CAMERA'):
        cls = operators.CSM_OT_first_person
        methods = {name: value for name, value in vars(cls).items() if callable(value)}
        self.operator = type("Flight", (), methods)()
        self.operator.speed = 0.0
        view = mathutils.Matrix.Translation((0.0, -10.0, 2.0))
        self.view = SimpleNamespace(
            view_perspective=perspective, view_location=mathutils.Vector((0.0, 0.0, 2.0)),
            view_rotation=mathutils.Quaternion((0.7071068, 0.7071068, 0.0, 0.0)),
            view_distance=10.0, view_matrix=view.inverted())
        self.context = SimpleNamespace(scene=scene, region_data=self.view, area=_Area(),
                                       window_manager=_WindowManager(), window=None)
        assert self.operator.invoke(self.context, _event('F')) == {'RUNNING_MODAL'}

    def send(self, *events):
        result = None
        for event in events:
            result = self.operator.modal(self.context, event)
        return result

    def drag(self, dx, dy):
        """A left-button drag from (100, 100) by (dx, dy) pixels, released."""
        return self.send(_event('LEFTMOUSE', 'PRESS', 100, 100),
                         _event('MOUSEMOVE', 'NOTHING', 100 + dx // 2, 100 + dy // 2),
                         _event('MOUSEMOVE', 'NOTHING', 100 + dx, 100 + dy),
                         _event('LEFTMOUSE', 'RELEASE', 100 + dx, 100 + dy))

    @property
    def finished_cleanly(self):
        wm, area = self.context.window_manager, self.context.area
        return not wm.timers and area.headers[-1] is None


@pytest.fixture
def camera_scene(empty_scene):
    camera = bpy.data.objects.new("Camera", bpy.data.cameras.new("Camera"))
    empty_scene.collection.objects.link(camera)
    empty_scene.camera = camera
    camera.location = (1.0, -8.0, 3.0)
    camera.rotation_mode = 'XYZ'
    camera.rotation_euler = (math.radians(80.0), 0.0, math.radians(10.0))
    camera.scale = (1.0, 1.0, 1.0)
    mesh = bpy.data.meshes.new("Plane")
    mesh.from_pydata([(-20, -20, 0), (20, -20, 0), (20, 20, 0), (-20, 20, 0)], [],
                     [(0, 1, 2, 3)])
    empty_scene.collection.objects.link(bpy.data.objects.new("Plane", mesh))
    bpy.context.view_layer.update()
    return empty_scene


def _channels(obj):
    return (obj.rotation_mode, tuple(obj.location), tuple(obj.rotation_euler),
            tuple(obj.rotation_quaternion), tuple(obj.scale))


def _moved(before, camera):
    return not np.allclose(np.array(before), np.array(camera.matrix_world), atol=1e-6)


@pytest.mark.parametrize("cancel", [_event('ESC'), _event('RIGHTMOUSE')])
def test_esc_or_right_click_puts_the_camera_back_exactly(camera_scene, cancel):
    camera = camera_scene.camera
    start = _channels(camera)
    start_matrix = camera.matrix_world.copy()
    flight = _Flight(camera_scene)
    assert flight.drag(120, -40) == {'RUNNING_MODAL'}     # a drag looks, it does not confirm
    flight.send(_event('W'))
    flight.operator._last_time -= 0.25                     # a quarter second of W held
    flight.send(_event('TIMER', 'NOTHING'))
    bpy.context.view_layer.update()
    assert _moved(start_matrix, camera)
    assert flight.send(cancel) == {'CANCELLED'}
    assert _channels(camera) == start          # bit for bit: no matrix round trip
    assert flight.finished_cleanly


@pytest.mark.parametrize("confirm", [[_event('RET')], [_event('NUMPAD_ENTER')],
                                     [_event('LEFTMOUSE', 'PRESS', 50, 50),
                                      _event('MOUSEMOVE', 'NOTHING', 51, 50),
                                      _event('LEFTMOUSE', 'RELEASE', 51, 50)]],
                         ids=["enter", "numpad-enter", "left-click"])
def test_a_left_click_or_enter_keeps_the_new_view(camera_scene, confirm):
    camera = camera_scene.camera
    start_matrix = camera.matrix_world.copy()
    flight = _Flight(camera_scene)
    flight.drag(100, 0)                        # 100 px right: 20 degrees to the right
    bpy.context.view_layer.update()
    turned = camera.matrix_world.copy()
    assert _moved(start_matrix, camera)
    assert flight.send(*confirm) == {'FINISHED'}
    bpy.context.view_layer.update()
    assert not _moved(turned, camera)          # a click's 1 px jitter does not turn it
    assert flight.finished_cleanly
    start_forward = -np.array(start_matrix)[:3, 2]
    forward = -np.array(camera.matrix_world)[:3, 2]
    yaw = math.degrees(math.atan2(forward[1], forward[0])
                       - math.atan2(start_forward[1], start_forward[0]))
    assert yaw == pytest.approx(-20.0, abs=0.5)


def test_cancel_restores_the_viewport_when_not_looking_through_the_camera(camera_scene):
    flight = _Flight(camera_scene, perspective='ORTHO')
    view = flight.view
    assert view.view_perspective == 'PERSP'    # first person needs a perspective eye
    camera_start = _channels(camera_scene.camera)
    flight.drag(60, 30)
    assert view.view_rotation != mathutils.Quaternion((0.7071068, 0.7071068, 0.0, 0.0))
    assert flight.send(_event('ESC')) == {'CANCELLED'}
    assert view.view_perspective == 'ORTHO'
    assert tuple(view.view_rotation) == pytest.approx((0.7071068, 0.7071068, 0.0, 0.0))
    assert tuple(view.view_location) == (0.0, 0.0, 2.0) and view.view_distance == 10.0
    assert _channels(camera_scene.camera) == camera_start


def test_the_wheel_changes_the_fly_speed_the_header_shows_in_metres_per_second(camera_scene):
    light = camera_scene.csm_light
    assert light.fly_speed == 0.0              # automatic until the first flight
    flight = _Flight(camera_scene)
    automatic = operators.round_speed(operators.scene_speed(camera_scene))
    assert light.fly_speed == pytest.approx(automatic)
    assert automatic == pytest.approx(math.hypot(40.0, 40.0) / 10.0, rel=0.02)
    header = flight.context.area.headers[-1]
    assert f"{automatic:.3g} m/s" in header
    for words in ("click/Enter confirm", "Esc/right-click cancel", "wheel"):
        assert words in header, header
    assert flight.send(_event('WHEELUPMOUSE')) == {'RUNNING_MODAL'}
    assert light.fly_speed == pytest.approx(automatic * 1.25)
    assert f"{automatic * 1.25:.3g} m/s" in flight.context.area.headers[-1]
    flight.send(_event('WHEELDOWNMOUSE'), _event('WHEELDOWNMOUSE'))
    assert light.fly_speed == pytest.approx(automatic * 1.25 * 0.64)
    # W held for half a second moves half a second's worth of the Fly Speed.
    camera = camera_scene.camera
    start = np.array(camera.matrix_world)
    flight.send(_event('W'))
    flight.operator._last_time -= 0.5
    flight.send(_event('TIMER', 'NOTHING'))
    bpy.context.view_layer.update()
    travelled = np.linalg.norm(np.array(camera.matrix_world)[:3, 3] - start[:3, 3])
    assert travelled == pytest.approx(light.fly_speed * 0.5, rel=0.05)
    assert flight.send(_event('RET')) == {'FINISHED'}
    # The next flight keeps the speed the wheel chose.
    assert _Flight(camera_scene).operator._speed(flight.context) == light.fly_speed


def test_other_events_pass_through_to_blender(camera_scene):
    flight = _Flight(camera_scene)
    assert flight.send(_event('Z')) == {'PASS_THROUGH'}
    assert flight.send(_event('ESC', 'RELEASE')) == {'PASS_THROUGH'}
    assert flight.send(_event('LEFTMOUSE', 'RELEASE')) == {'RUNNING_MODAL'}  # no press: no click
    assert flight.send(_event('ESC')) == {'CANCELLED'}
