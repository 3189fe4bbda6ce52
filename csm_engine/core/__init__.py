"""The engine's pure part: scene format, conventions, camera, cascades, shadow planning,
the frame uniform layout and its packing.

Imports numpy and the standard library only; never ``bpy``, ``gpu``, ``mathutils`` or
anything from ``csm_engine.render`` / ``csm_engine.blender`` (a test imports it with bpy
absent). Everything here is plain data in, plain data out, and unit-tested without Blender.
No module keeps state between calls: what a view carries from frame to frame is a
``view_state.ShadowViewState`` its owner passes in, and the only module-level objects
that hold anything are memos of pure functions (``memo.py``; a test checks both).
"""
