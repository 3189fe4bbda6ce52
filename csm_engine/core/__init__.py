"""The engine's pure part: scene format, conventions, camera, cascades, shadow planning and
the frame uniform layout.

Imports numpy and the standard library only; never ``bpy``, ``gpu``, ``mathutils`` or
anything from ``csm_engine.render`` / ``csm_engine.blender`` (a test imports it with bpy
absent). Everything here is plain data in, plain data out, and unit-tested without Blender.
"""
